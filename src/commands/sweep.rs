//! `mesoflow sweep`: runs a graph once per combination of parameter values, on one engine so that
//! nodes upstream of the varied parameters compute once; writes `sweep.csv` and charts of every
//! measure against every varied parameter and against the measured node's time.

use super::run::{
    cache_dir, device_mode, engine, graph_dir, graph_name, parse_outputs, require_gpu, write_report,
};
use crate::args::SweepArgs;
use crate::chart::{self, Chart, Series};
use crate::exit::invalid;
use crate::load;
use crate::progress::summary;
use mesoflow_graph::{edit::parse_value, PortRef};
use mesoflow_runtime::{RunOptions, SilentObserver};
use serde_json::Value;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;

struct Vary {
    node: String,
    param: String,
    values: Vec<Value>,
}

impl Vary {
    fn name(&self) -> String {
        format!("{}.{}", self.node, self.param)
    }
}

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

fn cell(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// One row of the sweep: the values chosen and what was measured.
struct Row {
    values: Vec<Value>,
    measures: Vec<Option<f64>>,
    node_seconds: Vec<Option<f64>>,
    run_seconds: f64,
    ok: bool,
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
    // Each measured node once, in the order of first mention.
    let mut measured_nodes: Vec<String> = Vec::new();
    for m in &measures {
        if !measured_nodes.contains(&m.node) {
            measured_nodes.push(m.node.clone());
        }
    }
    let engine = engine(&args.cache, &args.graph)?;
    let mut base_file = load::read(&args.graph)?;
    load::apply_sets(&mut base_file, &args.set)?;
    // Check every combination before running any, so a bad value fails fast with exit code 2.
    let combos = cartesian(&varies);
    let mut graphs = Vec::new();
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
    }
    // The first output of a node: how a node is asked for when what is measured is not an output.
    let first_output = |kind: &str| {
        engine
            .registry()
            .node(kind)
            .and_then(|n| n.signature().outputs.first().map(|o| o.name.clone()))
    };
    // Ask for the measured outputs as well as the sinks, so a measure is reported even when a
    // sink's cached result would otherwise make its node unnecessary. A timing is not an output:
    // its node is asked for through its first output.
    let mut outputs: Vec<PortRef> = Vec::new();
    for m in &measures {
        let Some(node) = graphs[0].index(&m.node).map(|i| &graphs[0].nodes[i]) else {
            return Err(invalid(format!(
                "--measure {m}: no node `{}` in the graph",
                m.node
            )));
        };
        let sig = engine.registry().node(&node.kind).map(|n| n.signature());
        let ty = sig.and_then(|s| s.output(&m.port).map(|o| o.ty.clone()));
        // A timing (the node's `seconds`, or one the kind declares) is read from the report.
        let timing =
            m.port == "seconds" || sig.is_some_and(|s| s.timings.iter().any(|t| t.name == m.port));
        match ty.as_deref() {
            Some("Scalar") => outputs.push(m.clone()),
            _ if timing => outputs.extend(first_output(&node.kind).map(|port| PortRef {
                node: m.node.clone(),
                port,
            })),
            Some(other) => {
                return Err(invalid(format!(
                    "--measure {m}: `{}` is a {other}; a measure must be a scalar output",
                    m.port
                )))
            }
            None => {
                let names: Vec<&str> = sig
                    .into_iter()
                    .flat_map(|s| {
                        s.outputs
                            .iter()
                            .filter(|o| o.ty == "Scalar")
                            .chain(&s.timings)
                            .map(|o| o.name.as_str())
                    })
                    .chain(["seconds"])
                    .collect();
                let hint = mesoflow_graph::did_you_mean(&m.port, names.iter().copied());
                return Err(invalid(format!(
                    "--measure {m}: `{}` ({}) has no scalar output or timing `{}`{hint}; it has {}",
                    m.node,
                    node.kind,
                    m.port,
                    names.join(", ")
                )));
            }
        }
    }
    for sink in graphs[0].sinks() {
        let kind = &graphs[0].nodes[graphs[0].index(sink).unwrap_or(0)].kind;
        if let Some(port) = first_output(kind) {
            outputs.push(PortRef {
                node: sink.to_string(),
                port,
            });
        }
    }
    let out_dir = args
        .out_dir
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(format!("{}-sweep", graph_name(&args.graph))));
    let cancel = super::run::cancel_flag();
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
        let report = engine
            .run(graph, &opts, Arc::new(SilentObserver))
            .map_err(|e| invalid(e.to_string()))?;
        write_report(&report, &run_dir)?;
        let label: Vec<String> = varies
            .iter()
            .zip(combo)
            .map(|(v, x)| format!("{}={}", v.name(), cell(x)))
            .collect();
        let measured: Vec<Option<f64>> = measures
            .iter()
            .map(|m| {
                report.node(&m.node).and_then(|n| {
                    n.metrics
                        .get(&m.port)
                        .or_else(|| n.timings.get(&m.port))
                        .copied()
                })
            })
            .collect();
        if !args.quiet {
            let shown: Vec<String> = measures
                .iter()
                .zip(&measured)
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
        rows.push(Row {
            values: combo.clone(),
            measures: measured,
            // The compute time of the value (for a cache hit, as measured when it was computed).
            node_seconds: measured_nodes
                .iter()
                .map(|n| {
                    report
                        .node(n)
                        .and_then(|r| r.timings.get("seconds").copied())
                })
                .collect(),
            run_seconds: report.seconds,
            ok: report.ok,
        });
        if report.cancelled {
            break;
        }
    }
    std::fs::create_dir_all(&out_dir)?;
    write_csv(
        &out_dir.join("sweep.csv"),
        &varies,
        &measures,
        &measured_nodes,
        &rows,
    )?;
    let mut chart_errors = Vec::new();
    for (mi, m) in measures.iter().enumerate() {
        let measure_name = m.to_string();
        let is_time = m.port == "seconds";
        for (vi, v) in varies.iter().enumerate() {
            let c = chart_against(&varies, vi, &rows, mi, &measure_name);
            if let Err(e) = chart::write(
                &out_dir.join(format!("{}.{}_vs_{}", m.node, m.port, v.name())),
                &c,
            ) {
                chart_errors.push(e);
            }
        }
        let ni = measured_nodes
            .iter()
            .position(|n| *n == m.node)
            .unwrap_or(0);
        // One series per combination of the non-numeric varied values (e.g. each solver), so
        // methods can be told apart on the cost–error plane.
        let mut groups: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
        for r in &rows {
            let (Some(t), Some(y)) = (r.node_seconds[ni], r.measures[mi]) else {
                continue;
            };
            let name: Vec<String> = varies
                .iter()
                .zip(&r.values)
                .filter(|(_, x)| !x.is_number())
                .map(|(v, x)| format!("{}={}", v.name(), cell(x)))
                .collect();
            groups.entry(name.join(" ")).or_default().push((t, y));
        }
        let c = Chart {
            title: format!("{}.{} against the time of `{}`", m.node, m.port, m.node),
            x_label: "seconds",
            y_label: &m.port,
            series: groups
                .into_iter()
                // In sweep order (e.g. increasing rank), so a line traces one method's trade-off.
                .map(|(name, points)| Series {
                    name,
                    points,
                    scatter: false,
                })
                .collect(),
            x_names: None,
        };
        if is_time {
            continue; // its own time against itself says nothing
        }
        if let Err(e) = chart::write(
            &out_dir.join(format!("{}.{}_vs_seconds", m.node, m.port)),
            &c,
        ) {
            chart_errors.push(e);
        }
    }
    for x in &versus {
        let xi = measures.iter().position(|m| m == x).unwrap_or(0);
        for (mi, m) in measures.iter().enumerate().filter(|(_, m)| *m != x) {
            let c = chart_versus(&varies, &rows, (xi, x), (mi, m));
            if let Err(e) = chart::write(
                &out_dir.join(format!("{}.{}_vs_{}.{}", m.node, m.port, x.node, x.port)),
                &c,
            ) {
                chart_errors.push(e);
            }
        }
    }
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

