//! Every shipped graph, at small sizes, three times over one disk cache: cold, warm into a new
//! output folder (every file must be written again, every node served from the cache or not
//! needed), and with `--verify-cache` (every hit recomputed and equal to its cache entry).

use crate::common::*;
use std::collections::BTreeSet;
use std::path::Path;

const DIRS: &str = r#"{"thetas": [0, 40, 80], "phis": [0, 90, 180, 270]}"#;

/// Parameter overrides that make a graph small enough for CI; the graph's structure is unchanged.
fn small(graph: &str) -> Vec<String> {
    let render = |ids: &[&str]| -> Vec<String> {
        ids.iter()
            .flat_map(|id| {
                [
                    format!("{id}.camera.resolution=[32,24]"),
                    format!("{id}.shadow_resolution=128"),
                ]
            })
            .collect()
    };
    // Subsurface renders gather with `exit_normal` from 500 entry points: the `body` grid
    // solver (3-8 s a render at 24+ cells across) and the bounce tracing at 3000 points made
    // sss_truth 70 s and qh_render 32 s of this test. `body` stays covered here by
    // family_translucent (through its `lighting`) and by the sss.render unit tests.
    let sss = |ids: &[&str]| -> Vec<String> {
        let mut v = render(ids);
        v.extend(ids.iter().flat_map(|id| {
            [
                format!("{id}.max_points=500"),
                format!("{id}.geometry=exit_normal"),
            ]
        }));
        v
    };
    let mut s: Vec<String> = match graph {
        "btf_capture" => vec!["tile.size=16".into()],
        "woven_capture" => vec![
            "surface.size=16".into(),
            format!("capture.views={DIRS}"),
            format!("capture.lights={DIRS}"),
        ],
        "btf_edit" => vec![
            format!("capture.views={DIRS}"),
            format!("capture.lights={DIRS}"),
            format!("recovered.views={DIRS}"),
            format!("recovered.lights={DIRS}"),
            "fit.iterations=50".into(),
            format!("mdf.views={DIRS}"),
            "exact.camera.resolution=[32,24]".into(),
            "exact.shadow_resolution=128".into(),
            "relief.camera.resolution=[32,24]".into(),
            "relief_converged.camera.resolution=[32,24]".into(),
        ],
        "btf_compress" => vec!["surface.size=16".into(), "pca.rank=3".into()],
        "btf_environment" => vec![
            "surface.size=16".into(),
            format!("capture.views={DIRS}"),
            format!("capture.lights={DIRS}"),
            "capture.bounce_rays=16".into(),
            format!("mdf.views={DIRS}"),
            "torus.segments=[24,12]".into(),
            "truth.camera.resolution=[32,24]".into(),
            "truth.samples=4".into(),
            "ours.camera.resolution=[32,24]".into(),
            "ours.environment_order=3".into(),
        ],
        "family_translucent" => vec![
            "mesh.segments=[32,16]".into(),
            "truth.samples=4".into(),
            "truth.camera.resolution=[32,24]".into(),
            // Fewer mean free paths across: a coarser body grid (3.8 s → 1.2 s).
            "lighting.mm_per_unit=10".into(),
            "truth.mm_per_unit=10".into(),
            // `ours` takes the lighting parameters from `lighting` (sss.lighting).
            "ours.camera.resolution=[32,24]".into(),
            "lighting.shadow_resolution=128".into(),
            "lighting.max_points=3000".into(),
        ],
        "family_mesostructure" => vec![
            "pattern.size=16".into(),
            format!("capture.views={DIRS}"),
            format!("capture.lights={DIRS}"),
            format!("mdf.views={DIRS}"),
            "mesh.segments=[32,16]".into(),
            "truth.samples=4".into(),
            "truth.camera.resolution=[32,24]".into(),
            "ours.camera.resolution=[32,24]".into(),
        ],
        "family_height_from_normals" => vec!["pattern.size=32".into()],
        "family_ward_fit" => vec![],
        "height_from_normals" => vec!["tile.size=32".into()],
        "isomap" => vec!["roll.n=300".into(), "landmark.landmarks=50".into()],
        "mdf_render" => {
            let mut v: Vec<String> = vec![
                "tile.size=16".into(),
                format!("tile.views={DIRS}"),
                format!("tile.lights={DIRS}"),
                format!("mdf.views={DIRS}"),
                "pca.rank=4".into(),
            ];
            v.extend(render(&[
                "sphere_plain",
                "sphere_mdf",
                "torus_plain",
                "torus_mdf",
                "torus_reference",
            ]));
            v
        }
        "plan_verify" => {
            let mut v: Vec<String> = vec![
                "surface.size=16".into(),
                format!("capture.views={DIRS}"),
                format!("capture.lights={DIRS}"),
                format!("mdf.views={DIRS}"),
                "torus.segments=[32,16]".into(),
                "sphere.segments=[32,16]".into(),
            ];
            v.extend(render(&["btf_full", "btf_view"]));
            v.extend(sss(&["sss_full", "sss_view"]));
            v
        }
        "plan_photo" => {
            let mut v: Vec<String> = vec![
                format!("capture.views={DIRS}"),
                format!("capture.lights={DIRS}"),
                format!("mdf.views={DIRS}"),
                "pca.rank=4".into(),
                "torus.segments=[32,16]".into(),
            ];
            v.extend(render(&["full", "view"]));
            v
        }
        "plan_qh" => {
            let mut v: Vec<String> = vec![
                "surface.size=16".into(),
                format!("lrf.views={DIRS}"),
                format!("lrf.lights={DIRS}"),
                "torus.segments=[32,16]".into(),
                "entrance.width=64".into(),
                "entrance.height=64".into(),
                "entrance.patch_sizes=[8,4]".into(),
                "entrance.iterations=1".into(),
            ];
            v.extend(sss(&["qh_full", "qh_view"]));
            v
        }
        "export" => vec![
            "skin.photons=40000".into(),
            "skin/measured.photons=20000".into(),
            "skin/refit.photons=20000".into(),
        ],
        "qh_fit" => vec![
            "measured.photons=20000".into(),
            "fit_mc.photons=40000".into(),
            "refit.photons=20000".into(),
        ],
        "qh_render" => {
            let mut v: Vec<String> = vec![
                "tile.size=16".into(),
                format!("tile.views={DIRS}"),
                format!("tile.lights={DIRS}"),
                "torus.segments=[32,16]".into(),
            ];
            v.extend(sss(&["homogeneous", "qh"]));
            v
        }
        "quickstart" => vec!["surface.size=32".into()],
        "sss_models" => vec!["reference.photons=20000".into(), "profile.points=64".into()],
        "sss_render" => {
            let mut v: Vec<String> = vec!["torus.segments=[32,16]".into()];
            v.extend(sss(&["marble", "skin", "marble_reference"]));
            v
        }
        "sss_truth" => {
            let mut v: Vec<String> = vec![
                "torus.segments=[32,16]".into(),
                "marble_truth.samples=4".into(),
                "skin1_truth.samples=4".into(),
                "marble_truth.camera.resolution=[32,24]".into(),
                "skin1_truth.camera.resolution=[32,24]".into(),
                // Fewer mean free paths across the torus: coarser tables, fewer entry points.
                "marble_truth.mm_per_unit=5".into(),
                "skin1_truth.mm_per_unit=5".into(),
                "marble.mm_per_unit=5".into(),
                "skin1.mm_per_unit=5".into(),
                "marble_brute.mm_per_unit=5".into(),
            ];
            v.extend(sss(&["marble", "skin1", "marble_brute"]));
            v
        }
        "truth" => vec![
            "surface.size=16".into(),
            format!("capture.views={DIRS}"),
            format!("capture.lights={DIRS}"),
            format!("mdf.views={DIRS}"),
            "torus.segments=[24,12]".into(),
            "truth.camera.resolution=[32,24]".into(),
            "truth.samples=4".into(),
            "ours.camera.resolution=[32,24]".into(),
            "ours.shadow_resolution=128".into(),
        ],
        "weathering" => vec!["sample.size=24".into()],
        "weathering_transfer" => vec![
            "sample.size=32".into(),
            "sample.seeds=4".into(),
            "guide.width=48".into(),
            "guide.height=32".into(),
            "synth.patch_sizes=[8,4]".into(),
            "synth.levels=2".into(),
            "synth.iterations=1".into(),
        ],
        other => panic!("graphs/{other}.json has no small settings in tests/every_graph.rs"),
    };
    s.sort();
    s
}

