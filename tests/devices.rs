//! Where GPU nodes run: the CPU fallback unless a GPU is required, a machine whose only adapter
//! is software OpenGL, and one whose only adapter is Mesa's software Vulkan (lavapipe).

use crate::common::*;
use std::path::Path;

#[test]
fn gpu_nodes_fall_back_to_the_cpu_unless_a_gpu_is_required() {
    // WGPU_BACKEND=dx12 on Linux leaves wgpu without any adapter: the no-GPU machine, simulated.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let g = root.join("graphs/quickstart.json");
    let go = |out: &str, require: &str| {
        let out = s.path(out);
        let r = Run::from(
            bin()
                .args([
                    "run",
                    g.to_str().unwrap(),
                    "--quiet",
                    "--no-cache",
                    "--output",
                    "normals.rms_slope",
                    "--out-dir",
                    out.to_str().unwrap(),
                ])
                .env("WGPU_BACKEND", "dx12")
                .env("MESOFLOW_REQUIRE_GPU", require)
                .output()
                .unwrap(),
        );
        (r, report(&out))
    };
    let (r, rep) = go("fallback", "0");
    assert_eq!(r.code, 0, "{}", r.stderr);
    let normals = rep["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == "normals")
        .unwrap()
        .clone();
    assert_eq!(normals["device"], "cpu");
    let w = rep["warnings"].as_array().unwrap();
    assert!(
        w.iter().any(|w| w["node"] == "normals"
            && w["message"].as_str().unwrap().contains("ran the CPU path")),
        "{w:?}"
    );

    let (r, rep) = go("required", "1");
    assert_eq!(r.code, 1);
    let normals = rep["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == "normals")
        .unwrap()
        .clone();
    assert_eq!(normals["status"], "failed");
    assert!(
        normals["error"]
            .as_str()
            .unwrap()
            .contains("MESOFLOW_REQUIRE_GPU=1"),
        "{normals}"
    );

    // --device cpu is an explicit choice: no adapter needed, no warning.
    let out = s.path("cpu");
    let r = bin()
        .args([
            "run",
            g.to_str().unwrap(),
            "--quiet",
            "--no-cache",
            "--device",
            "cpu",
            "--out-dir",
            out.to_str().unwrap(),
        ])
        .env("WGPU_BACKEND", "dx12")
        .env("MESOFLOW_REQUIRE_GPU", "1")
        .output()
        .unwrap();
    assert!(r.status.success());
    assert!(report(&out)["warnings"].as_array().unwrap().is_empty());
}

#[test]
fn a_machine_whose_only_adapter_is_software_opengl_runs_the_gpu_graphs_on_the_cpu_path() {
    // WGPU_BACKEND=gl: the machine without Mesa's Vulkan driver. `auto` must not pick llvmpipe
    // through GL (no float render targets, slower than the CPU path): the CPU path, a warning.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let out = s.path("o");
    let dirs = r#"{"thetas": [0, 40, 80], "phis": [0, 90, 180, 270]}"#;
    let mut args: Vec<String> = vec![
        "run".into(),
        root.join("graphs/mdf_render.json").display().to_string(),
        "--quiet".into(),
        "--no-cache".into(),
        "--out-dir".into(),
        out.display().to_string(),
    ];
    let mut sets: Vec<String> = vec![
        "tile.size=16".into(),
        format!("tile.views={dirs}"),
        format!("tile.lights={dirs}"),
        format!("mdf.views={dirs}"),
    ];
    for r in [
        "sphere_plain",
        "sphere_mdf",
        "torus_plain",
        "torus_mdf",
        "torus_reference",
    ] {
        sets.push(format!("{r}.camera.resolution=[32,24]"));
    }
    for kv in sets {
        args.push("--set".into());
        args.push(kv);
    }
    let r = Run::from(
        bin()
            .args(&args)
            .env("WGPU_BACKEND", "gl")
            .env_remove("MESOFLOW_REQUIRE_GPU")
            .output()
            .unwrap(),
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let rep = report(&out);
    let devices = per_node(&rep, "device");
    for id in ["mdf", "sphere_mdf", "torus_mdf"] {
        assert_eq!(devices[id], "cpu", "{id}: {rep}");
    }
    let w = rep["warnings"].as_array().unwrap();
    let why = |text: &str| {
        w.iter()
            .any(|w| w["node"] == "torus_mdf" && w["message"].as_str().unwrap().contains(text))
    };
    // CI installs Mesa's GL driver, so there the adapter exists and the reason is named.
    if std::env::var("CI").is_ok() {
        assert!(why("OpenGL, software"), "{w:?}");
    } else {
        assert!(why("OpenGL, software") || why("no GPU adapter"), "{w:?}");
    }
}

#[test]
fn auto_passes_over_a_software_vulkan_adapter_and_device_gpu_takes_it() {
    // Lavapipe runs our shaders on the CPU, the heavy ones slower than the CPU path (render.mesh
    // 2.1 s against 0.64 s, BENCHMARKS.md): `auto` takes the CPU path and says why; `--device
    // gpu` still runs the GPU code there, as CI tests it.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let g = root.join("graphs/quickstart.json");
    let go = |out: &str, device: &str| {
        let out = s.path(out);
        let r = Run::from(
            bin()
                .args([
                    "run",
                    g.to_str().unwrap(),
                    "--quiet",
                    "--no-cache",
                    "--set",
                    "surface.size=16",
                    "--device",
                    device,
                    "--out-dir",
                    out.to_str().unwrap(),
                ])
                .env("WGPU_BACKEND", "vulkan")
                .output()
                .unwrap(),
        );
        (r, report(&out))
    };
    let (r, gpu) = go("gpu", "gpu");
    let adapter = gpu["adapter"].as_str().unwrap_or_default().to_string();
    if r.code != 0 {
        // Only a missing adapter may skip; any other failure of the GPU run is this test's.
        assert!(
            r.stderr.contains("no GPU adapter"),
            "--device gpu failed for another reason than a missing adapter: {}",
            r.stderr
        );
        mesoflow_testkit::skip_unless_required(
            "MESOFLOW_REQUIRE_GPU",
            "no Vulkan adapter: nothing to pass over",
        );
        return;
    }
    if !adapter.contains("Vulkan, software") {
        // A hardware adapter: auto takes it, which the other tests see.
        mesoflow_testkit::skip(&format!(
            "the Vulkan adapter is `{adapter}`, not a software one"
        ));
        return;
    }
    assert_eq!(per_node(&gpu, "device")["normals"], "gpu", "{gpu}");
    let (r, auto) = go("auto", "auto");
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(per_node(&auto, "device")["normals"], "cpu", "{auto}");
    let w = auto["warnings"].as_array().unwrap();
    assert!(
        w.iter().any(|w| w["node"] == "normals"
            && w["message"].as_str().unwrap().contains("Vulkan, software")
            && w["message"].as_str().unwrap().contains("ran the CPU path")),
        "{w:?}"
    );
}

/// A warm run keys its GPU nodes from the probe remembered in the disk cache
/// (`gpu-probe.json`) instead of loading a driver, and a remembered probe that no longer holds
/// is caught before anything is computed under it: the graph is keyed again from the live one.
#[test]
fn a_warm_run_keys_gpu_nodes_from_the_remembered_probe_and_a_stale_one_is_caught() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let s = Scratch::new();
    let g = root.join("graphs/quickstart.json");
    let cache = s.path("cache");
    let memo = cache.join("gpu-probe.json");
    let go = |out: &str, device: &str| {
        let (r, rep) = run(
            &s,
            &g,
            out,
            &[
                "--cache-dir",
                cache.to_str().unwrap(),
                "--device",
                device,
                "--output",
                "normals.rms_slope",
            ],
        );
        assert_eq!(r.code, 0, "{}", r.stderr);
        rep
    };
    let node = |rep: &serde_json::Value, field: &str| per_node(rep, field)["normals"].clone();
    // The first auto run probes and remembers what it found.
    let first = go("first", "auto");
    let written: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&memo).expect("the probe is remembered")).unwrap();
    let live = written["found"].clone();
    let plant = |found: serde_json::Value| {
        let mut m = written.clone();
        m["found"] = found;
        std::fs::write(&memo, m.to_string()).unwrap();
    };

    // A remembered probe that no longer holds, naming the path the live one does not take:
    // the normals would be computed under that path's key, so the live probe is asked first,
    // disagrees, and the run is keyed again.
    let imagined_gpu = serde_json::json!({ "hardware": "an imagined GPU, Vulkan" });
    let imagined_software = serde_json::json!({ "software": "an imagined software adapter" });
    plant(if live.get("hardware").is_some() {
        imagined_software.clone()
    } else {
        imagined_gpu
    });
    let stale = go("stale", "auto");
    let after: serde_json::Value = serde_json::from_slice(&std::fs::read(&memo).unwrap()).unwrap();
    assert_eq!(
        after["found"], live,
        "the memo is rewritten from the live probe"
    );
    let w = stale["warnings"].as_array().unwrap();
    assert!(
        w.iter()
            .any(|w| w["message"].as_str().unwrap().contains("no longer holds")),
        "{w:?}"
    );
    // Keyed from the live probe, the run is the first run again, served from the cache.
    assert_eq!(node(&stale, "key"), node(&first, "key"));
    assert_eq!(node(&stale, "status"), "disk");

    // A remembered software adapter keys the CPU path, which `--device cpu` has cached: the
    // value is served and the memo is left as planted, so nothing probed the driver.
    let cpu = go("cpu", "cpu");
    plant(imagined_software.clone());
    let warm = go("warm", "auto");
    assert_eq!(node(&warm, "status"), "disk");
    assert_eq!(node(&warm, "device"), "cpu");
    assert_eq!(node(&warm, "key"), node(&cpu, "key"));
    let after: serde_json::Value = serde_json::from_slice(&std::fs::read(&memo).unwrap()).unwrap();
    assert_eq!(
        after["found"], imagined_software,
        "the remembered probe was not used"
    );
}
