//! The planner as the arbiter on held-out scenes of both families (issue 57's proof, slow tier):
//! six scenes of each, drawn from `scenes::HELD_OUT` on, at test size, each planned with
//! `mesoflow plan --against truth` at relative RMSE 0.10 and 0.20 and its planned graph run on the
//! full frame against the family's converged truth, beside the graph as given, each model variant
//! and brute force at the samples that meet the budget (`mesoflow_testkit::plan_families`).
//! The bounds are the issue's, fixed before the first run: within budget on ≥ 95 % of the scenes
//! of each family and budget (with six, every one), every miss within 1.5×, never slower than the
//! graph as given where it meets the budget nor than the fastest listed candidate that does (1.2×
//! for one-run timing noise), planning at most twice the longer full render. The bench
//! (`cargo bench --bench plan_families`) runs 24 of each at the families' own sizes.

use mesoflow_testkit::plan_families::{self, Options, SceneRow};
use mesoflow_testkit::scenes::{Kind, HELD_OUT};

const SCENES: u64 = 6;
const BUDGETS: [f64; 2] = [0.1, 0.2];

fn family(kind: Kind, resolution: [u32; 2], samples: u32, sets: &[&str]) {
    let out = tempfile::tempdir().expect("temp dir");
    let o = Options {
        resolution,
        samples,
        budgets: BUDGETS.to_vec(),
        out: out.path().to_path_buf(),
        sets: sets.iter().map(|s| s.to_string()).collect(),
    };
    let rows: Vec<SceneRow> = (HELD_OUT..HELD_OUT + SCENES)
        .map(|seed| plan_families::scene(kind, seed, &o))
        .collect();
    let mut table = String::new();
    for r in &rows {
        for b in &r.budgets {
            table.push_str(&format!(
                "seed {} budget {}: planned {} error {:?} {:?} s; given error {:?} {:?} s; brute {} spp {:?} {:?} s; plan {:.1} s ({:?}×) {:?}\n",
                r.seed, b.budget, b.planned.name, b.planned.error, b.planned.seconds,
                r.given.error, r.given.seconds, b.brute_samples, b.brute.error, b.brute.seconds,
                b.plan_seconds, r.plan_ratio(b), r.failures(b)
            ));
        }
    }
    eprintln!("{}:\n{table}", kind.name());
    for &b in &BUDGETS {
        let within = rows
            .iter()
            .filter(|r| r.budgets.iter().any(|x| x.budget == b && x.planned.fits(b)))
            .count();
        assert!(
            within as f64 >= 0.95 * rows.len() as f64,
            "{}: {within} of {} within the budget {b}\n{table}",
            kind.name(),
            rows.len()
        );
    }
    for r in &rows {
        for b in &r.budgets {
            let f = r.failures(b);
            assert!(f.is_empty(), "seed {} budget {}: {f:?}\n{table}", r.seed, b.budget);
        }
    }
}

#[test]
#[ignore = "slow: six held-out translucent scenes planned against the truth at two budgets"]
fn the_plan_meets_its_budget_on_held_out_translucent_scenes() {
    family(
        Kind::Translucent,
        [32, 24],
        256,
        &[
            "mesh.segments=[32,16]",
            "lighting.max_points=2000",
            "lighting.shadow_resolution=128",
        ],
    );
}

#[test]
#[ignore = "slow: six held-out mesostructure scenes planned against the truth at two budgets"]
fn the_plan_meets_its_budget_on_held_out_mesostructure_scenes() {
    family(Kind::Mesostructure, [80, 60], 64, &[]);
}
