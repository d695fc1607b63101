//! The planner's decisions: from what a view shows (`scene.footprint`'s measurements) and a FLIP
//! budget, the cheapest model per stage, each with its reason, as edits to the graph.
//!
//! The rules, per stage (budget B, the mean FLIP over the object's pixels):
//! - B = 0 asks for the full model: raw BTF at λ = 0, the MDF, the diffusion gather by brute
//!   force with the PBD profile.
//! - B ≥ 1 (FLIP's whole range) allows the cheapest: the BTF's average BRDF, no MDF, the BRDF
//!   approximation of subsurface scattering. Never nothing.
//! - BTF level λ = ⌊log₂ texels-per-pixel⌋ (seed 003: the level a pixel's footprint covers),
//!   capped at the tile's coarsest level, where the BTF is its average BRDF.
//! - BTF rank: PCA in YCbCr with luma rank 8 and chroma rank 2 (the 8/2/2 split); rank 1 at the
//!   cheapest. (A rank from the budget needs the measured error curve; a relative-RMSE rule
//!   asked for 126 components on a 32² weave at B = 0.05, far more than FLIP can see.)
//! - MDF: left out when the shell projects to under half a pixel.
//! - Subsurface scattering: the BRDF approximation when the longest effective mean free path is
//!   under half a pixel footprint; otherwise the sample spacing is no finer than half a footprint
//!   (the profile's default of a quarter of the shortest mean free path, when that is coarser).
//!
//! These are rules, not yet fitted error models: the plan records no predicted error (absent,
//! never 0) until a calibration sweep stands behind one.

use mesoflow_graph::GraphFile;
use serde_json::{json, Map, Value};
use std::collections::{BTreeMap, BTreeSet};

/// What the view shows, from `scene.footprint`'s metrics (absent ones are `None`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scene {
    pub visible_fraction: f64,
    pub camera_inside: bool,
    pub backfacing_fraction: Option<f64>,
    pub pixel_footprint_mm: Option<f64>,
    pub texels_per_pixel: Option<f64>,
    pub tile_texels: Option<f64>,
    pub shell_pixels: Option<f64>,
    pub mfp_mm: Option<f64>,
    pub mfp_min_mm: Option<f64>,
    pub mfp_pixels: Option<f64>,
}

impl Scene {
    pub fn from_metrics(m: &BTreeMap<String, f64>) -> Scene {
        let g = |k: &str| m.get(k).copied().filter(|v| v.is_finite());
        Scene {
            visible_fraction: g("visible_fraction").unwrap_or(0.0),
            camera_inside: g("camera_inside").is_some_and(|v| v > 0.5),
            backfacing_fraction: g("backfacing_fraction"),
            pixel_footprint_mm: g("pixel_footprint_mm"),
            texels_per_pixel: g("texels_per_pixel"),
            tile_texels: g("tile_texels"),
            shell_pixels: g("shell_pixels"),
            mfp_mm: g("mfp_mm"),
            mfp_min_mm: g("mfp_min_mm"),
            mfp_pixels: g("mfp_pixels"),
        }
    }

    pub fn to_json(&self) -> Value {
        let mut o = Map::new();
        o.insert("visible_fraction".into(), json!(self.visible_fraction));
        o.insert("camera_inside".into(), json!(self.camera_inside));
        for (k, v) in [
            ("backfacing_fraction", self.backfacing_fraction),
            ("pixel_footprint_mm", self.pixel_footprint_mm),
            ("texels_per_pixel", self.texels_per_pixel),
            ("tile_texels", self.tile_texels),
            ("shell_pixels", self.shell_pixels),
            ("mfp_mm", self.mfp_mm),
            ("mfp_min_mm", self.mfp_min_mm),
            ("mfp_pixels", self.mfp_pixels),
        ] {
            if let Some(v) = v {
                o.insert(k.into(), json!(v));
            }
        }
        Value::Object(o)
    }
}

/// One decision: the stage, what was chosen, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Decision {
    pub stage: &'static str,
    pub choice: Value,
    pub reason: String,
    /// What the choice costs where it can be said before running (texels, samples); absent
    /// otherwise.
    pub predicted_cost: Option<Value>,
}

/// The renderers the planner knows, and their ports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RenderKind {
    Mesh,
    Sss,
    Qh,
}

impl RenderKind {
    pub fn of(kind: &str) -> Option<RenderKind> {
        match kind {
            "render.mesh" => Some(RenderKind::Mesh),
            "sss.render" => Some(RenderKind::Sss),
            "qh.render" => Some(RenderKind::Qh),
            _ => None,
        }
    }
    /// The port the BTF (or local reflectance) arrives on.
    pub fn btf_port(self) -> Option<&'static str> {
        match self {
            RenderKind::Mesh => Some("btf"),
            RenderKind::Qh => Some("lrf"),
            RenderKind::Sss => None,
        }
    }
}

