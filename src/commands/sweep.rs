//! `mesoflow sweep`: runs a graph once per combination of parameter values, on one engine so that
//! nodes upstream of the varied parameters compute once; writes `sweep.csv` and charts of every
//! measure against every varied parameter and against the measured node's time.

use super::run::{
    cache_dir, device_mode, engine, graph_dir, graph_name, parse_outputs, require_gpu, write_report,
};
use crate::args::{EngineArg, SweepArgs};
use crate::exit::invalid;
use crate::load;
use crate::progress::summary;
use crate::sweep_table::{cartesian, cell, write_all, Vary};
use mesoflow_graph::edit::parse_value;
use mesoflow_runtime::{RunOptions, SilentObserver};
use serde_json::Value;
use std::path::PathBuf;
use std::sync::Arc;

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
    if let Some(x) = versus.iter().find(|x| !measures.contains(x)) {
        return Err(invalid(format!(
            "--versus {x}: measure it too (--measure {x})"
        )));
    }
    let measured_nodes = crate::sweep_table::measured_nodes(&measures);
    let engine = engine(&args.cache, &args.graph)?;
    let mut base_file = load::read(&args.graph)?;
    load::apply_sets(&mut base_file, &args.set)?;
    // Check every combination before running any, so a bad value fails fast with exit code 2.
    crate::sweep_table::grid_size(&varies, args.max_runs).map_err(invalid)?;
    let combos = cartesian(&varies);
    let mut graphs = Vec::new();
    let mut texts = Vec::new();
    for combo in &combos {
        let mut file = base_file.clone();
        for (v, value) in varies.iter().zip(combo) {
            file.apply(&mesoflow_graph::Override {
                node: v.node.clone(),
                param: v.param.clone(),
                value: value.clone(),
            })
            .map_err(invalid)?;
        }
        graphs.push(load::checked(&args.graph, &file, engine.registry())?);
        texts.push(file.to_json());
    }
    let outputs = crate::sweep_table::sweep_outputs(engine.registry(), &graphs[0], &measures)
        .map_err(invalid)?;
    let out_dir = args
        .out_dir
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(format!("{}-sweep", graph_name(&args.graph))));
    let cancel = super::run::cancel_flag();
    let slurm = args.cluster.engine == EngineArg::Slurm;
    if slurm {
        let Some(run_dir) = super::run::slurm_run_dir(&args.cluster, &args.cache, &out_dir)? else {
            return Ok(0);
        };
        let mut opts = RunOptions::new(
            &args.graph.display().to_string(),
            graph_dir(&args.graph),
            out_dir.clone(),
        );
        opts.outputs = outputs.clone();
        opts.device = device_mode(args.device);
        opts.cancel = cancel.clone();
        let variants: Vec<(String, mesoflow_graph::CheckedGraph)> =
            texts.into_iter().zip(graphs.iter().cloned()).collect();
        let outcome = crate::cluster::driver::drive(
            &engine,
            &variants,
            &opts,
            &cache_dir(&args.cache, &args.graph),
            &run_dir,
            &args.cluster,
            super::run::device_name(args.device),
            args.quiet,
        )?;
        if outcome.interrupted {
            return Ok(crate::exit::CANCELLED);
        }
    }
    let mut rows = Vec::new();
    for (i, (combo, graph)) in combos.iter().zip(&graphs).enumerate() {
        let run_dir = out_dir.join("runs").join(format!("{i:03}"));
        let mut opts = RunOptions::new(
            &args.graph.display().to_string(),
            graph_dir(&args.graph),
            run_dir.clone(),
        );
        opts.outputs = outputs.clone();
        opts.device = device_mode(args.device);
        opts.require_gpu = require_gpu();
        opts.use_cache = !args.cache.no_cache;
        opts.verify_cache = args.cache.verify_cache;
        opts.cancel = cancel.clone();
        if slurm {
            // Every value came from the cluster, through the cache: this pass computes nothing.
            opts.compute_only = Some(Default::default());
        }
        let report = engine
            .run(graph, &opts, Arc::new(SilentObserver))
            .map_err(|e| invalid(e.to_string()))?;
        write_report(&report, &run_dir)?;
        let label: Vec<String> = varies
            .iter()
            .zip(combo)
            .map(|(v, x)| format!("{}={}", v.name(), cell(x)))
            .collect();
        let row = crate::sweep_table::row_of(&report, combo.clone(), &measures, &measured_nodes);
        let measured = &row.measures;
        if !args.quiet {
            let shown: Vec<String> = measures
                .iter()
                .zip(measured)
                .map(|(m, v)| match v {
                    Some(v) => format!("{m}={v:.4e}"),
                    None => format!("{m}=—"),
                })
                .collect();
            println!(
                "[{}/{}] {}: {} in {:.2} s{}{}",
                i + 1,
                combos.len(),
                label.join(" "),
                if report.ok { "ok" } else { "FAILED" },
                report.seconds,
                if shown.is_empty() { "" } else { "; " },
                shown.join(" ")
            );
        }
        if !report.ok && !args.quiet {
            print!("{}", summary(&report));
        }
        rows.push(row);
        if report.cancelled {
            break;
        }
    }
    let chart_errors = write_all(
        &out_dir,
        &varies,
        &measures,
        &measured_nodes,
        &versus,
        &rows,
    )?;
    if let Some(e) = chart_errors.first() {
        eprintln!("warning: charts not written: {e}");
    }
    if !args.quiet {
        println!(
            "{}: {} runs; cache {}",
            out_dir.join("sweep.csv").display(),
            rows.len(),
            cache_dir(&args.cache, &args.graph).display()
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
        let c = cartesian(&[v("a", &[1, 2]), v("b", &[3, 4, 5])]);
        assert_eq!(c.len(), 6);
        assert_eq!(c[1], vec![Value::from(1), Value::from(4)]);
    }
}
