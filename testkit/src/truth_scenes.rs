//! The scenes of `graphs/truth.json` besides its own torus, as `--set` overrides, and what both
//! `benches/truth.rs` (which measures them) and `tests/truth.rs` (which holds their bounds) add
//! to the graph to measure the pixels lit at grazing angles.

use serde_json::{json, Value};

/// The nodes added to `graphs/truth.json` to measure it: `macro`, the undisplaced mesh rendered
/// by `render.reference` with albedo π under a unit light (its value is the cosine between the
/// macro normal and the light where the light reaches), and .npy writers of the truth, ours,
/// their masks and the cosine (`truth_npy`, `ours_npy`, `truth_mask_npy`, `ours_mask_npy`,
/// `macro_npy`, each written as `<id>.npy`).
pub fn add_measures(g: &mut Value) {
    let nodes = g["nodes"].as_object_mut().expect("a graph has nodes");
    let mut macro_ = nodes["truth"].clone();
    macro_["inputs"]["mesh"] = json!("torus.mesh");
    let pi = std::f64::consts::PI;
    macro_["params"]["albedo"] = json!([pi, pi, pi]);
    macro_["params"]["light"]["intensity"] = json!(1.0);
    nodes.insert("macro".into(), macro_);
    for (id, from) in NPY {
        nodes.insert(
            id.into(),
            json!({ "kind": "npy.write", "inputs": { "value": from }, "params": { "path": format!("{id}.npy") } }),
        );
    }
}

/// The .npy writers [`add_measures`] adds, and what each writes.
pub const NPY: [(&str, &str); 5] = [
    ("truth_npy", "truth.image"),
    ("ours_npy", "ours.image"),
    ("truth_mask_npy", "truth.coverage"),
    ("ours_mask_npy", "ours.mask"),
    ("macro_npy", "macro.image"),
];

/// The bias (ours over truth, summed over RGB, minus 1) of the pixels both show the object in
/// that are lit at 75–82° and at 82–90° from the macro normal, with their counts; NaN where a
/// range has no pixel. Images are RGB, masks and coverage one value a pixel.
pub fn grazing_bias(
    truth: &[f32],
    ours: &[f32],
    truth_mask: &[f32],
    ours_mask: &[f32],
    cosine: &[f32],
) -> [(f64, usize); 2] {
    let mut bins = [(0.0, 0.0, 0usize); 2];
    for px in 0..truth_mask.len() {
        if truth_mask[px] < 0.999 || ours_mask[px] < 0.5 {
            continue;
        }
        let c = cosine[px * 3] as f64;
        if c <= 0.0 {
            continue;
        }
        let angle = c.min(1.0).acos().to_degrees();
        let bin = match angle {
            a if (75.0..82.0).contains(&a) => 0,
            a if a >= 82.0 => 1,
            _ => continue,
        };
        for k in 0..3 {
            bins[bin].0 += ours[px * 3 + k] as f64;
            bins[bin].1 += truth[px * 3 + k] as f64;
        }
        bins[bin].2 += 1;
    }
    bins.map(|(o, t, n)| (if t > 0.0 { o / t - 1.0 } else { f64::NAN }, n))
}

/// The open plane: 2 × 2 units, 4 tiles each way (1/128 unit a texel), bumps 6 texels high,
/// seen obliquely `width` pixels wide; `renders` are the render nodes whose camera and light
/// move (the light's intensity 1 for `macro`, the bench's cosine render).
pub fn plane_sets(width: u32, mdf: bool, renders: &[&str]) -> Vec<String> {
    let h = width * 3 / 4;
    let mut v = vec![
        "torus.shape=plane".to_string(),
        "torus.size=2".into(),
        "torus.segments=[16,16]".into(),
        "true_surface.tiling=[4,4]".into(),
        "ours.tiling=[4,4]".into(),
        // 6 texels of height at 1/128 unit a texel.
        "true_surface.shell=0.046875".into(),
        "ours.shell=0.046875".into(),
    ];
    for id in renders {
        v.push(format!(
            "{id}.camera={{\"eye\": [0.0, -2.3, 1.7], \"target\": [0.0, 0.0, 0.0], \"fov\": 50, \"resolution\": [{width}, {h}]}}"
        ));
        v.push(format!(
            "{id}.light={{\"direction\": [0.45, 0.3, 0.84], \"intensity\": {}}}",
            if *id == "macro" { 1.0 } else { 3.0 }
        ));
    }
    v.push(format!("ours.use_mdf={mdf}"));
    v
}

/// The mean of ours and of the truth (summed over RGB) over the pixels both show the object in
/// whose macro normal faces away from the light (the terminator's far side), and their count.
pub fn past_horizon(
    truth: &[f32],
    ours: &[f32],
    truth_mask: &[f32],
    ours_mask: &[f32],
    cosine: &[f32],
) -> (f64, f64, usize) {
    let (mut o, mut t, mut n) = (0.0, 0.0, 0usize);
    for px in 0..truth_mask.len() {
        if truth_mask[px] < 0.999 || ours_mask[px] < 0.5 || cosine[px * 3] > 0.0 {
            continue;
        }
        for k in 0..3 {
            o += ours[px * 3 + k] as f64;
            t += truth[px * 3 + k] as f64;
        }
        n += 1;
    }
    let mean = |x: f64| if n > 0 { x / n as f64 } else { f64::NAN };
    (mean(o), mean(t), n)
}
