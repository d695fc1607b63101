//! The planner as the arbiter on held-out scenes of both families (issue 57's proof, slow tier):
//! six scenes of each, seeds [`FIRST`].. (held out: never planned while the planner was built),
//! each planned with `mesoflow plan --against truth` at relative RMSE 0.10 and 0.20 and its
//! planned graph run on the full frame against the family's converged truth, beside the graph
//! as given, each model variant and brute force at the samples that meet the budget
//! (`mesoflow_testkit::plan_families`, which `cargo bench --bench plan_families` runs over 24 of
//! each). The bounds are the issue's, fixed before the first run: within the budget on ≥ 95 % of
//! the scenes of each family and budget (with six, every one), every miss within 1.5×, never
//! slower than the graph as given where it meets the budget nor than 1.2× the fastest listed
//! candidate that does, planning at most twice the longer full render of the graph as given
//! and of brute force at the budget (both times one run on a shared machine: 1.2× for that).

use mesoflow_testkit::plan_families::{self, Options, SceneRow, PLAN_RATIO, TIME_SLACK};
use mesoflow_testkit::scenes::{Kind, HELD_OUT};

/// The first seed these tests plan: past the 48 the bench and the planner's development saw.
const FIRST: u64 = HELD_OUT + 48;
const SCENES: u64 = 6;
const BUDGETS: [f64; 2] = [0.1, 0.2];

fn family(kind: Kind) {
    let out = tempfile::tempdir().expect("temp dir");
    let o = Options {
        resolution: kind.resolution(),
        samples: kind.samples(),
        budgets: BUDGETS.to_vec(),
        out: out.path().to_path_buf(),
        sets: Vec::new(),
    };
    let rows: Vec<SceneRow> = (FIRST..FIRST + SCENES)
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
            assert!(
                f.is_empty(),
                "seed {} budget {}: {f:?} (times held to {TIME_SLACK}×, planning to {PLAN_RATIO}×)\n{table}",
                r.seed,
                b.budget
            );
        }
    }
}

#[test]
#[ignore = "slow: six held-out translucent scenes planned against the truth at two budgets"]
fn the_plan_meets_its_budget_on_held_out_translucent_scenes() {
    family(Kind::Translucent);
}

#[test]
#[ignore = "slow: six held-out mesostructure scenes planned against the truth at two budgets"]
fn the_plan_meets_its_budget_on_held_out_mesostructure_scenes() {
    family(Kind::Mesostructure);
}