fn cartesian(varies: &[Vary]) -> Vec<Vec<Value>> {
    let mut combos = vec![Vec::new()];
    for v in varies {
        combos = combos
            .into_iter()
            .flat_map(|c| {
                v.values
                    .iter()
                    .map(move |x| [c.clone(), vec![x.clone()]].concat())
            })
            .collect();
    }
    combos
}

fn write_csv(
    path: &std::path::Path,
    varies: &[Vary],
    measures: &[PortRef],
    nodes: &[String],
    rows: &[Row],
) -> anyhow::Result<()> {
    let mut out = String::new();
    let mut header: Vec<String> = varies.iter().map(Vary::name).collect();
    header.extend(measures.iter().map(|m| m.to_string()));
    // One column per measure: a node's seconds column only where it was not measured already.
    let extra: Vec<bool> = nodes
        .iter()
        .map(|n| !measures.iter().any(|m| m.node == *n && m.port == "seconds"))
        .collect();
    header.extend(
        nodes
            .iter()
            .zip(&extra)
            .filter(|(_, e)| **e)
            .map(|(n, _)| format!("{n}.seconds")),
    );
    header.extend(["run_seconds".to_string(), "ok".to_string()]);
    writeln!(
        out,
        "{}",
        header
            .iter()
            .map(|h| csv_field(h))
            .collect::<Vec<_>>()
            .join(",")
    )?;
    let num = |x: &Option<f64>| x.map(|v| format!("{v}")).unwrap_or_default();
    for r in rows {
        let mut cells: Vec<String> = r.values.iter().map(|v| csv_field(&cell(v))).collect();
        cells.extend(r.measures.iter().map(num));
        cells.extend(
            r.node_seconds
                .iter()
                .zip(&extra)
                .filter(|(_, e)| **e)
                .map(|(s, _)| num(s)),
        );
        cells.push(format!("{}", r.run_seconds));
        cells.push(r.ok.to_string());
        writeln!(out, "{}", cells.join(","))?;
    }
    std::fs::write(path, out)?;
    Ok(())
}

