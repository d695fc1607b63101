//! How close to the truth (`graphs/truth.json`): mesoflow's render (`render.mesh`: BTF, MDF,
//! shadow maps) against the true mesostructure rendered exactly (`render.reference` on
//! `mesh.displace`'s mesh), for the scenes — a torus under 6-texel bumps with and
//! without the MDF, the same under 2-texel bumps, an open 2 × 2 plane seen obliquely with and
//! without the MDF — and then the render's error against its frame time as each model choice
//! varies (direction sampling and interpolation, PCA rank, LOD level, shadow map resolution,
//! MDF on/off), beside
//! what a user without a BTF would render: the plain mesh with the tile's normal map.
//!
//! Per case: relative RMSE and bias over the pixels either image shows the object in, the
//! silhouette IoU, mean FLIP over the object, and the bias of the pixels lit at 75–82° and 82–90°
//! from the macro normal (from a render of the undisplaced mesh with albedo π under a unit light,
//! whose value is the cosine where the light reaches). Every node runs on the CPU (`--device
//! cpu`): the raw 81 × 81 BTF is larger than a GPU storage binding, and frame times compare only
//! on one device. Writes `truth.csv`, `truth_tradeoff.csv`, the chart `truth_tradeoff` and each
//! case's truth | ours | difference picture to the output folder.
//!
//! `cargo bench --bench truth -- [--out DIR] [--width W]`

use mesoflow::chart;
use mesoflow_testkit::{args, cli, truth_scenes};

use cli::{mesoflow, node};
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use truth_scenes::plane_sets;

struct Case {
    name: String,
    sets: Vec<String>,
    /// Nodes added to the graph, and the output `ours` then reads its BTF from.
    nodes: Vec<(String, Value)>,
    btf: Option<String>,
}

/// The render nodes of the bench's graph: the truth, ours and the macro cosine.
const RENDERS: [&str; 3] = ["truth", "ours", "macro"];

fn size_sets(width: u32) -> Vec<String> {
    let h = width * 3 / 4;
    ["truth", "ours", "macro"]
        .iter()
        .map(|id| format!("{id}.camera.resolution=[{width},{h}]"))
        .collect()
}

/// The graph with what the bench reads added: the macro cosine render and the images as .npy;
/// and the case's own nodes.
fn graph(root: &Path, case: &Case) -> Value {
    let mut g: Value =
        serde_json::from_str(&std::fs::read_to_string(root.join("graphs/truth.json")).unwrap())
            .unwrap();
    truth_scenes::add_measures(&mut g);
    let nodes = g["nodes"].as_object_mut().unwrap();
    // What a user without a BTF would render: the plain mesh with the tile's normal map.
    nodes.insert(
        "nm_normals".into(),
        json!({ "kind": "heightfield.normals", "inputs": { "height": "surface.height" } }),
    );
    let mut nm = nodes["truth"].clone();
    nm["inputs"] = json!({ "mesh": "torus.mesh", "normals": "nm_normals.normals" });
    nm["params"]["samples"] = json!(1);
    nm["params"]["tiling"] = nodes["ours"]["params"]["tiling"].clone();
    nodes.insert("nm".into(), nm);
    nodes.insert(
        "nm_compare".into(),
        json!({ "kind": "image.compare", "inputs": { "reference": "truth.image", "image": "nm.image",
            "reference_mask": "truth.coverage", "mask": "nm.coverage" } }),
    );
    nodes.insert(
        "nm_flip".into(),
        json!({ "kind": "image.flip", "inputs": { "reference": "truth.image", "test": "nm.image" }, "params": { "object_only": true } }),
    );
    for (id, v) in &case.nodes {
        nodes.insert(id.clone(), v.clone());
    }
    if let Some(b) = &case.btf {
        nodes["ours"]["inputs"]["btf"] = json!(b);
    }
    g
}

fn read_npy(path: &Path) -> Vec<f32> {
    let bytes = std::fs::read(path).unwrap();
    npyz::NpyFile::new(&bytes[..]).unwrap().into_vec().unwrap()
}

