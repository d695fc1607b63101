//! The scenes of `graphs/truth.json` besides its own torus, as `--set` overrides, shared by
//! `benches/truth.rs` (which measures them) and `tests/truth.rs` (which holds their bounds).

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