/// Why a plan cannot be made.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PlanError {
    #[error("the camera is inside the mesh: no footprint to plan from; move `eye` outside")]
    CameraInside,
    #[error("budget {0}: a FLIP budget is a number ≥ 0")]
    Budget(f64),
}

/// The chain a BTF reaches the renderer through.
#[derive(Clone, Debug, PartialEq)]
pub struct BtfChain {
    /// The node and port giving the raw BTF (what `btf.pca` reads, or the renderer directly).
    pub raw: String,
}

/// Decisions and the graph edits that carry them out.
pub struct Plan {
    pub decisions: Vec<Decision>,
    pub file: GraphFile,
}

const PREFIX: &str = "plan_";

/// Plans `render` (a node of `file`) for budget `b`, from `scene`. `chain` is where its BTF comes
/// from (for renderers with one).
pub fn plan(
    file: &GraphFile,
    render: &str,
    kind: RenderKind,
    scene: &Scene,
    chain: Option<&BtfChain>,
    b: f64,
) -> Result<Plan, PlanError> {
    if !(b.is_finite() && b >= 0.0) {
        return Err(PlanError::Budget(b));
    }
    if scene.camera_inside || scene.backfacing_fraction.is_some_and(|f| f > 0.5) {
        return Err(PlanError::CameraInside);
    }
    let mut out = file.clone();
    let mut decisions = Vec::new();
    let full = b == 0.0;
    let cheapest = b >= 1.0 || scene.visible_fraction == 0.0;
    let why_cheapest = if scene.visible_fraction == 0.0 {
        "the mesh is not in view: nothing it shows needs detail"
    } else {
        "a budget of 1 or more is FLIP's whole range: any model meets it"
    };

    if let (Some(port), Some(chain)) = (kind.btf_port(), chain) {
        let d = decide_btf(scene, full, cheapest, why_cheapest);
        apply_btf(&mut out, render, port, chain, &d.1);
        decisions.push(d.0);
    }
    if kind == RenderKind::Mesh {
        let connected = file
            .node(render)
            .is_some_and(|n| n.inputs.contains_key("mdf"));
        if connected {
            let (keep, reason) = if full {
                (true, "budget 0: the full model keeps the MDF".to_string())
            } else if cheapest {
                (false, why_cheapest.to_string())
            } else {
                match scene.shell_pixels {
                    Some(px) if px < 0.5 => (
                        false,
                        format!("the shell projects to {px:.2} px, under half a pixel: no silhouette to see"),
                    ),
                    Some(px) => (true, format!("the shell projects to {px:.2} px: silhouettes show")),
                    None => (true, "the shell's projection is unknown: kept".to_string()),
                }
            };
            if !keep {
                if let Some(n) = out.node_mut(render) {
                    n.inputs.remove("mdf");
                    n.params.insert("use_mdf".into(), json!(false));
                }
            }
            decisions.push(Decision {
                stage: "mdf",
                choice: json!({ "use_mdf": keep }),
                reason,
                predicted_cost: None,
            });
        }
    }
    if matches!(kind, RenderKind::Sss | RenderKind::Qh) {
        decisions.push(decide_sss(
            &mut out,
            file,
            render,
            scene,
            full,
            cheapest,
            why_cheapest,
        ));
    }
    prune(&mut out, file, render);
    Ok(Plan {
        decisions,
        file: out,
    })
}

/// The BTF's model: raw, or a PCA basis of `rank` (luma) and `chroma_rank` at `level`.
#[derive(Clone, Debug, PartialEq)]
pub struct BtfModel {
    pub raw: bool,
    pub level: f64,
    pub rank: u32,
    pub chroma_rank: u32,
}

/// The default YCbCr split: luma 8, chroma 2 each.
const LUMA_RANK: u32 = 8;
const CHROMA_RANK: u32 = 2;

