//! The planner's decisions: from what a view shows (`scene.footprint`'s measurements) and a FLIP
//! budget B (the mean FLIP over the object's pixels), the cheapest model per stage, each with its
//! reason, its predicted error and its predicted cost, as edits to the graph.
//!
//! - B = 0 asks for the full model: raw BTF at λ = 0, the MDF, the PBD profile gathered by brute
//!   force. B ≥ 1 (FLIP's whole range) allows the cheapest: the BTF's average BRDF at rank 1, no
//!   MDF, subsurface scattering as a BRDF. Never nothing.
//! - Otherwise each stage takes its share of B — for `render.mesh`'s BTF and MDF the share that
//!   predicts the least render time ([`Split::Joint`]) or half each ([`Split::Equal`]); half each
//!   for `qh.render`'s BTF and subsurface; all of it for `sss.render` — and the cheapest
//!   candidate whose error, predicted by the measured model ([`calibration`]), fits it:
//!   - BTF: PCA in YCbCr at rank r (chroma r/4) and level λ, by memory; none fits → the raw BTF;
//!   - MDF: left out when its predicted error fits (always when the shell projects under half a
//!     pixel); where kept, tabulated 8, 4 or 2 times coarser than its height field (the
//!     coarsest that still has a texel per pixel and is predicted within the share);
//!   - subsurface: the BRDF approximation, or the brute-force gather with samples 4, 2, 1 or ½
//!     pixel footprints apart (never closer than the default spacing), by render time; none
//!     fits → the full model's gather (brute force, default spacing). Scattering under half a
//!     pixel is always the BRDF approximation.
//!   - synthesis (a `synthesis.texture` the renderer reads): stopped 1 or 2 pyramid levels early
//!     (2 or 4 times fewer texels per side) when that still gives a texel per pixel and is
//!     predicted within a tenth of the budget.
//!
//! A prediction beyond the calibrated range (a view nearer or farther than any calibrated one)
//! is not trusted: there the stage keeps the graph's own model, except for the half-pixel rules
//! and the cheapest plan. Stage errors are assumed to add; the verification sweep (benches/plan_verify.rs) measures
//! how far that and the calibration carry to a scene that is not the calibration scene.

pub mod calibration;

use mesoflow_graph::GraphFile;
use mesoflow_nodes::render::footprint::shadow_resolution;
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
    pub btf_floats: Option<f64>,
    pub btf_pairs: Option<f64>,
    pub shell_pixels: Option<f64>,
    pub silhouette_fraction: Option<f64>,
    pub object_pixels: Option<f64>,
    pub mfp_mm: Option<f64>,
    pub mfp_min_mm: Option<f64>,
    pub mfp_pixels: Option<f64>,
    /// Other textures over the tile, by the output that gives them ("node.port"): the MDF's
    /// height field, a synthesis's exemplar and target guide ([`texture_sources`]).
    pub textures: BTreeMap<String, TextureView>,
}

/// What the view shows of a texture over the tile (`scene.footprint` with `texture`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TextureView {
    pub texels_per_pixel: f64,
    pub width: usize,
    pub height: usize,
}

impl TextureView {
    pub fn from_metrics(m: &BTreeMap<String, f64>) -> Option<TextureView> {
        let g = |k: &str| m.get(k).copied().filter(|v| v.is_finite() && *v > 0.0);
        Some(TextureView {
            texels_per_pixel: g("texture_texels_per_pixel")?,
            width: g("texture_width")? as usize,
            height: g("texture_height")? as usize,
        })
    }

    /// Texels per pixel of a `w` × `h` texture over the same tile: they go as the square root
    /// of the texel count (the footprint's texel is the geometric mean of its sides).
    pub fn at(&self, w: usize, h: usize) -> f64 {
        let ratio = (w * h) as f64 / (self.width * self.height).max(1) as f64;
        self.texels_per_pixel * ratio.sqrt()
    }
}

/// The outputs ("node.port") whose texels per pixel the decisions need, each measured by a probe
/// of its own: the height field an `mdf.tabulate` feeding `render` reads, and the exemplar and
/// target guide of each `synthesis.texture` whose image `render` reads.
pub fn texture_sources(file: &GraphFile, render: &str) -> Vec<String> {
    let mut out = Vec::new();
    let Some(r) = file.node(render) else {
        return out;
    };
    for from in r.inputs.values() {
        let Some(n) = from.split_once('.').and_then(|(id, _)| file.node(id)) else {
            continue;
        };
        let ports: &[&str] = match n.kind.as_str() {
            "mdf.tabulate" => &["height"],
            "synthesis.texture" => &["exemplar", "target_guide"],
            _ => &[],
        };
        for p in ports {
            if let Some(src) = n.inputs.get(*p) {
                if !out.contains(src) {
                    out.push(src.clone());
                }
            }
        }
    }
    out
}