/// Measure `mi` against varied parameter `vi`; one series per combination of the other parameters.
fn chart_against<'a>(
    varies: &'a [Vary],
    vi: usize,
    rows: &[Row],
    mi: usize,
    measure: &'a str,
) -> Chart<'a> {
    let numeric = varies[vi].values.iter().all(Value::is_number);
    let position = |v: &Value| -> f64 {
        if numeric {
            v.as_f64().unwrap_or(f64::NAN)
        } else {
            varies[vi].values.iter().position(|x| x == v).unwrap_or(0) as f64
        }
    };
    let mut groups: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
    for r in rows {
        let Some(y) = r.measures[mi] else { continue };
        let others: Vec<String> = varies
            .iter()
            .zip(&r.values)
            .enumerate()
            .filter(|(j, _)| *j != vi)
            .map(|(_, (v, x))| format!("{}={}", v.name(), cell(x)))
            .collect();
        groups
            .entry(others.join(" "))
            .or_default()
            .push((position(&r.values[vi]), y));
    }
    Chart {
        title: format!("{measure} against {}", varies[vi].name()),
        x_label: &varies[vi].param,
        y_label: measure,
        series: groups
            .into_iter()
            .map(|(name, points)| Series {
                name,
                points,
                scatter: false,
            })
            .collect(),
        x_names: (!numeric).then(|| varies[vi].values.iter().map(cell).collect()),
    }
}

/// Measure `m` against measure `x`: each series traces the first varied parameter (e.g. the
/// rank) with the other varied values fixed (one series per combination), so a line is one
/// configuration's cost–error trade-off.
fn chart_versus<'a>(
    varies: &[Vary],
    rows: &[Row],
    (xi, x): (usize, &'a PortRef),
    (mi, m): (usize, &'a PortRef),
) -> Chart<'a> {
    let mut groups: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
    for r in rows {
        let (Some(a), Some(b)) = (r.measures[xi], r.measures[mi]) else {
            continue;
        };
        let name: Vec<String> = varies
            .iter()
            .zip(&r.values)
            .skip(1)
            .map(|(v, val)| format!("{}={}", v.name(), cell(val)))
            .collect();
        groups.entry(name.join(" ")).or_default().push((a, b));
    }
    Chart {
        title: format!(
            "{m} against {x}, along {}",
            varies.first().map_or(String::new(), |v| v.name())
        ),
        x_label: &x.port,
        y_label: &m.port,
        series: groups
            .into_iter()
            .map(|(name, mut points)| {
                points.sort_by(|p, q| p.0.total_cmp(&q.0));
                Series {
                    name,
                    points,
                    scatter: false,
                }
            })
            .collect(),
        x_names: None,
    }
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
