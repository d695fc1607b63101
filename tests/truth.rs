//! How close to the truth, held in CI: `graphs/truth.json` as docs/guide/truth.md measures it (the torus
//! under bumps 6 texels high, a ubo81 Lambert BTF, the MDF, 320 × 240, every node on the CPU)
//! and its open plane with and without the MDF, against the true mesostructure rendered by
//! `render.reference`. The bounds are the (relative RMSE at most 0.30, IoU at least
//! 0.99 on the torus, pixels lit at 75–90° within ±10% on average, the open plane's IoU at least
//! 0.97), and a margin over what `cargo bench --bench truth` measured where the issue sets none,
//! so that a change that loses accuracy fails here.

use mesoflow_testkit::truth_scenes;

use crate::common::{mesoflow, read_npy, report, Scratch};
use serde_json::Value;
use std::path::Path;

struct Measured {
    rmse: f64,
    iou: f64,
    /// Bias of the pixels lit at 75–82° and 82–90° from the macro normal, and their counts.
    grazing: [(f64, usize); 2],
    /// Ours and the truth past the macro horizon (means), and the pixels there.
    past_horizon: (f64, f64, usize),
    /// Mean FLIP over the object's pixels (`flip.mean`).
    flip: f64,
}

fn measure(s: &Scratch, name: &str, sets: &[String]) -> Measured {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut g: Value =
        serde_json::from_str(&std::fs::read_to_string(root.join("graphs/truth.json")).unwrap())
            .unwrap();
    truth_scenes::add_measures(&mut g);
    let graph = s.write(&format!("{name}.json"), &g.to_string());
    let out = s.path(name);
    let mut args: Vec<String> = vec![
        "run".into(),
        graph.display().to_string(),
        "--quiet".into(),
        "--device".into(),
        "cpu".into(),
        "--out-dir".into(),
        out.display().to_string(),
        "--cache-dir".into(),
        s.path("cache").display().to_string(),
        "--output".into(),
        "compare.relative_rmse".into(),
        "--output".into(),
        "compare.iou".into(),
        "--output".into(),
        "flip.mean".into(),
    ];
    for (id, _) in truth_scenes::NPY {
        args.push("--output".into());
        args.push(format!("{id}.files"));
    }
    for kv in sets {
        args.push("--set".into());
        args.push(kv.clone());
    }
    let r = mesoflow(
        &args.iter().map(String::as_str).collect::<Vec<_>>(),
        s.dir.path(),
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let rep = report(&out);
    let compare: &Value = rep["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == "compare")
        .unwrap();
    let m = |k: &str| compare["metrics"][k].as_f64().unwrap_or(f64::NAN);
    let npy = |id: &str| read_npy(&out.join(format!("{id}.npy"))).1;
    let (truth, ours) = (npy("truth_npy"), npy("ours_npy"));
    let (tm, om, cosine) = (
        npy("truth_mask_npy"),
        npy("ours_mask_npy"),
        npy("macro_npy"),
    );
    let flip = rep["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == "flip")
        .and_then(|n| n["metrics"]["mean"].as_f64())
        .unwrap_or(f64::NAN);
    Measured {
        flip,
        rmse: m("relative_rmse"),
        iou: m("iou"),
        grazing: truth_scenes::grazing_bias(&truth, &ours, &tm, &om, &cosine),
        past_horizon: truth_scenes::past_horizon(&truth, &ours, &tm, &om, &cosine),
    }
}

#[test]
#[ignore = "slow: the ground truth at full size, 66 s"]
fn renders_stay_as_close_to_the_true_mesostructure_as_measured() {
    let s = Scratch::new();
    // The torus: the bounds (measured 2026-12-07: relative RMSE 0.2001, IoU 0.9934, pixels
    // lit at 75–82° +6.7%, 82–90° +3.2%; every node on the CPU, so the same bits every run).
    let t = measure(&s, "torus", &[]);
    eprintln!(
        "torus: relative RMSE {:.4}, IoU {:.4}, lit at 75–82° {:+.3} ({} px), 82–90° {:+.3} ({} px)",
        t.rmse, t.iou, t.grazing[0].0, t.grazing[0].1, t.grazing[1].0, t.grazing[1].1
    );
    assert!(t.rmse <= 0.30, "torus relative RMSE {}", t.rmse);
    assert!(t.iou >= 0.99, "torus IoU {}", t.iou);
    // FLIP, which the guide quotes beside the RMSE (measured 0.194 reading the BTF at the
    // pixel's footprint, 0.190 reading its texels; the same bits every run, so a bound 3% above).
    eprintln!("torus: FLIP {:.4}", t.flip);
    assert!(t.flip <= 0.20, "torus FLIP {}", t.flip);
    for (range, (bias, pixels)) in ["75–82°", "82–90°"].iter().zip(t.grazing) {
        // Hundreds of pixels in each range, or the average says little.
        assert!(pixels > 500, "{pixels} pixels lit at {range}");
        assert!(bias.abs() <= 0.10, "pixels lit at {range}: bias {bias:+.3}");
    }
    // Past the macro horizon the curved mesostructure still catches light: the truth averages
    // 0.0146 there, ours 0.0183 (it was black, 0.0036, before the mesostructure decided).
    // Within a factor of 2 either way; hundreds of pixels, or the mean says little.
    let (ours, truth, pixels) = t.past_horizon;
    eprintln!("past the horizon: ours {ours:.4}, truth {truth:.4} ({pixels} px)");
    assert!(pixels > 300, "{pixels} pixels past the horizon");
    assert!(
        ours > 0.5 * truth && ours < 2.0 * truth,
        "past the horizon: ours {ours:.4}, truth {truth:.4}"
    );
    // The open plane: the shell's sides carve its far edge and extend its near one (IoU
    // measured 0.996 with the MDF, 0.923 without), and the parallax-compensated view blend
    // needs the MDF (relative RMSE measured 0.188 with it in the last run,
    // docs/sweeps/truth.csv; 0.362 without).
    let renders = ["truth", "ours", "macro"];
    let with = measure(
        &s,
        "plane_mdf",
        &truth_scenes::plane_sets(320, true, &renders),
    );
    let without = measure(&s, "plane", &truth_scenes::plane_sets(320, false, &renders));
    eprintln!(
        "plane: MDF relative RMSE {:.4}, IoU {:.4}; without {:.4}, {:.4}",
        with.rmse, with.iou, without.rmse, without.iou
    );
    assert!(with.iou >= 0.97, "plane IoU with the MDF {}", with.iou);
    assert!(
        with.iou > without.iou + 0.02,
        "{} vs {}",
        with.iou,
        without.iou
    );
    assert!(
        with.rmse <= 0.22,
        "plane relative RMSE with the MDF {}",
        with.rmse
    );
}