impl Scene {
    /// The scene a probe measured. `visible_fraction` decides whether anything is seen at all
    /// (none seen plans the cheapest model), so a probe that did not report it, or reported a
    /// non-finite value, is an error: read as 0 it would plan the cheapest model for any view.
    pub fn from_metrics(m: &BTreeMap<String, f64>) -> Result<Scene, PlanError> {
        let g = |k: &str| m.get(k).copied().filter(|v| v.is_finite());
        Ok(Scene {
            visible_fraction: g("visible_fraction")
                .ok_or(PlanError::MissingMetric("visible_fraction"))?,
            camera_inside: g("camera_inside").is_some_and(|v| v > 0.5),
            backfacing_fraction: g("backfacing_fraction"),
            pixel_footprint_mm: g("pixel_footprint_mm"),
            texels_per_pixel: g("texels_per_pixel"),
            tile_texels: g("tile_texels"),
            btf_floats: g("btf_floats"),
            btf_pairs: g("btf_pairs"),
            shell_pixels: g("shell_pixels"),
            silhouette_fraction: g("silhouette_fraction"),
            object_pixels: g("object_pixels"),
            mfp_mm: g("mfp_mm"),
            mfp_min_mm: g("mfp_min_mm"),
            mfp_pixels: g("mfp_pixels"),
            textures: BTreeMap::new(),
        })
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
            ("btf_floats", self.btf_floats),
            ("btf_pairs", self.btf_pairs),
            ("shell_pixels", self.shell_pixels),
            ("silhouette_fraction", self.silhouette_fraction),
            ("object_pixels", self.object_pixels),
            ("mfp_mm", self.mfp_mm),
            ("mfp_min_mm", self.mfp_min_mm),
            ("mfp_pixels", self.mfp_pixels),
        ] {
            if let Some(v) = v {
                o.insert(k.into(), json!(v));
            }
        }
        if !self.textures.is_empty() {
            let t: Map<String, Value> = self
                .textures
                .iter()
                .map(|(k, v)| {
                    (
                        k.clone(),
                        json!({ "texels_per_pixel": v.texels_per_pixel, "width": v.width, "height": v.height }),
                    )
                })
                .collect();
            o.insert("textures".into(), Value::Object(t));
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
    /// The FLIP the measured model predicts for this choice (0 for the full model's own
    /// choice); absent where the model has nothing to say.
    pub predicted_error: Option<f64>,
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
    /// Stages sharing the budget.
    fn stages(self) -> f64 {
        match self {
            RenderKind::Sss => 1.0,
            RenderKind::Mesh | RenderKind::Qh => 2.0,
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
    #[error("{0} pixels per degree: the viewer's ppd is a number ≥ 0.5")]
    Ppd(f64),
    #[error("{0}")]
    Calibration(String),
    #[error("the view's probe (scene.footprint) reported no finite `{0}`: cannot plan from an unknown view")]
    MissingMetric(&'static str),
}

/// The chain a BTF reaches the renderer through.
#[derive(Clone, Debug, PartialEq)]
pub struct BtfChain {
    /// The node and port giving the raw BTF (what `btf.pca` reads, or the renderer directly).
    pub raw: String,
}

/// The error the view may show: mean FLIP over the object's pixels, for a viewer at `ppd`
/// pixels per degree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Budget {
    pub flip: f64,
    pub ppd: f64,
}

#[cfg(test)]
impl Budget {
    /// `flip` at FLIP's default viewing condition (67 pixels per degree).
    pub fn flip(flip: f64) -> Budget {
        Budget {
            flip,
            ppd: mesoflow_nodes::image::flip::DEFAULT_PPD,
        }
    }
}

/// How a render's budget is shared between its BTF and MDF stages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    /// Half each.
    Equal,
    /// Whichever share of nine (0, B/8, …, B) to the BTF gives the least predicted render time
    /// (the product of the stages' predicted time ratios; memory breaks ties): the budget goes
    /// where it saves the most time per unit of error.
    Joint,
}

/// Decisions and the graph edits that carry them out.
pub struct Plan {
    pub decisions: Vec<Decision>,
    pub file: GraphFile,
    /// The budget each stage was given, by stage.
    pub shares: Vec<(&'static str, f64)>,
    /// The calibrated viewing condition the predictions are for, and whether the viewer's lies
    /// within the calibrated ones.
    pub calibrated_ppd: f64,
    pub ppd_inside: bool,
}

/// A decision's predicted render time over the full model's (1 where it says none).
fn time_ratio(d: &Decision) -> f64 {
    d.predicted_cost
        .as_ref()
        .and_then(|c| c["render_time_vs_full"].as_f64())
        .unwrap_or(1.0)
}

fn floats_of(d: &Decision) -> f64 {
    d.predicted_cost
        .as_ref()
        .and_then(|c| c["floats"].as_f64())
        .unwrap_or(f64::INFINITY)
}

const PREFIX: &str = "plan_";

/// What every stage's decision reads: the measured model, the graph as given, the render node
/// and what its view shows, and whether the budget asks for the full or the cheapest model.
#[derive(Clone, Copy)]
struct Stage<'a> {
    model: &'a calibration::Calibration,
    file: &'a GraphFile,
    render: &'a str,
    kind: RenderKind,
    scene: &'a Scene,
    full: bool,
    cheapest: bool,
    why_cheapest: &'a str,
}

/// Plans `render` (a node of `file`) for `budget`, from `scene`. `chain` is where its BTF comes
/// from (for renderers with one).
pub fn plan(
    file: &GraphFile,
    render: &str,
    kind: RenderKind,
    scene: &Scene,
    chain: Option<&BtfChain>,
    budget: Budget,
    split: Split,
) -> Result<Plan, PlanError> {
    let b = budget.flip;
    if !(b.is_finite() && b >= 0.0) {
        return Err(PlanError::Budget(b));
    }
    if !(budget.ppd.is_finite() && budget.ppd >= 0.5) {
        return Err(PlanError::Ppd(budget.ppd));
    }
    if scene.camera_inside || scene.backfacing_fraction.is_some_and(|f| f > 0.5) {
        return Err(PlanError::CameraInside);
    }
    let model = calibration::Calibration::builtin(budget.ppd).map_err(PlanError::Calibration)?;
    let share = b / kind.stages();
    let mut out = file.clone();
    let mut decisions = Vec::new();
    let full = b == 0.0;
    let cheapest = b >= 1.0 || scene.visible_fraction == 0.0;
    let why_cheapest = if scene.visible_fraction == 0.0 {
        "the mesh is not in view: nothing it shows needs detail"
    } else {
        "a budget of 1 or more is FLIP's whole range: any model meets it"
    };
    let cx = Stage {
        model: &model,
        file,
        render,
        kind,
        scene,
        full,
        cheapest,
        why_cheapest,
    };

    let mut shares = Vec::new();
    // The BTF's share: half for the equal split; for the joint split, the one of nine that
    // predicts the least render time for BTF and MDF together.
    let mdf_connected = kind == RenderKind::Mesh
        && file
            .node(render)
            .is_some_and(|n| n.inputs.contains_key("mdf"));
    let btf_share = match (split, kind.btf_port().zip(chain), mdf_connected) {
        (Split::Joint, Some(_), true) if !full && !cheapest => {
            // Inside this arm neither the full nor the cheapest model is asked for.
            let try_share = |s: f64| {
                let (bd, _) = decide_btf(&cx, s);
                let mut scratch = file.clone();
                let md = decide_mdf(&cx, &mut scratch, b - s);
                let t = time_ratio(&bd) * md.as_ref().map_or(1.0, time_ratio);
                (t, floats_of(&bd))
            };
            (0..=8)
                .map(|k| b * k as f64 / 8.0)
                .map(|s| (s, try_share(s)))
                .min_by(|x, y| x.1 .0.total_cmp(&y.1 .0).then(x.1 .1.total_cmp(&y.1 .1)))
                .map_or(share, |(s, _)| s)
        }
        _ => share,
    };
    if let (Some(port), Some(chain)) = (kind.btf_port(), chain) {
        let d = decide_btf(&cx, btf_share);
        apply_btf(&mut out, render, port, chain, &d.1);
        decisions.push(d.0);
        shares.push(("btf", btf_share));
    }
    if kind == RenderKind::Mesh {
        let mdf_share = if chain.is_some() {
            b - btf_share
        } else {
            share
        };
        if let Some(d) = decide_mdf(&cx, &mut out, mdf_share) {
            decisions.push(d);
            shares.push(("mdf", mdf_share));
            if let Some(d) = decide_mdf_resolution(&cx, &mut out, mdf_share) {
                decisions.push(d);
            }
        }
    }
    if matches!(kind, RenderKind::Sss | RenderKind::Qh) {
        decisions.push(decide_sss(&cx, &mut out, share));
        shares.push(("sss", share));
        if let Some(d) = decide_threshold(&cx, &mut out, share) {
            decisions.push(d);
        }
        if let Some(d) = decide_profile(&cx, &mut out, share) {
            decisions.push(d);
        }
    }
    if let Some(d) = decide_shadows(&cx, &mut out, b) {
        decisions.push(d);
    }
    decisions.extend(decide_synthesis(&cx, &mut out, b));
    prune(&mut out, file, render);
    Ok(Plan {
        decisions,
        file: out,
        shares,
        calibrated_ppd: model.ppd,
        ppd_inside: model.ppd_inside,
    })
}

/// The MDF: left out when the shell is under half a pixel, or when leaving it out is predicted
/// within the stage's share; `None` when the render has no MDF connected.
fn decide_mdf(cx: &Stage, out: &mut GraphFile, share: f64) -> Option<Decision> {
    let Stage {
        model,
        file,
        render,
        scene,
        full,
        cheapest,
        why_cheapest,
        ..
    } = *cx;
    if !file.node(render)?.inputs.contains_key("mdf") {
        return None;
    }

    let predicted_off =
        scene
            .shell_pixels
            .zip(scene.silhouette_fraction)
            .and_then(|(px, contour)| {
                model.mdf_off_per_contour.at(px).map(|(e, inside)| {
                    let band = calibration::band_fraction(contour, px);
                    ((e * band).min(1.0), inside)
                })
            });
    let (keep, reason, predicted) = if full {
        (
            true,
            "budget 0: the full model keeps the MDF".to_string(),
            Some(0.0),
        )
    } else if cheapest {
        (false, why_cheapest.to_string(), predicted_off.map(|p| p.0))
    } else {
        match (scene.shell_pixels, predicted_off) {
            (Some(px), _) if px < 0.5 => (
                false,
                format!("the shell projects to {px:.2} px, under half a pixel: no silhouette to see"),
                predicted_off.map(|p| p.0),
            ),
            (Some(px), Some((e, true))) if e <= share => (
                false,
                format!("the shell projects to {px:.2} px; leaving the MDF out is predicted to cost FLIP {e:.3}, within this stage's {share:.3}"),
                Some(e),
            ),
            (Some(px), Some((e, true))) => (
                true,
                format!("the shell projects to {px:.2} px; leaving the MDF out is predicted to cost FLIP {e:.3}, over this stage's {share:.3}"),
                Some(0.0),
            ),
            (Some(px), Some((_, false))) => (
                true,
                format!("the shell projects to {px:.2} px, beyond the calibrated range: the MDF is kept"),
                Some(0.0),
            ),
            _ => (true, "the shell's projection is unknown: kept".to_string(), None),
        }
    };
    if !keep {
        if let Some(n) = out.node_mut(render) {
            n.inputs.remove("mdf");
            n.params.insert("use_mdf".into(), json!(false));
        }
    }
    let time = scene
        .shell_pixels
        .and_then(|px| model.mdf_off_time.at(px))
        .filter(|_| !keep)
        .map(|(t, _)| json!({ "render_time_vs_full": t }));
    Some(Decision {
        stage: "mdf",
        choice: json!({ "use_mdf": keep }),
        reason,
        predicted_error: predicted,
        predicted_cost: time,
    })
}

/// The MDF's table, where kept: tabulated 8, 4 or 2 times coarser than its height field — the
/// coarsest that still has a texel per pixel where the view sees the tile finest (the resolution
/// the footprint needs) and that the measured model predicts within the stage's share: the MDF
/// was kept because leaving it out costs more than the share, and a coarser table is the
/// stage's next cheaper model. `None` where the render has no MDF, the budget asks for the full
/// model, or the table is not tabulated from a height field.
fn decide_mdf_resolution(cx: &Stage, out: &mut GraphFile, share: f64) -> Option<Decision> {
    let Stage {
        model,
        file,
        render,
        scene,
        full,
        ..
    } = *cx;
    if full {
        return None;
    }
    let from = out.node(render)?.inputs.get("mdf")?.clone();
    let (id, port) = from.split_once('.')?;
    let node = file.node(id).filter(|n| n.kind == "mdf.tabulate")?;
    let height = node.inputs.get("height")?;
    let Some(tex) = scene.textures.get(height) else {
        return Some(Decision {
            stage: "mdf_resolution",
            choice: json!({ "resolution": node.params.get("resolution") }),
            reason: "the height field's texels per pixel are unknown: the table is kept".into(),
            predicted_error: Some(0.0),
            predicted_cost: None,
        });
    };
    let width = node
        .params
        .get("resolution")
        .and_then(Value::as_u64)
        .map_or(tex.width, |w| w as usize);
    let height_texels = (width as f64 * tex.height as f64 / tex.width as f64).round() as usize;
    let tpp = tex.at(width, height_texels);
    let band = scene
        .silhouette_fraction
        .zip(scene.shell_pixels)
        .map(|(s, px)| calibration::band_fraction(s, px));
    let limit = share;
    let mut why_not = Vec::new();
    let pick = model.mdf_resolution.iter().find_map(|c| {
        let coarse = width / c.factor as usize;
        if coarse < 8 || (c.factor as f64) > tpp {
            return None;
        }
        let (e, inside) = c.flip_per_contour.at(tpp)?;
        let e = (e * band?).min(1.0);
        if inside && e <= limit {
            Some((c, coarse, e))
        } else {
            why_not.push(format!(
                "{}× coarser is predicted at FLIP {e:.4}{}",
                c.factor,
                range_note(inside)
            ));
            None
        }
    });
    let Some((c, coarse, e)) = pick else {
        let detail = if why_not.is_empty() {
            String::new()
        } else {
            format!("; {}", why_not.join(", "))
        };
        return Some(Decision {
            stage: "mdf_resolution",
            choice: json!({ "resolution": width }),
            reason: format!(
                "the table has {tpp:.2} texels per pixel where the tile is seen finest: kept at {width} texels (a coarser one must keep a texel per pixel and stay within {share:.3}{detail})"
            ),
            predicted_error: Some(0.0),
            predicted_cost: None,
        });
    };
    let mut params = node.params.clone();
    params.insert("resolution".into(), json!(coarse));
    let copy = format!("{PREFIX}mdf");
    upsert(out, &copy, "mdf.tabulate", params, node.inputs.clone());
    out.node_mut(render)?
        .inputs
        .insert("mdf".into(), format!("{copy}.{port}"));
    let mut cost = json!({ "table_entries_vs_full": 1.0 / (c.factor * c.factor) as f64 });
    if let Some(t) = c.time {
        cost["tabulation_time_vs_full"] = json!(t);
    }
    Some(Decision {
        stage: "mdf_resolution",
        choice: json!({ "resolution": coarse }),
        reason: format!(
            "the table has {tpp:.2} texels per pixel where the tile is seen finest: tabulated {}× coarser ({coarse} texels, not {width}), predicted at FLIP {e:.4}, within this stage's {share:.3}",
            c.factor
        ),
        predicted_error: Some(e),
        predicted_cost: Some(cost),
    })
}

/// Each `synthesis.texture` whose image the render reads: stopped 2 or 1 pyramid levels before
/// its finest (its output 4 or 2 times smaller per side, the full run's own coarser result) —
/// the earliest that still gives a texel per pixel where the view sees the tile finest (no more
/// output texels than the view shows) and that the measured model predicts within a tenth of the
/// budget; with a budget of 1 or more, the earliest whose patches fit. In a copy the render
/// reads, never in place (other consumers may want the full texture).
fn decide_synthesis(cx: &Stage, out: &mut GraphFile, b: f64) -> Vec<Decision> {
    use mesoflow_nodes::synthesis::{optimize, texture};
    let Stage {
        model,
        file,
        render,
        scene,
        full,
        cheapest,
        ..
    } = *cx;
    let mut decisions = Vec::new();
    let Some(r) = file.node(render) else {
        return decisions;
    };
    if full {
        return decisions;
    }
    let sources: BTreeSet<String> = r
        .inputs
        .values()
        .filter_map(|f| f.split_once('.'))
        .filter(|(id, _)| file.node(id).is_some_and(|n| n.kind == "synthesis.texture"))
        .map(|(id, _)| id.to_string())
        .collect();
    for id in sources {
        let Some(node) = file.node(&id) else { continue };
        let Ok(p) = serde_json::from_value::<texture::Params>(Value::Object(node.params.clone()))
        else {
            continue;
        };
        let view = |port: &str| node.inputs.get(port).and_then(|s| scene.textures.get(s));
        let Some(ex) = view("exemplar") else {
            decisions.push(Decision {
                stage: "synthesis",
                choice: json!({ "node": id, "stop_level": p.stop_level }),
                reason: format!("`{id}`'s exemplar is not measured: kept"),
                predicted_error: Some(0.0),
                predicted_cost: None,
            });
            continue;
        };
        let default = view("target_guide").map_or((ex.width, ex.height), |g| (g.width, g.height));
        let w = if p.width == 0 {
            default.0
        } else {
            p.width as usize
        };
        let h = if p.height == 0 {
            default.1
        } else {
            p.height as usize
        };
        let tpp = ex.at(w, h);
        let mut sizes: Vec<usize> = p.patch_sizes.iter().map(|&z| z as usize).collect();
        sizes.sort_unstable_by(|a, b| b.cmp(a));
        sizes.dedup();
        let fits = |k: u32| {
            let s = optimize::Settings {
                width: w,
                height: h,
                levels: p.levels as usize,
                stop: k as usize,
                sizes: sizes.clone(),
                iterations: 1,
                exponent: p.exponent,
                periodic: p.periodic,
                rounds: 1,
                seed: 0,
            };
            k < p.levels
                && optimize::plan((ex.width, ex.height), (w, h), &s)
                    .last()
                    .is_some_and(|(l, _)| *l == k as usize)
        };
        let limit = 0.1 * b;
        let pick: Option<(u32, Option<f64>, Option<f64>)> = if cheapest {
            (p.stop_level + 1..p.levels)
                .rev()
                .find(|&k| fits(k))
                .map(|k| {
                    let c = model.synthesis.iter().find(|c| c.stop_level == k);
                    (
                        k,
                        c.and_then(|c| c.flip.at(tpp)).map(|e| e.0),
                        c.and_then(|c| c.time),
                    )
                })
        } else {
            model.synthesis.iter().find_map(|c| {
                let k = c.stop_level;
                if k <= p.stop_level || (1u64 << k) as f64 > tpp || !fits(k) {
                    return None;
                }
                let (e, inside) = c.flip.at(tpp)?;
                (inside && e <= limit).then_some((k, Some(e), c.time))
            })
        };
        let Some((k, e, time)) = pick else {
            decisions.push(Decision {
                stage: "synthesis",
                choice: json!({ "node": id, "stop_level": p.stop_level }),
                reason: format!(
                    "`{id}`'s {w} × {h} output has {tpp:.2} texels per pixel where the tile is seen finest: kept (stopping a level early must keep a texel per pixel, fit its patches and be predicted within a tenth of {b:.3})"
                ),
                predicted_error: Some(0.0),
                predicted_cost: None,
            });
            continue;
        };
        let copy = format!("{PREFIX}{id}");
        let mut params = node.params.clone();
        params.insert("stop_level".into(), json!(k));
        upsert(out, &copy, "synthesis.texture", params, node.inputs.clone());
        if let Some(rn) = out.node_mut(render) {
            for from in rn.inputs.values_mut() {
                if let Some((src, port)) = from.split_once('.') {
                    if src == id {
                        *from = format!("{copy}.{port}");
                    }
                }
            }
        }
        let (ow, oh) = (w >> k, h >> k);
        let mut cost = json!({ "texels_vs_full": (ow * oh) as f64 / (w * h) as f64 });
        if let Some(t) = time {
            cost["synthesis_time_vs_full"] = json!(t);
        }
        let why = if cheapest {
            "a budget of 1 or more: the earliest stop whose patches fit".to_string()
        } else {
            format!(
                "predicted at FLIP {:.4}, within a tenth of {b:.3}",
                e.unwrap_or(f64::NAN)
            )
        };
        decisions.push(Decision {
            stage: "synthesis",
            choice: json!({ "node": id, "stop_level": k, "size": [ow, oh] }),
            reason: format!(
                "`{id}`'s {w} × {h} output has {tpp:.2} texels per pixel where the tile is seen finest: stopped {k} level(s) early ({ow} × {oh}), {why}"
            ),
            predicted_error: e,
            predicted_cost: Some(cost),
        });
    }
    decisions
}

/// The BTF's model: raw, or a PCA basis of `rank` (luma) and `chroma_rank` at `level`.
#[derive(Clone, Debug, PartialEq)]
pub struct BtfModel {
    pub raw: bool,
    pub level: f64,
    pub rank: u32,
    pub chroma_rank: u32,
}

/// " (beyond the calibrated range: its nearest end)" where a prediction is extrapolated.
fn range_note(inside: bool) -> &'static str {
    if inside {
        ""
    } else {
        " (beyond the calibrated range: its nearest end)"
    }
}

fn decide_btf(cx: &Stage, share: f64) -> (Decision, BtfModel) {
    let Stage {
        model,
        scene,
        full,
        cheapest,
        why_cheapest,
        ..
    } = *cx;
    let coarsest = scene.tile_texels.map_or(0.0, |t| t.max(1.0).log2().ceil());
    let raw = |reason: String, predicted: f64| {
        (
            Decision {
                stage: "btf",
                choice: json!({ "model": "raw", "level": 0 }),
                reason,
                predicted_error: Some(predicted),
                predicted_cost: Some(match scene.btf_floats {
                    Some(f) => json!({ "floats": f, "render_time_vs_full": 1.0 }),
                    None => json!({ "render_time_vs_full": 1.0 }),
                }),
            },
            BtfModel {
                raw: true,
                level: 0.0,
                rank: 0,
                chroma_rank: 0,
            },
        )
    };
    if full {
        return raw(
            "budget 0: the full model is the raw BTF at full resolution".into(),
            0.0,
        );
    }
    // Memory of a basis: per block of rank k, k maps at the level's resolution, a mean, and
    // k basis vectors over the pairs.
    let texels = scene.tile_texels.unwrap_or(64.0).powi(2);
    let pairs = scene.btf_pairs.unwrap_or(0.0);
    let floats = |r: u32, l: f64| {
        let chroma = (r / 4).max(1) as f64;
        let at = (texels / 4f64.powf(l)).max(1.0);
        (r as f64 + 2.0 * chroma) * (at + pairs) + 3.0 * at
    };
    let pca = |r: u32, l: f64, reason: String, predicted: Option<f64>, time: Option<f64>| {
        let chroma = (r / 4).max(1);
        let average = l >= coarsest && coarsest > 0.0;
        (
            Decision {
                stage: "btf",
                choice: json!({ "model": "pca", "color": "ycbcr", "rank": r, "chroma_rank": chroma, "level": l }),
                reason: format!(
                    "{reason}{}",
                    if average {
                        "; at the coarsest level the BTF is its average BRDF"
                    } else {
                        ""
                    }
                ),
                predicted_error: predicted,
                predicted_cost: Some(match time {
                    Some(t) => json!({ "floats": floats(r, l), "render_time_vs_full": t }),
                    None => json!({ "floats": floats(r, l) }),
                }),
            },
            BtfModel {
                raw: false,
                level: l,
                rank: r,
                chroma_rank: chroma,
            },
        )
    };
    let tpp = scene.texels_per_pixel;
    let predict = |o: &calibration::BtfOption| tpp.and_then(|t| o.flip.at(t));
    if cheapest {
        let worst = model
            .btf
            .iter()
            .filter(|o| o.rank == 2 && o.level as f64 >= coarsest.min(5.0))
            .find_map(predict)
            .map(|p| p.0);
        return pca(1, coarsest, why_cheapest.to_string(), worst, None);
    }
    let Some(t) = tpp else {
        return raw("texels per pixel unknown: the raw BTF".into(), 0.0);
    };
    let best = model
        .btf
        .iter()
        .filter(|o| o.level as f64 <= coarsest)
        .filter_map(|o| predict(o).map(|p| (o, p)))
        .filter(|(_, (e, inside))| *inside && *e <= share)
        .min_by(|a, b| {
            floats(a.0.rank, a.0.level as f64).total_cmp(&floats(b.0.rank, b.0.level as f64))
        });
    match best {
        Some((o, (e, inside))) => pca(
            o.rank,
            o.level as f64,
            format!(
                "{t:.2} texels per pixel: the least memory whose predicted FLIP ({e:.3}{}) fits this stage's {share:.3}",
                range_note(inside)
            ),
            Some(e),
            o.time.at(t).map(|p| p.0),
        ),
        None => raw(
            format!("{t:.2} texels per pixel: no PCA rank and level is predicted within this stage's {share:.3}; the raw BTF"),
            0.0,
        ),
    }
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

fn decide_sss(cx: &Stage, out: &mut GraphFile, share: f64) -> Decision {
    let Stage {
        model,
        file,
        render,
        scene,
        full,
        cheapest,
        why_cheapest,
        ..
    } = *cx;
    let set = |out: &mut GraphFile, k: &str, v: Value| {
        if let Some(n) = out.node_mut(render) {
            n.params.insert(k.into(), v);
        }
    };
    let mfp = scene.mfp_pixels;
    let candidate = |o: calibration::SssOption| model.sss.iter().find(|c| c.option == o);
    let brdf_error = mfp
        .and_then(|m| candidate(calibration::SssOption::Brdf).and_then(|c| c.flip.at(m)))
        .map(|p| p.0);
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
            predicted_error: Some(0.0),
            predicted_cost: None,
        };
    }
    let brdf = |out: &mut GraphFile, reason: String, predicted: Option<f64>| {
        set(out, "mode", json!("brdf"));
        Decision {
            stage: "sss",
            choice: json!({ "mode": "brdf" }),
            reason,
            predicted_error: predicted,
            predicted_cost: Some(json!({ "samples": 0 })),
        }
    };
    if cheapest {
        return brdf(out, why_cheapest.to_string(), brdf_error);
    }
    if let Some(p) = mfp.filter(|p| *p < 0.5) {
        return brdf(
            out,
            format!(
                "the longest effective mean free path ({:.3} mm) is {p:.2} of a pixel footprint: scattering stays inside a pixel",
                scene.mfp_mm.unwrap_or(f64::NAN)
            ),
            brdf_error,
        );
    }
    // The cheapest calibrated candidate (by render time) predicted within the budget, by the
    // worse of the calibration media.
    let best = mfp.and_then(|m| {
        model
            .sss_predictions(m)
            .into_iter()
            .filter(|(o, e, _)| {
                *e <= share
                    && matches!(
                        o,
                        calibration::SssOption::Brdf | calibration::SssOption::Gather { .. }
                    )
            })
            .min_by(|a, b| a.2.total_cmp(&b.2))
    });
    let default_spacing = scene.mfp_min_mm.map(|m| 0.25 * m);
    match (best, default_spacing, scene.pixel_footprint_mm) {
        (Some((calibration::SssOption::Brdf, e, time)), _, _) => {
            let mut d = brdf(
                out,
                format!(
                    "scattering spans {:.2} px; the BRDF approximation is predicted at FLIP {e:.3}, within {share:.3}",
                    mfp.unwrap_or(f64::NAN),
                ),
                Some(e),
            );
            d.predicted_cost = Some(json!({ "samples": 0, "render_time_vs_full": time }));
            d
        }
        (
            Some((calibration::SssOption::Gather { footprints: k }, e, time)),
            Some(default),
            Some(footprint),
        ) => {
            let spacing = (k * footprint).max(default);
            set(out, "mode", json!("diffusion"));
            set(out, "spacing", json!(spacing));
            // Brute force, as calibrated (the calibration's gathers ran on the GPU path, which
            // sums every sample); an octree would add an error the model does not know.
            set(out, "threshold", json!(0.0));
            Decision {
                stage: "sss",
                choice: json!({ "mode": "diffusion", "spacing_mm": spacing, "threshold": 0.0 }),
                reason: format!(
                    "scattering spans {:.2} px; samples {k} pixel footprints apart ({spacing:.3} mm, never closer than the default {default:.3} mm) are predicted at FLIP {e:.3} (the worse calibration medium), within {share:.3}",
                    mfp.unwrap_or(f64::NAN),
                ),
                predicted_error: Some(e),
                predicted_cost: Some(json!({ "render_time_vs_full": time })),
            }
        }
        _ => {
            // Nothing cheaper is predicted within the budget: the full model's gather (brute
            // force at the profile's own spacing). The profile stays the graph's.
            set(out, "mode", json!("diffusion"));
            set(out, "threshold", json!(0.0));
            if let Some(n) = out.node_mut(render) {
                n.params.remove("spacing");
            }
            Decision {
                stage: "sss",
                choice: json!({ "mode": "diffusion", "threshold": 0.0 }),
                reason: format!(
                    "scattering spans {:.2} px; no cheaper candidate is predicted within {share:.3}: the full model's brute-force gather",
                    mfp.unwrap_or(f64::NAN)
                ),
                predicted_error: None,
                predicted_cost: None,
            }
        }
    }
}

