//! `mesoflow sweep`: runs a graph once per combination of parameter values, on one engine so that
//! nodes upstream of the varied parameters compute once; writes `sweep.csv` and charts of every
//! measure against every varied parameter and against the measured node's time.

use crate::args::{EngineArg, SweepArgs};
use crate::exit::invalid;
use crate::load;
use crate::progress::summary;
use crate::session::{
    cache_dir, cancel_flag, device_mode, device_name, engine, graph_dir, graph_name, parse_outputs,
    policy, slurm_run_dir,
};
use crate::sweep::{Sweep, Vary};
use mesoflow_graph::edit::parse_value;
use mesoflow_runtime::{RunOptions, RunPolicy};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// Splits on commas outside brackets and quotes, so `[1,2],[3,4]` is two values.
fn split_values(text: &str) -> Vec<String> {
    let (mut out, mut cur, mut depth, mut quoted) = (Vec::new(), String::new(), 0i32, false);
    for ch in text.chars() {
        match ch {
            '"' => quoted = !quoted,
            '[' | '{' if !quoted => depth += 1,
            ']' | '}' if !quoted => depth -= 1,
            ',' if !quoted && depth == 0 => {
                out.push(std::mem::take(&mut cur));
                continue;
            }
            _ => {}
        }
        cur.push(ch);
    }
    out.push(cur);
    out.into_iter()
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .collect()
}

fn parse_vary(text: &str) -> anyhow::Result<Vary> {
    let (target, values) = text
        .split_once('=')
        .ok_or_else(|| invalid(format!("--vary {text}: expected id.param=v1,v2,…")))?;
    let (node, param) = target
        .split_once('.')
        .filter(|(n, p)| !n.is_empty() && !p.is_empty())
        .ok_or_else(|| invalid(format!("--vary {text}: expected id.param=v1,v2,…")))?;
    let values: Vec<Value> = split_values(values)
        .iter()
        .map(|v| parse_value(v))
        .collect();
    if values.is_empty() {
        return Err(invalid(format!("--vary {text}: no values")));
    }
    Ok(Vary {
        node: node.into(),
        param: param.into(),
        values,
    })
}

pub fn sweep(args: &SweepArgs) -> anyhow::Result<i32> {
    let varies: Vec<Vary> = args
        .vary
        .iter()
        .map(|v| parse_vary(v))
        .collect::<anyhow::Result<_>>()?;
    let measures = parse_outputs(&args.measure)?;
    let versus = parse_outputs(&args.versus)?;
    let engine = engine(&args.cache, &args.graph.path)?;
    let mut base_file = load::read(&args.graph.path)?;
    load::apply_sets(&mut base_file, &args.graph.set)?;
    // A subgraph's exposed output (`p.y`) is measured as the inner output it names.
    let measures = mesoflow_graph::subgraph::through_all(&base_file, measures);
    let versus = mesoflow_graph::subgraph::through_all(&base_file, versus);
    // Every combination is checked before any runs, so a bad value fails fast with exit code 2.
    let sweep = Sweep::prepare(
        &args.graph.path.display().to_string(),
        &base_file,
        varies,
        measures,
        versus,
        args.max_runs,
        engine.registry(),
    )
    .map_err(|r| invalid(r.to_string()))?;
    let out_dir = args.out_dir.clone().unwrap_or_else(|| {
        PathBuf::from("out")
            .join(graph_name(&args.graph.path))
            .join("sweep")
    });
    let cancel = cancel_flag();
    let slurm = args.cluster.engine == EngineArg::Slurm;
    let options = |run_dir: &Path| {
        let mut opts = RunOptions::new(
            &args.graph.path.display().to_string(),
            graph_dir(&args.graph.path),
            run_dir.to_path_buf(),
            RunPolicy {
                cancel: cancel.clone(),
                ..policy(args.device, &args.cache)
            },
        );
        if slurm {
            // Every value came from the cluster, through the cache: this pass computes nothing.
            opts.compute_only = Some(Default::default());
        }
        opts
    };
    if slurm {
        let Some(run_dir) = slurm_run_dir(&args.cluster, &args.cache, &out_dir)? else {
            return Ok(0);
        };
        let mut opts = RunOptions::new(
            &args.graph.path.display().to_string(),
            graph_dir(&args.graph.path),
            out_dir.clone(),
            RunPolicy {
                device: device_mode(args.device),
                cancel: cancel.clone(),
                ..RunPolicy::default()
            },
        );
        opts.outputs = sweep.outputs.clone();
        let variants: Vec<(String, mesoflow_graph::CheckedGraph)> = sweep
            .texts
            .iter()
            .cloned()
            .zip(sweep.graphs.iter().cloned())
            .collect();
        let outcome = crate::cluster::driver::drive(
            &engine,
            &variants,
            &opts,
            &cache_dir(&args.cache, &args.graph.path),
            &run_dir,
            &args.cluster,
            device_name(args.device),
            args.quiet,
        )?;
        if outcome.interrupted {
            return Ok(crate::exit::CANCELLED);
        }
    }
    let rows = sweep.run(&engine, &out_dir, options, |i, row, report| {
        if args.quiet {
            return;
        }
        println!("{}", sweep.progress_line(i, row));
        if !report.ok {
            print!("{}", summary(report));
        }
    })?;
    let chart_errors = sweep.write(&out_dir, &rows)?;
    if let Some(e) = chart_errors.first() {
        eprintln!("warning: charts not written: {e}");
    }
    if !args.quiet {
        println!(
            "{}: {} runs; cache {}",
            out_dir.join("sweep.csv").display(),
            rows.len(),
            cache_dir(&args.cache, &args.graph.path).display()
        );
    }
    let code = if cancel.load(std::sync::atomic::Ordering::Relaxed) {
        crate::exit::CANCELLED
    } else if rows.iter().all(|r| r.ok) {
        0
    } else {
        crate::exit::FAILED
    };
    Ok(code)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_split_outside_brackets() {
        assert_eq!(split_values("1,2.5, weave"), vec!["1", "2.5", "weave"]);
        assert_eq!(split_values("[1,2],[3,4]"), vec!["[1,2]", "[3,4]"]);
        assert_eq!(split_values("\"a,b\",c"), vec!["\"a,b\"", "c"]);
    }

    #[test]
    fn grid_is_the_cartesian_product() {
        let v = |n: &str, xs: &[i64]| Vary {
            node: n.into(),
            param: "p".into(),
            values: xs.iter().map(|x| Value::from(*x)).collect(),
        };
        let c = crate::sweep::cartesian(&[v("a", &[1, 2]), v("b", &[3, 4, 5])]);
        assert_eq!(c.len(), 6);
        assert_eq!(c[1], vec![Value::from(1), Value::from(4)]);
    }
}