fn run(
    root: &Path,
    graph: &Path,
    cache: &Path,
    out: &Path,
    sets: &[String],
    extra: &[&str],
) -> Run {
    let mut args: Vec<String> = vec![
        "run".into(),
        graph.display().to_string(),
        "--quiet".into(),
        "--cache-dir".into(),
        cache.display().to_string(),
        "--out-dir".into(),
        out.display().to_string(),
    ];
    for kv in sets {
        args.push("--set".into());
        args.push(kv.clone());
    }
    args.extend(extra.iter().map(|s| s.to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    mesoflow(&args, root)
}

/// Files under `dir`, relative, without the report.
fn files(dir: &Path) -> BTreeSet<String> {
    fn walk(base: &Path, dir: &Path, out: &mut BTreeSet<String>) {
        for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(base, &p, out);
            } else if let Ok(rel) = p.strip_prefix(base) {
                out.insert(rel.display().to_string());
            }
        }
    }
    let mut out = BTreeSet::new();
    walk(dir, dir, &mut out);
    out.remove("report.json");
    out
}

#[test]
fn every_graph_runs_cold_then_warm_with_every_file_then_verifies_its_cache() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut graphs: Vec<_> = std::fs::read_dir(root.join("graphs"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        // What `mesoflow plan` writes beside a graph is the user's, not a shipped graph.
        .filter(|p| {
            let name = p.file_name().unwrap().to_string_lossy();
            !name.ends_with(".planned.json") && !name.ends_with(".plan.json")
        })
        .collect();
    graphs.sort();
    assert!(graphs.len() >= 11, "{graphs:?}");
    for graph in graphs {
        let name = graph.file_stem().unwrap().to_string_lossy().into_owned();
        let sets = small(&name);
        let s = Scratch::new();
        let cache = s.path("cache");
        let (cold, warm, verify) = (s.path("cold"), s.path("warm"), s.path("verify"));

        let t = std::time::Instant::now();
        let r = run(root, &graph, &cache, &cold, &sets, &[]);
        assert_eq!(r.code, 0, "{name} cold: {}", r.stderr);
        let cold_s = t.elapsed().as_secs_f64();
        let cold_files = files(&cold);

        let r = run(root, &graph, &cache, &warm, &sets, &[]);
        assert_eq!(r.code, 0, "{name} warm: {}", r.stderr);
        let rep = report(&warm);
        let computed: Vec<_> = statuses(&rep)
            .into_iter()
            .filter(|(_, st)| st == "computed")
            .collect();
        // Kinds that never enter the disk cache (`disk_cache: false`: cheaper to recompute than
        // to read back) compute again in a new process; any other computed node is a miss.
        let allowed = [
            "scalar.constant",
            "scalar.affine",
            "mesh.primitive",
            "btf.lod",
            "btf.write_ubo2003",
            "btf.reconstruct",
            "qh.fit_dipole",
            "image.ramp",
            "image.blur",
            "image.compare",
            "image.row",
            "points.read",
            "points.synthetic",
            "weathering.sample",
            "sss.material",
            "sss.compare",
        ];
        for (id, _) in &computed {
            let kind = rep["nodes"]
                .as_array()
                .unwrap()
                .iter()
                .find(|n| n["id"] == id.as_str())
                .map(|n| n["kind"].as_str().unwrap_or("").to_string())
                .unwrap_or_default();
            assert!(
                allowed.contains(&kind.as_str()),
                "{name}: `{id}` ({kind}) was computed again on a warm run"
            );
        }
        assert_eq!(
            files(&warm),
            cold_files,
            "{name}: a warm run into a new folder must write every file"
        );
        for f in &cold_files {
            assert_eq!(
                std::fs::read(cold.join(f)).unwrap(),
                std::fs::read(warm.join(f)).unwrap(),
                "{name}: {f} differs between the cold and the warm run"
            );
        }

        let r = run(root, &graph, &cache, &verify, &sets, &["--verify-cache"]);
        assert_eq!(r.code, 0, "{name} --verify-cache: {}", r.stderr);
        let rep = report(&verify);
        assert_eq!(rep["ok"], true, "{name}");
        eprintln!(
            "every_graph: {name}: cold {cold_s:.1} s, all three {:.1} s",
            t.elapsed().as_secs_f64()
        );
        assert_no_temp_files(&cache);
    }
}