struct Measured {
    relative_rmse: f64,
    bias: f64,
    iou: f64,
    flip: f64,
    /// Bias of the pixels lit at 75–82° and 82–90° from the macro normal, and their counts.
    grazing: [(f64, usize); 2],
    frame_ms: f64,
    /// The plain mesh with a normal map: relative RMSE, IoU, FLIP, milliseconds (1 sample a
    /// pixel, CPU ray tracing).
    normal_mapped: (f64, f64, f64, f64),
}

fn run_case(root: &Path, out: &Path, cache: &Path, width: u32, case: &Case) -> Measured {
    let dir = out.join(&case.name);
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("graph.json");
    std::fs::write(
        &file,
        serde_json::to_string_pretty(&graph(root, case)).unwrap(),
    )
    .unwrap();
    let run_out = dir.join("out");
    let mut a: Vec<String> = vec![
        "run".into(),
        file.display().to_string(),
        "--quiet".into(),
        "--device".into(),
        "cpu".into(),
        // Asked for, the measures are reported even when served from the cache.
        "--output".into(),
        "compare.relative_rmse".into(),
        "--output".into(),
        "compare.bias".into(),
        "--output".into(),
        "compare.iou".into(),
        "--output".into(),
        "flip.mean".into(),
        "--output".into(),
        "nm_compare.relative_rmse".into(),
        "--output".into(),
        "nm_flip.mean".into(),
        "--output".into(),
        "side_by_side_png.file".into(),
        "--output".into(),
        "truth_npy.files".into(),
        "--output".into(),
        "ours_npy.files".into(),
        "--output".into(),
        "truth_mask_npy.files".into(),
        "--output".into(),
        "ours_mask_npy.files".into(),
        "--output".into(),
        "macro_npy.files".into(),
        "--out-dir".into(),
        run_out.display().to_string(),
        "--cache-dir".into(),
        cache.display().to_string(),
    ];
    for s in size_sets(width).iter().chain(&case.sets) {
        a.push("--set".into());
        a.push(s.clone());
    }
    mesoflow(&a.iter().map(String::as_str).collect::<Vec<_>>());
    let rep: Value =
        serde_json::from_str(&std::fs::read_to_string(run_out.join("report.json")).unwrap())
            .unwrap();
    let m = |id: &str, k: &str| node(&rep, id)["metrics"][k].as_f64().unwrap_or(f64::NAN);
    let truth = read_npy(&run_out.join("truth_npy.npy"));
    let ours = read_npy(&run_out.join("ours_npy.npy"));
    let (tm, om) = (
        read_npy(&run_out.join("truth_mask_npy.npy")),
        read_npy(&run_out.join("ours_mask_npy.npy")),
    );
    let cosine = read_npy(&run_out.join("macro_npy.npy"));
    let grazing = truth_scenes::grazing_bias(&truth, &ours, &tm, &om, &cosine);
    let (beyond, beyond_truth, beyond_px) =
        truth_scenes::past_horizon(&truth, &ours, &tm, &om, &cosine);
    println!(
        "{}: past the macro horizon ours {beyond:.4}, truth {beyond_truth:.4} ({beyond_px} px)",
        case.name
    );
    std::fs::copy(
        run_out.join("truth_ours_difference.png"),
        out.join(format!("{}.png", case.name)),
    )
    .unwrap();
    Measured {
        relative_rmse: m("compare", "relative_rmse"),
        bias: m("compare", "bias"),
        iou: m("compare", "iou"),
        flip: m("flip", "mean"),
        grazing,
        frame_ms: node(&rep, "ours")["timings"]["frame_ms"]
            .as_f64()
            .unwrap_or(f64::NAN),
        normal_mapped: (
            m("nm_compare", "relative_rmse"),
            m("nm_compare", "iou"),
            m("nm_flip", "mean"),
            node(&rep, "nm")["timings"]["seconds"]
                .as_f64()
                .map_or(f64::NAN, |s| s * 1e3),
        ),
    }
}