fn decide_btf(
    scene: &Scene,
    full: bool,
    cheapest: bool,
    why_cheapest: &str,
) -> (Decision, BtfModel) {
    let coarsest = scene.tile_texels.map_or(0.0, |t| t.max(1.0).log2().ceil());
    if full {
        let m = BtfModel {
            raw: true,
            level: 0.0,
            rank: 0,
            chroma_rank: 0,
        };
        return (
            Decision {
                stage: "btf",
                choice: json!({ "model": "raw", "level": 0 }),
                reason: "budget 0: the full model is the raw BTF at full resolution".into(),
                predicted_cost: None,
            },
            m,
        );
    }
    let (level, level_reason) = if cheapest {
        (coarsest, why_cheapest.to_string())
    } else {
        match scene.texels_per_pixel {
            Some(t) if t >= 2.0 => {
                let l = t.log2().floor().min(coarsest);
                (
                    l,
                    format!(
                        "{t:.2} texels per pixel: level ⌊log₂ {t:.2}⌋ = {l} is what a pixel covers"
                    ),
                )
            }
            Some(t) => (0.0, format!("{t:.2} texels per pixel: full resolution")),
            None => (0.0, "texels per pixel unknown: full resolution".into()),
        }
    };
    let (rank, chroma_rank) = if cheapest {
        (1, 1)
    } else {
        (LUMA_RANK, CHROMA_RANK)
    };
    let average = level >= coarsest && coarsest > 0.0;
    let reason = format!(
        "{level_reason}; PCA in YCbCr at rank {rank}/{chroma_rank}/{chroma_rank}{}",
        if average {
            "; at the coarsest level the BTF is its average BRDF"
        } else {
            ""
        }
    );
    let texels = scene
        .tile_texels
        .map(|t| json!({ "texels_across": (t / level.exp2()).max(1.0).floor() }));
    (
        Decision {
            stage: "btf",
            choice: json!({ "model": "pca", "color": "ycbcr", "rank": rank, "chroma_rank": chroma_rank, "level": level }),
            reason,
            predicted_cost: texels,
        },
        BtfModel {
            raw: false,
            level,
            rank,
            chroma_rank,
        },
    )
}

fn apply_btf(out: &mut GraphFile, render: &str, port: &str, chain: &BtfChain, m: &BtfModel) {
    let set_input = |out: &mut GraphFile, from: String| {
        if let Some(n) = out.node_mut(render) {
            n.inputs.insert(port.into(), from);
        }
    };
    if m.raw {
        set_input(out, chain.raw.clone());
        return;
    }
    let pca = format!("{PREFIX}pca");
    let lod = format!("{PREFIX}lod");
    let mut pca_params = Map::new();
    pca_params.insert("color".into(), json!("ycbcr"));
    pca_params.insert("rank".into(), json!(m.rank));
    pca_params.insert("chroma_rank".into(), json!(m.chroma_rank));
    upsert(
        out,
        &pca,
        "btf.pca",
        pca_params,
        [("btf".to_string(), chain.raw.clone())].into(),
    );
    let mut lod_params = Map::new();
    lod_params.insert("level".into(), json!(m.level));
    upsert(
        out,
        &lod,
        "btf.lod",
        lod_params,
        [("basis".to_string(), format!("{pca}.basis"))].into(),
    );
    set_input(out, format!("{lod}.basis"));
}

fn upsert(
    out: &mut GraphFile,
    id: &str,
    kind: &str,
    params: Map<String, Value>,
    inputs: BTreeMap<String, String>,
) {
    let decl = mesoflow_graph::NodeDecl {
        kind: kind.into(),
        params,
        inputs,
    };
    match out.node_mut(id) {
        Some(n) => *n = decl,
        None => out.nodes.push((id.to_string(), decl)),
    }
}