/// The subsurface options of the invisible tier for a gathered render: each with the worse
/// calibration medium's (FLIP, time) at this view where that FLIP is within a tenth of `share`;
/// none for the full model, a BRDF render or a view the calibration does not cover.
fn invisible_sss(
    cx: &Stage,
    out: &GraphFile,
    share: f64,
) -> Vec<(calibration::SssOption, f64, f64)> {
    let brdf = out
        .node(cx.render)
        .is_some_and(|n| n.params.get("mode") == Some(&json!("brdf")));
    match cx.scene.mfp_pixels {
        Some(mfp) if !cx.full && !brdf => cx
            .model
            .sss_predictions(mfp)
            .into_iter()
            .filter(|(_, e, _)| *e <= 0.1 * share)
            .collect(),
        _ => Vec::new(),
    }
}

/// The CPU path's octree: the gather at the largest calibrated threshold the measured model
/// predicts within a tenth of the translucency's share (meant to be invisible, as shadow maps
/// are), else brute force as `decide_sss` set it. The GPU path sums every sample whatever the
/// threshold, so there the choice changes nothing; on the CPU the octree is what makes the
/// gather fast.
fn decide_threshold(cx: &Stage, out: &mut GraphFile, share: f64) -> Option<Decision> {
    let (t, e, time) = invisible_sss(cx, out, share)
        .into_iter()
        .filter_map(|(o, e, time)| match o {
            calibration::SssOption::Octree { threshold } => Some((threshold, e, time)),
            _ => None,
        })
        .max_by(|a, b| a.0.total_cmp(&b.0))?;
    out.node_mut(cx.render)?
        .params
        .insert("threshold".into(), json!(t));
    Some(Decision {
        stage: "octree",
        choice: json!({ "threshold": t }),
        reason: format!(
            "on the CPU path (the GPU sums every sample): an octree at ΔA/d² < {t} is predicted at FLIP {e:.4} (the worse calibration medium), within a tenth of {share:.3}"
        ),
        predicted_error: Some(e),
        predicted_cost: Some(json!({ "cpu_render_time_vs_full": time })),
    })
}