fn main() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let out = PathBuf::from(args::arg("--out", "out/truth".to_string()));
    let width: u32 = args::arg("--width", 320);
    let cache = out.join("cache");
    std::fs::create_dir_all(&out).unwrap();
    let case = |name: &str, sets: Vec<String>| Case {
        name: name.into(),
        sets,
        nodes: Vec::new(),
        btf: None,
    };
    let two_texel = vec![
        "surface.depth=2".to_string(),
        "true_surface.shell=0.0148".into(),
        "ours.shell=0.0148".into(),
    ];
    let scenes = vec![
        case("torus_mdf", vec![]),
        case("torus_no_mdf", vec!["ours.use_mdf=false".into()]),
        case("torus_2_texel_mdf", two_texel),
        case("plane_mdf", plane_sets(width, true, &RENDERS)),
        case("plane_no_mdf", plane_sets(width, false, &RENDERS)),
    ];
    let mut csv = String::from("case,relative_rmse,bias,silhouette_iou,flip,bias_lit_75_82,pixels_75_82,bias_lit_82_90,pixels_82_90,frame_ms\n");
    println!(
        "{:<20} {:>9} {:>7} {:>7} {:>6} {:>14} {:>14} {:>9}",
        "case", "rel RMSE", "bias", "IoU", "FLIP", "bias 75–82°", "bias 82–90°", "frame ms"
    );
    let row = |csv: &mut String, name: &str, r: &Measured| {
        let _ = writeln!(
            csv,
            "{name},{:.4},{:.4},{:.4},{:.4},{:.4},{},{:.4},{},{:.1}",
            r.relative_rmse,
            r.bias,
            r.iou,
            r.flip,
            r.grazing[0].0,
            r.grazing[0].1,
            r.grazing[1].0,
            r.grazing[1].1,
            r.frame_ms
        );
        println!(
            "{name:<20} {:>9.3} {:>+7.3} {:>7.3} {:>6.3} {:>+8.3} ({:>4}) {:>+8.3} ({:>4}) {:>9.1}",
            r.relative_rmse,
            r.bias,
            r.iou,
            r.flip,
            r.grazing[0].0,
            r.grazing[0].1,
            r.grazing[1].0,
            r.grazing[1].1,
            r.frame_ms
        );
    };
    // A case measured once: a second run of the same graph would be served from the cache,
    // without a frame time.
    let mut measured: Vec<(String, (f64, f64, f64, f64))> = Vec::new();
    let mut normal_mapped = None;
    for c in &scenes {
        let r = run_case(&root, &out, &cache, width, c);
        row(&mut csv, &c.name, &r);
        if c.name == "torus_mdf" {
            normal_mapped = Some(r.normal_mapped);
        }
        measured.push((
            format!("{:?} {:?}", c.sets, c.nodes),
            (r.relative_rmse, r.iou, r.flip, r.frame_ms),
        ));
    }
    std::fs::write(out.join("truth.csv"), &csv).unwrap();

    // Error against frame time on the torus (6-texel bumps), one model choice at a time from
    // the graph's (raw BTF at ubo81, level 0, MDF, 2048² shadow map).
    // A choice: settings, and nodes that stand between the capture and the render.
    type Choice = (String, Vec<String>, Vec<(String, Value)>);
    let pca = |rank: u32, level: u32| -> Vec<(String, Value)> {
        vec![
            (
                "pca".into(),
                json!({ "kind": "btf.pca", "inputs": { "btf": "capture.btf" },
                "params": { "color": "ycbcr", "rank": rank, "chroma_rank": (rank / 4).max(1) } }),
            ),
            (
                "lod".into(),
                json!({ "kind": "btf.lod", "inputs": { "basis": "pca.basis" }, "params": { "level": level } }),
            ),
        ]
    };
    let views = |thetas: &str, phis: &str| -> Vec<String> {
        let set = format!("{{\"thetas\": {thetas}, \"phis\": {phis}}}");
        vec![
            format!("capture.views={set}"),
            format!("capture.lights={set}"),
        ]
    };
    let families: Vec<(&str, Vec<Choice>)> = vec![
        (
            "direction sampling",
            vec![
                (
                    "every 30°".into(),
                    views("[0, 30, 60, 85]", "[0, 60, 120, 180, 240, 300]"),
                    vec![],
                ),
                ("ubo81 (15°)".into(), vec![], vec![]),
            ],
        ),
        (
            "direction interpolation",
            vec![
                (
                    "nearest three, 1/angle".into(),
                    vec!["ours.interpolation=\"nearest\"".into()],
                    vec![],
                ),
                ("bilinear over rings".into(), vec![], vec![]),
            ],
        ),
        (
            "PCA rank (YCbCr)",
            [4u32, 8, 16, 32]
                .iter()
                .map(|&r| (format!("rank {r}"), vec![], pca(r, 0)))
                .collect(),
        ),
        (
            "LOD level (rank 16)",
            [0u32, 1, 2, 3]
                .iter()
                .map(|&l| (format!("level {l}"), vec![], pca(16, l)))
                .collect(),
        ),
        (
            "shadow map",
            [256u32, 512, 1024]
                .iter()
                .map(|&s| {
                    (
                        format!("{s}²"),
                        vec![format!("ours.shadow_resolution={s}")],
                        vec![],
                    )
                })
                .collect(),
        ),
        (
            "MDF",
            vec![
                ("off".into(), vec!["ours.use_mdf=false".into()], vec![]),
                ("on".into(), vec![], vec![]),
            ],
        ),
    ];
    let mut trade = String::from("family,choice,relative_rmse,silhouette_iou,flip,frame_ms\n");
    let mut series = Vec::new();
    for (family, choices) in &families {
        let mut points = Vec::new();
        for (k, (label, sets, nodes)) in choices.iter().enumerate() {
            // The family's first two words: "direction sampling" and "direction
            // interpolation" must not share a folder.
            let slug: Vec<String> = family
                .split_whitespace()
                .take(2)
                .map(|w| w.chars().filter(char::is_ascii_alphanumeric).collect())
                .collect();
            let name = format!("trade_{}_{k}", slug.join("_").to_lowercase());
            let key = format!("{sets:?} {nodes:?}");
            let r = match measured.iter().find(|m| m.0 == key) {
                Some(m) => m.1,
                None => {
                    let r = run_case(
                        &root,
                        &out,
                        &cache,
                        width,
                        &Case {
                            name,
                            sets: sets.clone(),
                            nodes: nodes.clone(),
                            btf: (!nodes.is_empty()).then(|| "lod.basis".to_string()),
                        },
                    );
                    let v = (r.relative_rmse, r.iou, r.flip, r.frame_ms);
                    measured.push((key, v));
                    v
                }
            };
            let _ = writeln!(
                trade,
                "{family},{label},{:.4},{:.4},{:.4},{:.1}",
                r.0, r.1, r.2, r.3
            );
            println!(
                "{family:<22} {label:<14} rel RMSE {:.3}  IoU {:.3}  FLIP {:.3}  frame {:.1} ms",
                r.0, r.1, r.2, r.3
            );
            points.push((r.3, r.0));
        }
        series.push(chart::Series {
            name: family.to_string(),
            points,
            scatter: false,
        });
    }
    if let Some(nm) = normal_mapped {
        let _ = writeln!(
            trade,
            "normal mapping (no BTF),plain mesh + normal map,{:.4},{:.4},{:.4},{:.1}",
            nm.0, nm.1, nm.2, nm.3
        );
        println!(
            "normal mapping (no BTF) rel RMSE {:.3}  IoU {:.3}  FLIP {:.3}  render {:.1} ms (1 sample a pixel, ray traced)",
            nm.0, nm.1, nm.2, nm.3
        );
        series.push(chart::Series {
            name: "normal mapping, no BTF (ray traced, 1 spp)".into(),
            points: vec![(nm.3, nm.0)],
            scatter: true,
        });
    }
    std::fs::write(out.join("truth_tradeoff.csv"), &trade).unwrap();
    let c = chart::Chart {
        title: "Torus, 6-texel bumps: error against the true mesostructure vs frame time (CPU)"
            .into(),
        x_label: "frame time (ms, CPU path)",
        y_label: "relative RMSE against the truth",
        series,
        x_names: None,
    };
    if let Err(e) = chart::write(&out.join("truth_tradeoff"), &c) {
        eprintln!("chart: {e}");
    }
    println!("wrote {}", out.display());
}