fn decide_sss(
    out: &mut GraphFile,
    file: &GraphFile,
    render: &str,
    scene: &Scene,
    full: bool,
    cheapest: bool,
    why_cheapest: &str,
) -> Decision {
    let set = |out: &mut GraphFile, k: &str, v: Value| {
        if let Some(n) = out.node_mut(render) {
            n.params.insert(k.into(), v);
        }
    };
    if full {
        set(out, "mode", json!("diffusion"));
        set(out, "threshold", json!(0.0));
        // The full model's profile is PBD, where the profile comes from `sss.profile`.
        let profile_node = file
            .node(render)
            .and_then(|n| n.inputs.get("profile"))
            .and_then(|s| s.split_once('.').map(|(n, _)| n.to_string()));
        if let Some(id) = profile_node {
            if let Some(n) = out.node_mut(&id).filter(|n| n.kind == "sss.profile") {
                n.params.insert("model".into(), json!("pbd"));
            }
        }
        return Decision {
            stage: "sss",
            choice: json!({ "mode": "diffusion", "threshold": 0.0, "profile": "pbd" }),
            reason: "budget 0: the full model gathers the PBD profile by brute force".into(),
            predicted_cost: None,
        };
    }
    let brdf_reason = if cheapest {
        Some(why_cheapest.to_string())
    } else {
        scene.mfp_pixels.filter(|p| *p < 0.5).map(|p| {
            format!(
                "the longest effective mean free path ({:.3} mm) is {p:.2} of a pixel footprint: scattering stays inside a pixel",
                scene.mfp_mm.unwrap_or(f64::NAN)
            )
        })
    };
    if let Some(reason) = brdf_reason {
        set(out, "mode", json!("brdf"));
        return Decision {
            stage: "sss",
            choice: json!({ "mode": "brdf" }),
            reason,
            predicted_cost: Some(json!({ "samples": 0 })),
        };
    }
    set(out, "mode", json!("diffusion"));
    let default = scene.mfp_min_mm.map(|m| 0.25 * m);
    let pixel = scene.pixel_footprint_mm.map(|f| 0.5 * f);
    let (choice, reason) = match (default, pixel) {
        (Some(d), Some(px)) if px > d => {
            set(out, "spacing", json!(px));
            (
                json!({ "mode": "diffusion", "spacing_mm": px }),
                format!("scattering spans {:.2} px: gathered, with samples every half pixel footprint ({px:.4} mm) rather than every quarter mean free path ({d:.4} mm)", scene.mfp_pixels.unwrap_or(f64::NAN)),
            )
        }
        _ => (
            json!({ "mode": "diffusion" }),
            format!(
                "scattering spans {:.2} px: gathered at the profile's own spacing (a quarter of the shortest mean free path)",
                scene.mfp_pixels.unwrap_or(f64::NAN)
            ),
        ),
    };
    Decision {
        stage: "sss",
        choice,
        reason,
        predicted_cost: None,
    }
}

/// Removes the nodes the plan disconnected: those that fed something in `before` and feed
/// nothing now, unless they write files (a writer is a result in itself). Repeats until stable.
fn prune(out: &mut GraphFile, before: &GraphFile, render: &str) {
    let fed = |f: &GraphFile| -> BTreeSet<String> {
        f.nodes
            .iter()
            .flat_map(|(_, d)| d.inputs.values())
            .filter_map(|s| s.split_once('.').map(|(n, _)| n.to_string()))
            .collect()
    };
    let had_consumers = fed(before);
    loop {
        let now = fed(out);
        let orphan: Vec<String> = out
            .nodes
            .iter()
            .filter(|(id, d)| {
                id != render
                    && !now.contains(id)
                    && (had_consumers.contains(id) || id.starts_with(PREFIX))
                    && !d.kind.ends_with(".write")
                    && !d.kind.starts_with("btf.write")
            })
            .map(|(id, _)| id.clone())
            .collect();
        if orphan.is_empty() {
            break;
        }
        out.nodes.retain(|(id, _)| !orphan.contains(id));
    }
}