/// The diffusion profile: the classical dipole instead of the graph's PBD where the measured
/// model predicts the change within a tenth of the translucency's share (like a shadow map's,
/// meant to be invisible), for a gathered render (a BRDF uses only the profile's totals, which
/// the dipole gets 1–17% wrong where PBD's are 4–10% high: no calibration says which a view
/// shows). The render itself costs the same; the saving is the profile's computation. The
/// graph's profile node stays as it is (others may read it): the render reads a copy.
fn decide_profile(cx: &Stage, out: &mut GraphFile, share: f64) -> Option<Decision> {
    let Stage {
        model,
        file,
        render,
        scene,
        ..
    } = *cx;
    let (_, e, _) = invisible_sss(cx, out, share)
        .into_iter()
        .find(|(o, ..)| *o == calibration::SssOption::Dipole)?;
    let mfp = scene.mfp_pixels?;
    let from = file.node(render)?.inputs.get("profile")?;
    let (id, port) = from.split_once('.')?;
    let profile = file.node(id).filter(|n| n.kind == "sss.profile")?;
    if profile.params.get("model").and_then(Value::as_str) != Some("pbd") {
        return None;
    }
    let mut params = profile.params.clone();
    params.insert("model".into(), json!("dipole"));
    let copy = format!("{PREFIX}profile");
    upsert(out, &copy, "sss.profile", params, profile.inputs.clone());
    out.node_mut(render)?
        .inputs
        .insert("profile".into(), format!("{copy}.{port}"));
    Some(Decision {
        stage: "profile",
        choice: json!({ "model": "dipole" }),
        reason: format!(
            "scattering spans {mfp:.2} px: the classical dipole's profile instead of PBD's is predicted at FLIP {e:.4} (the worse calibration medium), within a tenth of {share:.3}"
        ),
        predicted_error: Some(e),
        predicted_cost: model
            .dipole_profile_time
            .map(|t| json!({ "profile_time_vs_full": t })),
    })
}

