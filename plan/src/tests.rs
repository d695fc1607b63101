use super::*;
use mesoflow_nodes::support::raytrace::footprint::shadow_resolution;
use serde_json::json;
use std::collections::BTreeMap;

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
fn budget_zero_is_the_graph_as_given() {
    // The full model is the graph as the user wrote it (issue 41): its own PCA basis, not the
    // raw BTF the planner once put in its place.
    let p = run(&scene(10.0, 0.1), 0.0);
    assert_eq!(p.file, graph());
    assert!(p.decisions.iter().all(|d| d.predicted_error == Some(0.0)));
}

#[test]
fn a_plan_never_gives_more_model_than_the_graph() {
    // A far view whose BTF share no candidate fits (the issue's 11.5 texels per pixel): the
    // user's rank-16 basis stays, never the raw BTF; and no candidate above rank 16 or finer
    // than the graph's level is ever chosen.
    let mut f = graph();
    f.node_mut("pca").unwrap().params =
        serde_json::from_value(json!({"rank": 16, "color": "ycbcr"})).unwrap();
    f.nodes.push((
        "lod".into(),
        mesoflow_graph::NodeDecl {
            kind: "btf.lod".into(),
            params: serde_json::from_value(json!({"level": 1.0})).unwrap(),
            inputs: [("basis".to_string(), "pca.basis".to_string())].into(),
        },
    ));
    f.node_mut("r")
        .unwrap()
        .inputs
        .insert("btf".into(), "lod.basis".into());
    let chain = btf_chain(&f, "r", "btf").unwrap();
    assert!(matches!(
        chain.given,
        Some(GivenBtf::Pca { rank: 16, level, .. }) if level == 1.0
    ));
    for tpp in [0.3, 2.0, 11.5, 40.0] {
        for b in [0.0, 0.001, 0.02, 0.08, 0.3] {
            let p = plan(
                &f,
                "r",
                RenderKind::Mesh,
                &scene(tpp, 1.0),
                Some(&chain),
                Budget::flip(b),
                Split::Joint,
            )
            .unwrap();
            let d = decision(&p, "btf");
            let input = &p.file.node("r").unwrap().inputs["btf"];
            assert_ne!(
                input, "capture.btf",
                "tpp {tpp}, budget {b}: the raw BTF: {d:?}"
            );
            if d.choice["model"] == json!("pca") {
                assert!(d.choice["rank"].as_u64().unwrap() <= 16, "{d:?}");
                assert!(d.choice["level"].as_f64().unwrap() >= 1.0, "{d:?}");
            } else {
                assert_eq!(d.choice["model"], json!("as given"), "{d:?}");
                assert_eq!(input, "lod.basis");
            }
        }
    }
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
                        btf_given: None,
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
                    assert!(b > 0.0 && r.params.get("mode") == Some(&json!("diffusion")));
                    assert!(t > 0.05, "never a finer octree than the graph's");
                    assert_eq!(d.choice["threshold"].as_f64(), Some(t));
                    assert!(
                        d.predicted_error.unwrap() <= 0.1 * b,
                        "{mfp} px, {b}: {d:?}"
                    );
                }
                // Without one the gather keeps the graph's 0.05 (brute force would be more
                // model than the graph), or the render is a BRDF.
                None => assert!(
                    t == 0.05 || r.params.get("mode") == Some(&json!("brdf")),
                    "{t}"
                ),
            }
            // The graph leaves `mode` at its default, diffusion.
            if r.params
                .get("mode")
                .is_none_or(|m| m == &json!("diffusion"))
            {
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
    // Budget 0: the graph as given (no brute force, no PBD it did not ask for).
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
    assert_eq!(p.file, f);
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

/// Every render node of every shipped graph, planned at every budget for near and far views
/// (textures and shells from sub-pixel to many pixels): the planned graph passes the static
/// check, so every parameter the planner writes exists in its kind's schema and has a value the
/// kind accepts, and every connection it makes has matching types.
#[test]
fn every_parameter_the_planner_writes_is_in_its_kind_s_schema() {
    let registry = mesoflow_nodes::registry::builtin();
    let dir = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../graphs"));
    let mut planned = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "json") {
            continue;
        }
        // As `mesoflow plan` reads it: located, its subgraphs inlined.
        let file = GraphFile::parse(&std::fs::read_to_string(&path).unwrap())
            .unwrap()
            .located(&path);
        let file = mesoflow_graph::subgraph::expand(&file).unwrap();
        for (id, decl) in &file.nodes {
            let Some(kind) = RenderKind::of(&decl.kind) else {
                continue;
            };
            let chain = kind.btf_port().and_then(|p| btf_chain(&file, id, p));
            for (tpp, shell_px, mfp_px) in [(0.3, 0.2, 0.2), (2.0, 3.0, 4.0), (12.0, 0.05, 40.0)] {
                let mut s = scene(tpp, shell_px);
                s.object_pixels = Some(5000.0);
                s.mfp_mm = Some(1.0);
                s.mfp_min_mm = Some(0.5);
                s.mfp_pixels = Some(mfp_px);
                for b in [0.0, 0.02, 0.1, 0.4, 1.0] {
                    let p = plan(
                        &file,
                        id,
                        kind,
                        &s,
                        chain.as_ref(),
                        Budget::flip(b),
                        Split::Joint,
                    )
                    .unwrap_or_else(|e| panic!("{}: {id}: {e}", path.display()));
                    let name = format!("{} planned for {id} at {b}", path.display());
                    if let Err(e) = mesoflow_graph::check(&name, &p.file, &registry) {
                        panic!("{e}");
                    }
                    planned += 1;
                }
            }
        }
    }
    // 21 render nodes in the shipped graphs, 3 views, 5 budgets.
    assert!(planned >= 300, "{planned}");
}