/// Where the BTF of `render`'s `port` comes from: through `btf.lod` and `btf.pca` back to the
/// raw BTF.
pub fn btf_chain(file: &GraphFile, render: &str, port: &str) -> Option<BtfChain> {
    let mut from = file.node(render)?.inputs.get(port)?.clone();
    loop {
        let (id, _) = from.split_once('.')?;
        let n = file.node(id)?;
        match n.kind.as_str() {
            "btf.lod" => from = n.inputs.get("basis")?.clone(),
            "btf.pca" => from = n.inputs.get("btf")?.clone(),
            _ => return Some(BtfChain { raw: from }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graph() -> GraphFile {
        GraphFile::parse(
            r#"{"mesoflow": 1, "nodes": {
              "hf": {"kind": "heightfield.procedural"},
              "capture": {"kind": "btf.capture", "inputs": {"height": "hf.height"}},
              "pca": {"kind": "btf.pca", "inputs": {"btf": "capture.btf"}},
              "mdf": {"kind": "mdf.tabulate", "inputs": {"height": "hf.height"}},
              "torus": {"kind": "mesh.primitive"},
              "r": {"kind": "render.mesh", "inputs": {"mesh": "torus.mesh", "btf": "pca.basis", "mdf": "mdf.mdf"}},
              "png": {"kind": "image.write", "inputs": {"image": "r.image"}, "params": {"path": "r.png"}}
            }}"#,
        )
        .unwrap()
    }

    fn scene(tpp: f64, shell_px: f64) -> Scene {
        Scene {
            visible_fraction: 0.4,
            backfacing_fraction: Some(0.0),
            pixel_footprint_mm: Some(0.1),
            texels_per_pixel: Some(tpp),
            tile_texels: Some(64.0),
            shell_pixels: Some(shell_px),
            ..Default::default()
        }
    }

    fn run(s: &Scene, b: f64) -> Plan {
        let f = graph();
        let chain = btf_chain(&f, "r", "btf").unwrap();
        assert_eq!(chain.raw, "capture.btf");
        plan(&f, "r", RenderKind::Mesh, s, Some(&chain), b).unwrap()
    }

    #[test]
    fn budget_zero_is_the_full_model() {
        let p = run(&scene(10.0, 0.1), 0.0);
        let r = p.file.node("r").unwrap();
        assert_eq!(r.inputs["btf"], "capture.btf");
        assert_eq!(r.inputs["mdf"], "mdf.mdf");
        // The user's PCA fed only the render: disconnected, it is pruned.
        assert!(p.file.node("pca").is_none());
    }

    #[test]
    fn far_views_get_a_coarse_level_and_no_mdf() {
        // 10 texels per pixel: ⌊log₂ 10⌋ = 3; a 0.2 px shell is invisible.
        let p = run(&scene(10.0, 0.2), 0.05);
        assert_eq!(p.file.node("plan_lod").unwrap().params["level"], json!(3.0));
        let r = p.file.node("r").unwrap();
        assert_eq!(r.inputs["btf"], "plan_lod.basis");
        assert!(!r.inputs.contains_key("mdf"));
        assert!(
            p.file.node("mdf").is_none(),
            "the MDF tabulation is no longer computed"
        );
        assert!(p.file.node("png").is_some(), "writers stay");
    }

    #[test]
    fn near_views_keep_full_resolution_and_the_mdf() {
        let p = run(&scene(0.3, 3.0), 0.05);
        assert_eq!(p.file.node("plan_lod").unwrap().params["level"], json!(0.0));
        assert_eq!(p.file.node("r").unwrap().inputs["mdf"], "mdf.mdf");
    }

    #[test]
    fn an_enormous_budget_picks_the_cheapest_never_nothing() {
        let p = run(&scene(0.3, 3.0), 1e9);
        // 64 texels: level 6 is one texel, the average BRDF; rank 1.
        assert_eq!(p.file.node("plan_lod").unwrap().params["level"], json!(6.0));
        assert_eq!(p.file.node("plan_pca").unwrap().params["rank"], json!(1));
        assert_eq!(p.file.node("r").unwrap().inputs["btf"], "plan_lod.basis");
    }

    #[test]
    fn a_camera_inside_and_a_bad_budget_are_errors() {
        let mut s = scene(1.0, 1.0);
        s.backfacing_fraction = Some(0.9);
        let f = graph();
        assert!(matches!(
            plan(&f, "r", RenderKind::Mesh, &s, None, 0.1),
            Err(PlanError::CameraInside)
        ));
        for b in [-1.0, f64::NAN] {
            assert!(matches!(
                plan(&f, "r", RenderKind::Mesh, &scene(1.0, 1.0), None, b),
                Err(PlanError::Budget(_))
            ));
        }
    }

    #[test]
    fn scattering_under_half_a_pixel_becomes_a_brdf() {
        let f = GraphFile::parse(
            r#"{"mesoflow": 1, "nodes": {
              "m": {"kind": "sss.material", "params": {"preset": "ketchup"}},
              "pr": {"kind": "sss.profile", "inputs": {"material": "m.material"}},
              "torus": {"kind": "mesh.primitive"},
              "r": {"kind": "sss.render", "inputs": {"mesh": "torus.mesh", "material": "m.material", "profile": "pr.profile"}}
            }}"#,
        )
        .unwrap();
        let s = Scene {
            visible_fraction: 0.3,
            pixel_footprint_mm: Some(2.0),
            mfp_mm: Some(0.5),
            mfp_min_mm: Some(0.1),
            mfp_pixels: Some(0.25),
            ..Default::default()
        };
        let p = plan(&f, "r", RenderKind::Sss, &s, None, 0.05).unwrap();
        assert_eq!(p.file.node("r").unwrap().params["mode"], json!("brdf"));
        // Nearer, scattering spans pixels: gathered, samples every half footprint.
        let near = Scene {
            pixel_footprint_mm: Some(0.4),
            mfp_pixels: Some(1.25),
            ..s.clone()
        };
        let p = plan(&f, "r", RenderKind::Sss, &near, None, 0.05).unwrap();
        let r = p.file.node("r").unwrap();
        assert_eq!(r.params["mode"], json!("diffusion"));
        assert_eq!(r.params["spacing"], json!(0.2));
        // Budget 0: brute force, PBD.
        let p = plan(&f, "r", RenderKind::Sss, &near, None, 0.0).unwrap();
        assert_eq!(p.file.node("r").unwrap().params["threshold"], json!(0.0));
        assert_eq!(p.file.node("pr").unwrap().params["model"], json!("pbd"));
    }
}