/// Shadow maps: the renderer's resolution lowered to what the view shows, at the sparsest
/// calibrated density the measured model predicts within a tenth of the budget (the change is
/// meant to be invisible).
fn decide_shadows(cx: &Stage, out: &mut GraphFile, b: f64) -> Option<Decision> {
    let Stage {
        model,
        file,
        render,
        kind,
        scene,
        full,
        cheapest,
        ..
    } = *cx;
    let node = file.node(render)?;
    let defaults = match kind {
        RenderKind::Mesh => (false, 1024),
        RenderKind::Sss | RenderKind::Qh => (true, 1024),
    };
    let on = node
        .params
        .get("shadows")
        .and_then(Value::as_bool)
        .unwrap_or(defaults.0);
    if !on || full {
        return None;
    }
    let current = node
        .params
        .get("shadow_resolution")
        .and_then(Value::as_u64)
        .map_or(defaults.1, |v| v as u32);
    let px = scene.object_pixels?;
    let curves = match kind {
        RenderKind::Sss => &model.shadows_sss,
        RenderKind::Mesh | RenderKind::Qh => &model.shadows_mesh,
    };
    // The sparsest calibrated density predicted invisible (within a tenth of the budget); the
    // sparsest of all when the budget asks for the cheapest.
    let (size, density, e, inside, time) = curves.iter().find_map(|c| {
        let size = shadow_resolution(px, c.texels_per_pixel, current);
        let (e, inside) = c.flip.at(px)?;
        let ok = size < current && (cheapest || (inside && e <= 0.1 * b));
        ok.then(|| (size, c.texels_per_pixel, e, inside, c.time.at(px)))
    })?;
    if let Some(n) = out.node_mut(render) {
        n.params.insert("shadow_resolution".into(), json!(size));
    }
    Some(Decision {
        stage: "shadows",
        choice: json!({ "shadow_resolution": size }),
        reason: format!(
            "the object spans {px:.0} px: a {size}² shadow map (not {current}²), {density} texels per pixel, is predicted at FLIP {e:.4}{}",
            range_note(inside)
        ),
        predicted_error: Some(e),
        predicted_cost: time.map(|(t, _)| json!({ "render_time_vs_full": t })),
    })
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
            btf_pairs: Some(1600.0),
            btf_floats: Some(64.0 * 64.0 * 1600.0 * 3.0),
            shell_pixels: Some(shell_px),
            silhouette_fraction: Some(0.1),
            ..Default::default()
        }
    }

    #[test]
    fn a_probe_without_visible_fraction_is_an_error_not_an_empty_view() {
        // Read as 0, a missing fraction planned the cheapest model for any view (issue 39).
        let mut m = BTreeMap::new();
        m.insert("texels_per_pixel".to_string(), 2.0);
        assert_eq!(
            Scene::from_metrics(&m),
            Err(PlanError::MissingMetric("visible_fraction"))
        );
        m.insert("visible_fraction".to_string(), f64::NAN);
        assert!(Scene::from_metrics(&m).is_err());
        m.insert("visible_fraction".to_string(), 0.25);
        let s = Scene::from_metrics(&m).unwrap();
        assert_eq!((s.visible_fraction, s.texels_per_pixel), (0.25, Some(2.0)));
        // The other metrics stay unknown, not 0.
        assert_eq!(s.shell_pixels, None);
    }

    fn run(s: &Scene, b: f64) -> Plan {
        let f = graph();
        let chain = btf_chain(&f, "r", "btf").unwrap();
        assert_eq!(chain.raw, "capture.btf");
        plan(
            &f,
            "r",
            RenderKind::Mesh,
            s,
            Some(&chain),
            Budget::flip(b),
            Split::Equal,
        )
        .unwrap()
    }

    fn decision<'a>(p: &'a Plan, stage: &str) -> &'a Decision {
        p.decisions.iter().find(|d| d.stage == stage).unwrap()
    }

    #[test]
    fn budget_zero_is_the_full_model() {
        let p = run(&scene(10.0, 0.1), 0.0);
        let r = p.file.node("r").unwrap();
        assert_eq!(r.inputs["btf"], "capture.btf");
        assert_eq!(r.inputs["mdf"], "mdf.mdf");
        // The user's PCA fed only the render: disconnected, it is pruned.
        assert!(p.file.node("pca").is_none());
        assert!(p.decisions.iter().all(|d| d.predicted_error == Some(0.0)));
    }

    #[test]
    fn every_choice_is_predicted_within_its_share_or_is_the_full_models() {
        // Over views near to far and budgets small to large: a stage either keeps the full
        // model's choice or takes one whose predicted error fits its half of the budget.
        for tpp in [0.2, 1.0, 3.0, 10.0] {
            for shell in [0.3, 1.0, 4.0, 20.0] {
                for b in [0.01, 0.05, 0.2, 0.6] {
                    let p = run(&scene(tpp, shell), b);
                    for d in &p.decisions {
                        let full = d.choice.get("model") == Some(&json!("raw"))
                            || d.choice.get("use_mdf") == Some(&json!(true));
                        let e = d.predicted_error.unwrap_or(f64::INFINITY);
                        assert!(
                            full || e <= b / 2.0 || (d.stage == "mdf" && shell < 0.5),
                            "tpp {tpp}, shell {shell} px, budget {b}: {d:?}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn the_joint_split_keeps_the_total_within_budget() {
        // Whatever share the joint split gives the BTF, the stages' predictions add up to at
        // most the budget.
        let f = graph();
        let chain = btf_chain(&f, "r", "btf").unwrap();
        for tpp in [0.2, 1.0, 3.0, 10.0] {
            for shell in [0.6, 1.0, 4.0] {
                for b in [0.01, 0.05, 0.2, 0.6] {
                    let p = plan(
                        &f,
                        "r",
                        RenderKind::Mesh,
                        &scene(tpp, shell),
                        Some(&chain),
                        Budget::flip(b),
                        Split::Joint,
                    )
                    .unwrap();
                    let total: f64 = p
                        .decisions
                        .iter()
                        .filter(|d| d.stage != "shadows")
                        .map(|d| d.predicted_error.unwrap_or(0.0))
                        .sum();
                    assert!(
                        total <= b + 1e-12,
                        "tpp {tpp}, shell {shell}, budget {b}: {:?}",
                        p.decisions
                    );
                    let given: f64 = p.shares.iter().map(|s| s.1).sum();
                    assert!((given - b).abs() < 1e-12, "{:?}", p.shares);
                }
            }
        }
    }

    #[test]
    fn a_larger_budget_never_costs_more_memory() {
        for tpp in [0.3, 2.0, 8.0] {
            let mut last = f64::INFINITY;
            for b in [0.0, 0.02, 0.05, 0.1, 0.2, 0.4, 0.8, 2.0] {
                let p = run(&scene(tpp, 1.0), b);
                let floats = decision(&p, "btf").predicted_cost.as_ref().unwrap()["floats"]
                    .as_f64()
                    .unwrap();
                assert!(floats <= last, "tpp {tpp}, budget {b}: {floats} > {last}");
                last = floats;
            }
        }
    }

    #[test]
    fn shadow_maps_match_the_object_on_screen() {
        // Worked by hand: 23 px at 4 texels → 92 → 128, at 2 → 46 → 64; 10 px at 4 → 40 → 64,
        // at 1 → 32 (the floor); 300 px → 1200 → the graph's 512; never above the graph's own.
        assert_eq!(shadow_resolution(23.0, 4.0, 512), 128);
        assert_eq!(shadow_resolution(23.0, 2.0, 512), 64);
        assert_eq!(shadow_resolution(10.0, 4.0, 512), 64);
        assert_eq!(shadow_resolution(10.0, 1.0, 512), 32);
        assert_eq!(shadow_resolution(300.0, 4.0, 512), 512);
        assert_eq!(shadow_resolution(10.0, 4.0, 32), 32);
    }

    #[test]
    fn shadow_maps_are_as_sparse_as_the_budget_allows_and_no_sparser() {
        let mut f = graph();
        let r = f.node_mut("r").unwrap();
        r.params.insert("shadows".into(), json!(true));
        r.params.insert("shadow_resolution".into(), json!(1024));
        let model =
            calibration::Calibration::builtin(mesoflow_nodes::image::flip::DEFAULT_PPD).unwrap();
        for px in [20.0, 60.0, 150.0] {
            let mut s = scene(1.0, 1.0);
            s.object_pixels = Some(px);
            let size = |b: f64| {
                let p = plan(
                    &f,
                    "r",
                    RenderKind::Mesh,
                    &s,
                    None,
                    Budget::flip(b),
                    Split::Equal,
                )
                .unwrap();
                let d = p.decisions.iter().find(|d| d.stage == "shadows");
                if let Some(d) = d {
                    // Within a tenth of the budget, as predicted by the calibrated density it names.
                    assert!(
                        b >= 1.0 || d.predicted_error.unwrap() <= 0.1 * b,
                        "{px} px, {b}: {d:?}"
                    );
                }
                p.file.node("r").unwrap().params["shadow_resolution"]
                    .as_u64()
                    .unwrap()
            };
            let mut last = 0;
            for b in [0.0, 0.005, 0.02, 0.1, 0.5] {
                let got = size(b);
                assert!(
                    last == 0 || got <= last,
                    "{px} px: a larger budget, a finer map"
                );
                last = got;
            }
            assert_eq!(size(0.0), 1024, "budget 0 keeps the graph's map");
            // The cheapest: one texel per pixel the object spans.
            let sparsest = model.shadows_mesh[0].texels_per_pixel;
            assert_eq!(size(1e9) as u32, shadow_resolution(px, sparsest, 1024));
        }
    }

    #[test]
    fn sub_pixel_shells_drop_the_mdf_and_its_tabulation() {
        let p = run(&scene(10.0, 0.2), 0.05);
        let r = p.file.node("r").unwrap();
        assert!(!r.inputs.contains_key("mdf"));
        assert!(
            p.file.node("mdf").is_none(),
            "the MDF tabulation is no longer computed"
        );
        assert!(p.file.node("png").is_some(), "writers stay");
    }

    #[test]
    fn an_enormous_budget_picks_the_cheapest_never_nothing() {
        let p = run(&scene(0.3, 3.0), 1e9);
        // 64 texels: level 6 is one texel, the average BRDF; rank 1.
        assert_eq!(p.file.node("plan_lod").unwrap().params["level"], json!(6.0));
        assert_eq!(p.file.node("plan_pca").unwrap().params["rank"], json!(1));
        assert_eq!(p.file.node("r").unwrap().inputs["btf"], "plan_lod.basis");
        assert!(!p.file.node("r").unwrap().inputs.contains_key("mdf"));
    }

    #[test]
    fn a_camera_inside_and_a_bad_budget_are_errors() {
        let mut s = scene(1.0, 1.0);
        s.camera_inside = true;
        let f = graph();
        assert!(matches!(
            plan(
                &f,
                "r",
                RenderKind::Mesh,
                &s,
                None,
                Budget::flip(0.1),
                Split::Joint
            ),
            Err(PlanError::CameraInside)
        ));
        for b in [-1.0, f64::NAN] {
            assert!(matches!(
                plan(
                    &f,
                    "r",
                    RenderKind::Mesh,
                    &scene(1.0, 1.0),
                    None,
                    Budget::flip(b),
                    Split::Joint
                ),
                Err(PlanError::Budget(_))
            ));
        }
        for ppd in [0.0, f64::NAN] {
            let budget = Budget { flip: 0.1, ppd };
            assert!(matches!(
                plan(
                    &f,
                    "r",
                    RenderKind::Mesh,
                    &scene(1.0, 1.0),
                    None,
                    budget,
                    Split::Joint
                ),
                Err(PlanError::Ppd(_))
            ));
        }
    }

    #[test]
    fn a_viewer_reads_the_calibration_at_or_below_its_pixels_per_degree() {
        use calibration::Calibration;
        use mesoflow_nodes::image::flip::DEFAULT_PPD;
        let at = |ppd: f64| Calibration::builtin(ppd).unwrap();
        // Calibrated at 30, 67.02 (FLIP's default) and 120 pixels per degree.
        assert_eq!((at(30.0).ppd, at(30.0).ppd_inside), (30.0, true));
        assert_eq!((at(20.0).ppd, at(20.0).ppd_inside), (30.0, false));
        assert_eq!(at(45.0).ppd, 30.0);
        assert_eq!(at(67.0).ppd, DEFAULT_PPD);
        assert_eq!(at(100.0).ppd, DEFAULT_PPD);
        assert_eq!((at(200.0).ppd, at(200.0).ppd_inside), (120.0, true));
        // The columns differ: a viewer's ppd changes what is predicted.
        assert_ne!(at(120.0).btf, at(30.0).btf);
    }

    #[test]
    fn fewer_pixels_per_degree_never_plan_a_cheaper_model() {
        // A viewer at 30 ppd sees each pixel's error larger than at 120: over views near to
        // far and budgets, the plan for 30 keeps at least as many BTF floats.
        let f = graph();
        let chain = btf_chain(&f, "r", "btf").unwrap();
        for tpp in [0.5, 2.0, 8.0, 20.0] {
            for b in [0.05, 0.1, 0.25] {
                let floats = |ppd: f64| {
                    let p = plan(
                        &f,
                        "r",
                        RenderKind::Mesh,
                        &scene(tpp, 1.0),
                        Some(&chain),
                        Budget { flip: b, ppd },
                        Split::Equal,
                    )
                    .unwrap();
                    floats_of(decision(&p, "btf"))
                };
                assert!(floats(30.0) >= floats(120.0), "tpp {tpp}, budget {b}");
            }
        }
    }

    #[test]
    fn the_dipole_replaces_pbd_only_where_predicted_invisible_and_never_in_place() {
        let f = GraphFile::parse(
            r#"{"mesoflow": 1, "nodes": {
              "m": {"kind": "sss.material", "params": {"preset": "skin1"}},
              "pr": {"kind": "sss.profile", "inputs": {"material": "m.material"}, "params": {"model": "pbd"}},
              "torus": {"kind": "mesh.primitive"},
              "full": {"kind": "sss.render", "inputs": {"mesh": "torus.mesh", "material": "m.material", "profile": "pr.profile"}},
              "r": {"kind": "sss.render", "inputs": {"mesh": "torus.mesh", "material": "m.material", "profile": "pr.profile"}}
            }}"#,
        )
        .unwrap();
        let measured =
            calibration::Calibration::builtin(mesoflow_nodes::image::flip::DEFAULT_PPD).unwrap();
        // A model in which the dipole is 100× closer to PBD than measured, so that both
        // outcomes occur; and the measured one.
        let mut closer = measured.clone();
        for c in closer
            .sss
            .iter_mut()
            .filter(|c| c.option == calibration::SssOption::Dipole)
        {
            c.flip = c.flip.scaled(0.01);
        }
        let mut chosen = [0, 0];
        for (m, model) in [&measured, &closer].into_iter().enumerate() {
            for mfp in [2.0, 5.0, 12.0, 30.0, 80.0] {
                let s = Scene {
                    visible_fraction: 0.3,
                    mfp_pixels: Some(mfp),
                    ..Default::default()
                };
                for b in [0.0, 0.02, 0.1, 0.5] {
                    for mode in ["diffusion", "brdf"] {
                        let cx = Stage {
                            model,
                            file: &f,
                            render: "r",
                            kind: RenderKind::Sss,
                            scene: &s,
                            full: b == 0.0,
                            cheapest: false,
                            why_cheapest: "",
                        };
                        let mut out = f.clone();
                        out.node_mut("r")
                            .unwrap()
                            .params
                            .insert("mode".into(), json!(mode));
                        let d = decide_profile(&cx, &mut out, b);
                        // The graph's profile node is never changed: the full render reads it.
                        assert_eq!(out.node("pr").unwrap().params["model"], json!("pbd"));
                        let r = out.node("r").unwrap();
                        let Some(d) = d else {
                            assert_eq!(r.inputs["profile"], "pr.profile");
                            continue;
                        };
                        chosen[m] += 1;
                        assert!(b > 0.0 && mode == "diffusion", "{b} {mode}");
                        assert_eq!(r.inputs["profile"], "plan_profile.profile");
                        assert_eq!(
                            out.node("plan_profile").unwrap().params["model"],
                            json!("dipole")
                        );
                        // Within a tenth of the translucency's share (all of b), as the model
                        // predicts for the worse calibration medium whose range holds the view.
                        let e = d.predicted_error.unwrap();
                        let worst = model
                            .sss
                            .iter()
                            .filter(|c| c.option == calibration::SssOption::Dipole)
                            .filter_map(|c| c.flip.at(mfp).filter(|x| x.1).map(|x| x.0))
                            .fold(0.0, f64::max);
                        assert!(e <= 0.1 * b && e == worst, "mfp {mfp}, budget {b}: {e}");
                    }
                }
            }
        }
        // Measured, the dipole is never invisible (FLIP 0.04–0.2 against PBD, ketchup the
        // worse); 100× closer, it is at the larger budgets.
        assert_eq!(chosen[0], 0);
        assert!(chosen[1] > 0);
    }

    #[test]
    fn the_cpu_octree_coarsens_with_the_budget_within_a_tenth_of_it() {
        let f = GraphFile::parse(
            r#"{"mesoflow": 1, "nodes": {
              "m": {"kind": "sss.material", "params": {"preset": "skin1"}},
              "pr": {"kind": "sss.profile", "inputs": {"material": "m.material"}, "params": {"model": "pbd"}},
              "torus": {"kind": "mesh.primitive"},
              "r": {"kind": "sss.render", "inputs": {"mesh": "torus.mesh", "material": "m.material", "profile": "pr.profile"}, "params": {"threshold": 0.05}}
            }}"#,
        )
        .unwrap();
        let mut chosen = 0;
        for mfp in [2.0, 5.0, 12.0, 30.0, 80.0] {
            let s = Scene {
                visible_fraction: 0.3,
                pixel_footprint_mm: Some(8.0 / mfp),
                mfp_mm: Some(8.0),
                mfp_min_mm: Some(2.0),
                mfp_pixels: Some(mfp),
                ..Default::default()
            };
            let mut last = 0.0;
            for b in [0.0, 0.01, 0.05, 0.2, 0.6] {
                let p = plan(
                    &f,
                    "r",
                    RenderKind::Sss,
                    &s,
                    None,
                    Budget::flip(b),
                    Split::Joint,
                )
                .unwrap();
                let r = p.file.node("r").unwrap();
                let t = r.params["threshold"].as_f64().unwrap();
                match p.decisions.iter().find(|d| d.stage == "octree") {
                    Some(d) => {
                        chosen += 1;
                        assert!(b > 0.0 && r.params["mode"] == json!("diffusion"));
                        assert_eq!(d.choice["threshold"].as_f64(), Some(t));
                        assert!(
                            d.predicted_error.unwrap() <= 0.1 * b,
                            "{mfp} px, {b}: {d:?}"
                        );
                    }
                    // Without one the gather is brute force (the graph's 0.05 is not kept),
                    // or the render is a BRDF.
                    None => assert!(t == 0.0 || r.params["mode"] == json!("brdf"), "{t}"),
                }
                if r.params["mode"] == json!("diffusion") {
                    assert!(t >= last, "{mfp} px: a larger budget, a finer octree");
                    last = t;
                }
            }
        }
        assert!(chosen > 0);
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
        let p = plan(
            &f,
            "r",
            RenderKind::Sss,
            &s,
            None,
            Budget::flip(0.05),
            Split::Joint,
        )
        .unwrap();
        assert_eq!(p.file.node("r").unwrap().params["mode"], json!("brdf"));
        // Nearer, scattering spans many pixels: gathered, and what is chosen is predicted
        // within the budget or is the graph's own gather.
        let near = Scene {
            pixel_footprint_mm: Some(0.01),
            mfp_pixels: Some(50.0),
            ..s.clone()
        };
        let p = plan(
            &f,
            "r",
            RenderKind::Sss,
            &near,
            None,
            Budget::flip(0.05),
            Split::Joint,
        )
        .unwrap();
        let d = &p.decisions[0];
        assert_eq!(
            p.file.node("r").unwrap().params["mode"],
            json!("diffusion"),
            "{d:?}"
        );
        assert!(d.predicted_error.is_none_or(|e| e <= 0.05), "{d:?}");
        // Budget 0: brute force, PBD.
        let p = plan(
            &f,
            "r",
            RenderKind::Sss,
            &near,
            None,
            Budget::flip(0.0),
            Split::Joint,
        )
        .unwrap();
        assert_eq!(p.file.node("r").unwrap().params["threshold"], json!(0.0));
        assert_eq!(p.file.node("pr").unwrap().params["model"], json!("pbd"));
    }

    #[test]
    fn the_mdf_table_coarsens_to_a_texel_per_pixel_within_its_share() {
        let f = graph();
        let chain = btf_chain(&f, "r", "btf").unwrap();
        let mut chosen = 0;
        for shell in [1.0, 3.0, 8.0] {
            let mut last_factor = 1;
            for tpp in [0.5, 1.0, 1.9, 2.5, 4.5, 9.0, 30.0] {
                for b in [0.0, 0.02, 0.1, 0.3] {
                    let mut s = scene(tpp, shell);
                    // The height field has the BTF's 64 texels: the same texels per pixel.
                    s.textures.insert(
                        "hf.height".into(),
                        TextureView {
                            texels_per_pixel: tpp,
                            width: 64,
                            height: 64,
                        },
                    );
                    let p = plan(
                        &f,
                        "r",
                        RenderKind::Mesh,
                        &s,
                        Some(&chain),
                        Budget::flip(b),
                        Split::Equal,
                    )
                    .unwrap();
                    // The graph's own table is never changed (a full render may share it).
                    assert!(p
                        .file
                        .node("mdf")
                        .is_none_or(|n| n.params.get("resolution").is_none()));
                    let Some(d) = p.decisions.iter().find(|d| d.stage == "mdf_resolution") else {
                        // Only where the MDF is left out, or for the full model.
                        assert!(b == 0.0 || !p.file.node("r").unwrap().inputs.contains_key("mdf"));
                        continue;
                    };
                    let r = p.file.node("r").unwrap();
                    let Some(copy) = p.file.node("plan_mdf") else {
                        assert_eq!(r.inputs["mdf"], "mdf.mdf");
                        assert_eq!(d.predicted_error, Some(0.0));
                        continue;
                    };
                    chosen += 1;
                    assert_eq!(r.inputs["mdf"], "plan_mdf.mdf");
                    assert_eq!(copy.inputs["height"], "hf.height");
                    let res = copy.params["resolution"].as_u64().unwrap();
                    let factor = 64 / res;
                    // A texel per pixel kept, and invisible by the measured model.
                    assert!(factor as f64 <= tpp, "tpp {tpp}: {d:?}");
                    let share = p.shares.iter().find(|s| s.0 == "mdf").unwrap().1;
                    assert!(d.predicted_error.unwrap() <= share + 1e-15, "{d:?}");
                    if b == 0.3 {
                        assert!(factor >= last_factor, "coarser as the view recedes: {d:?}");
                        last_factor = factor;
                    }
                }
            }
        }
        assert!(chosen > 0);
    }

    #[test]
    fn synthesis_stops_early_only_where_the_view_cannot_show_its_texels() {
        let f = GraphFile::parse(
            r#"{"mesoflow": 1, "nodes": {
              "hf": {"kind": "heightfield.procedural"},
              "n": {"kind": "heightfield.normals", "inputs": {"height": "hf.height"}},
              "capture": {"kind": "btf.capture", "inputs": {"height": "hf.height"}},
              "syn": {"kind": "synthesis.texture", "inputs": {"exemplar": "n.preview"},
                      "params": {"width": 256, "height": 256, "levels": 3, "patch_sizes": [16, 8]}},
              "m": {"kind": "sss.material", "params": {"preset": "marble"}},
              "pr": {"kind": "sss.profile", "inputs": {"material": "m.material"}},
              "torus": {"kind": "mesh.primitive"},
              "r": {"kind": "qh.render", "inputs": {"mesh": "torus.mesh", "lrf": "capture.btf", "material": "m.material",
                    "profile": "pr.profile", "entrance": "syn.image"}},
              "png": {"kind": "image.write", "inputs": {"image": "syn.image"}, "params": {"path": "syn.png"}}
            }}"#,
        )
        .unwrap();
        assert_eq!(texture_sources(&f, "r"), ["n.preview"]);
        let chain = btf_chain(&f, "r", "lrf").unwrap();
        let mut stops = Vec::new();
        for tpp in [0.5, 1.5, 2.5, 5.0, 12.0, 40.0] {
            for b in [0.0, 0.02, 0.1, 0.4, 1e9] {
                let mut s = scene(1.0, 1.0);
                s.mfp_pixels = Some(10.0);
                s.textures.insert(
                    "n.preview".into(),
                    TextureView {
                        // The 64² exemplar's; the 256² output has 4× as many per pixel.
                        texels_per_pixel: tpp / 4.0,
                        width: 64,
                        height: 64,
                    },
                );
                let p = plan(
                    &f,
                    "r",
                    RenderKind::Qh,
                    &s,
                    Some(&chain),
                    Budget::flip(b),
                    Split::Equal,
                )
                .unwrap();
                // The graph's own node is kept for its other reader, unchanged.
                assert!(p
                    .file
                    .node("syn")
                    .unwrap()
                    .params
                    .get("stop_level")
                    .is_none());
                let d = p.decisions.iter().find(|d| d.stage == "synthesis");
                if b == 0.0 {
                    assert!(d.is_none());
                    continue;
                }
                let d = d.unwrap();
                let r = p.file.node("r").unwrap();
                let k = match p.file.node("plan_syn") {
                    None => {
                        assert_eq!(r.inputs["entrance"], "syn.image");
                        0
                    }
                    Some(c) => {
                        assert_eq!(r.inputs["entrance"], "plan_syn.image");
                        c.params["stop_level"].as_u64().unwrap()
                    }
                };
                if b >= 1.0 {
                    // The cheapest: level 2's exemplar is 16², an 8-pixel patch fits (half of
                    // it); there is no level 3.
                    assert_eq!(k, 2, "{d:?}");
                    continue;
                }
                if k > 0 {
                    assert!((1u64 << k) as f64 <= tpp, "tpp {tpp}: {d:?}");
                    assert!(d.predicted_error.unwrap() <= 0.1 * b, "{d:?}");
                }
                stops.push((tpp, b, k));
            }
        }
        // Under two texels per pixel nothing stops early; somewhere farther something does.
        assert!(stops.iter().filter(|s| s.0 < 2.0).all(|s| s.2 == 0));
        assert!(stops.iter().any(|s| s.2 > 0), "{stops:?}");
    }
}
