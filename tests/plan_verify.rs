//! The planner held to its budget on `graphs/plan_verify.json`: the verification sweep that
//! `benches/plan_verify.rs` charts (7 camera distances × 4 budgets × a BTF torus and a skin
//! sphere, 240 × 180), with the acceptance bounds: at least 95% of the cases within the
//! budget (mean FLIP over the object's pixels), and every miss within 1.5× of it; the prediction
//! not below the measurement by more than a quarter of the budget; and time saved over the far
//! half of the distances, so that a planner that never simplifies fails as surely as one that
//! overspends. The charts are the bench's.

use mesoflow_testkit::plan_sweep;

/// The translucent far views' median time saved on the CPU path (see below).
const SSS_CPU: f64 = 3.0;

#[test]
#[ignore = "slow: the full verification sweep, 56 cases, each plan proved on a probe, 1.5 min"]
fn planned_views_stay_within_their_flip_budget() {
    let out = tempfile::tempdir().expect("temp dir");
    let rows = plan_sweep::sweep(out.path(), 240, "joint", None);
    assert_eq!(
        rows.len(),
        plan_sweep::DISTANCES.len() * plan_sweep::BUDGETS.len() * plan_sweep::OBJECTS.len()
    );
    let table: Vec<String> = rows
        .iter()
        .map(|r| {
            format!(
                "{} d={} b={}: FLIP {:.4} (predicted {:?}) {}",
                r.object, r.distance, r.budget, r.flip, r.predicted, r.decisions
            )
        })
        .collect();
    let table = table.join("\n");
    assert!(rows.iter().all(|r| r.flip.is_finite()), "{table}");
    let within = rows.iter().filter(|r| r.flip <= r.budget).count();
    // The acceptance: ≥ 95% within budget, every miss within 1.5×.
    assert!(
        within as f64 >= 0.95 * rows.len() as f64,
        "{within} of {} within budget\n{table}",
        rows.len()
    );
    for r in rows.iter().filter(|r| r.flip > r.budget) {
        assert!(r.flip <= 1.5 * r.budget, "a miss beyond 1.5×\n{table}");
    }
    // Predicted ≥ measured, within a quarter of the budget: the last charted sweep
    // (docs/sweeps/plan_verify.csv) measured at most 0.057 of the budget above the prediction.
    for r in &rows {
        if let Some(p) = r.predicted {
            assert!(
                r.flip <= p + 0.25 * r.budget,
                "{} d={} b={}: measured {:.4} above the predicted {p:.4} by more than a quarter of the budget\n{table}",
                r.object, r.distance, r.budget, r.flip
            );
        }
    }
    // Time saved where the view shows less: the far half of the distances (7 and beyond). The
    // last charted sweep had medians of 5.5× (BTF) and 1.2× (translucent) on lavapipe
    // (BENCHMARKS.md), 10× and 5.9× on the CPU path; the bounds are half the BTF's and, over
    // both objects, 1.5×, which a planner that keeps the full model (1×) cannot reach.
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let far = |object: Option<&str>| -> Vec<f64> {
        rows.iter()
            .filter(|r| r.distance >= 7.0 && object.is_none_or(|o| r.object == o))
            .map(|r| r.full_s / r.view_s.max(1e-9))
            .collect()
    };
    let (btf, sss, all) = (
        median(far(Some("btf"))),
        median(far(Some("sss"))),
        median(far(None)),
    );
    println!(
        "far half, median render time saved: BTF {btf:.2}×, translucent {sss:.2}×, both objects {all:.2}×"
    );
    // On the CPU path `render.mesh`'s shadow map is traced only where pixels look it up (issue
    // 56), so the graph's 512² map no longer costs more than a planned 32–128² one, and the far
    // BTF views, already a few milliseconds, have little left to save: measured 1.00× (BTF)
    // there on 2026-12-06, twice, where the median over both objects (half of them near 1×)
    // then moved between 1.13× and 1.29× from run to run. On the CPU the bounds are that a BTF
    // plan is not slower (≥ 0.7×, see below) and that the translucent views still save (≥ 3×, about half
    // their measured 6.78×, which a planner that keeps the full model, 1×, cannot
    // reach); on a GPU, whose map is still drawn whole, the bounds above. The BTF bound is 0.7×,
    // not 0.9×: those frames take a few milliseconds each, and CI measured 0.84× on a run where
    // this machine measured 1.00× (single-frame noise, BENCHMARKS.md: ±20%); this machine then
    // measured 0.67× once beside the other tests (2026-12-07), so each render now times the mean
    // of `plan_sweep::TIMED_FRAMES` frames.
    let cpu = rows.iter().any(|r| r.object == "btf" && r.device == "cpu");
    if cpu {
        assert!(
            btf >= 0.7,
            "the far half's BTF views on the CPU are {btf:.2}× the graph's time (median)\n{table}"
        );
        assert!(
            sss >= SSS_CPU,
            "the far half's translucent views saved only {sss:.2}× (median)\n{table}"
        );
        return;
    }
    let (btf_bound, all_bound) = (2.5, 1.5);
    assert!(
        btf >= btf_bound,
        "the far half's BTF views saved only {btf:.2}× (median)\n{table}"
    );
    assert!(
        all >= all_bound,
        "the far half's views saved only {all:.2}× (median; bound {all_bound}×)\n{table}"
    );
}
