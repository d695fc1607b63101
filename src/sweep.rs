//! One sweep for every front end: [`Sweep::prepare`] (the grid of combinations, each one's graph
//! checked before any runs, the outputs the runs ask for), [`Sweep::run`] (each combination on
//! one engine, so nodes upstream of the varied parameters compute once, a row a run handed to
//! the caller as it is measured) and [`Sweep::write`] (`sweep.csv`, and the charts of every
//! measure against every varied parameter, against the measured node's time and against
//! `versus` measures). `mesoflow sweep`, the studio and the Python package's `mesoflow.sweep`
//! prepare, run and write through it, so the three refuse the same sweeps and leave the same
//! files.

use crate::chart::{self, Chart, Series};
use anyhow::Context;
use mesoflow_graph::{CheckedGraph, GraphErrors, GraphFile, Override, PortRef};
use mesoflow_runtime::{Engine, Registry, RunOptions, RunReport, SilentObserver};
use serde_json::Value;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use std::sync::atomic::Ordering;
use std::sync::Arc;

/// Why a sweep cannot start: a mistake in what it asks (a vary, a measure, the grid's size),
/// or a combination whose graph does not check (with every problem of it).
#[derive(Debug)]
pub enum Refusal {
    Asked(String),
    /// A measure that is not a scalar output or timing of its node (or names no node).
    Measure(PortRef, String),
    Graph(GraphErrors),
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Refusal::Asked(m) | Refusal::Measure(_, m) => f.write_str(m),
            Refusal::Graph(e) => f.write_str(e.to_string().trim_end()),
        }
    }
}

/// A sweep ready to run: every combination's graph checked, and what its runs ask for.
pub struct Sweep {
    pub varies: Vec<Vary>,
    pub measures: Vec<PortRef>,
    pub versus: Vec<PortRef>,
    /// The nodes the measures read, each once, in order.
    pub measured_nodes: Vec<String>,
    /// The values of each combination, in `varies`' order.
    pub combos: Vec<Vec<Value>>,
    /// Each combination's graph, checked.
    pub graphs: Vec<CheckedGraph>,
    /// Each combination's graph file (what a cluster's jobs run).
    pub texts: Vec<String>,
    /// The outputs every run asks for ([`sweep_outputs`]).
    pub outputs: Vec<PortRef>,
}

impl Sweep {
    /// The sweep of `base` (the graph file named `name`, its `--set`s applied) over `varies`,
    /// measuring `measures`: refused before anything runs when a `versus` is not measured, the
    /// grid is over `max_runs`, a combination's graph does not check or a measure is not a
    /// scalar output or timing.
    pub fn prepare(
        name: &str,
        base: &GraphFile,
        varies: Vec<Vary>,
        measures: Vec<PortRef>,
        versus: Vec<PortRef>,
        max_runs: usize,
        registry: &Registry,
    ) -> Result<Sweep, Refusal> {
        if varies.is_empty() || measures.is_empty() {
            return Err(Refusal::Asked(
                "a sweep needs at least one varied parameter and one measure".into(),
            ));
        }
        if let Some(v) = varies.iter().find(|v| v.values.is_empty()) {
            return Err(Refusal::Asked(format!("vary {}: no values", v.name())));
        }
        if let Some(x) = versus.iter().find(|x| !measures.contains(x)) {
            return Err(Refusal::Asked(format!(
                "versus {x}: measure it too (add it to the measures)"
            )));
        }
        grid_size(&varies, max_runs).map_err(Refusal::Asked)?;
        let combos = cartesian(&varies);
        let mut graphs = Vec::with_capacity(combos.len());
        let mut texts = Vec::with_capacity(combos.len());
        for combo in &combos {
            let mut file = base.clone();
            for (v, value) in varies.iter().zip(combo) {
                file.apply(&Override {
                    node: v.node.clone(),
                    param: v.param.clone(),
                    value: value.clone(),
                })
                .map_err(Refusal::Asked)?;
            }
            graphs.push(mesoflow_graph::check(name, &file, registry).map_err(Refusal::Graph)?);
            texts.push(file.to_json());
        }
        let outputs = sweep_outputs(registry, &graphs[0], &measures)
            .map_err(|(m, message)| Refusal::Measure(m, message))?;
        Ok(Sweep {
            measured_nodes: measured_nodes(&measures),
            varies,
            measures,
            versus,
            combos,
            graphs,
            texts,
            outputs,
        })
    }

    /// Runs every combination in order on `engine`, each into `out_dir/runs/NNN` with its
    /// report written there, under the options `options` gives for that folder (the caller's
    /// policy: device, cache, cancel flag; the outputs are set here); hands each row to
    /// `on_row` (its index, the row, the report) as it is measured. Stops before the next run
    /// once the cancel flag is set, and after a cancelled run.
    pub fn run(
        &self,
        engine: &Engine,
        out_dir: &Path,
        options: impl Fn(&Path) -> RunOptions,
        mut on_row: impl FnMut(usize, &Row, &RunReport),
    ) -> anyhow::Result<Vec<Row>> {
        let mut rows = Vec::new();
        for (i, (combo, graph)) in self.combos.iter().zip(&self.graphs).enumerate() {
            let run_dir = out_dir.join("runs").join(format!("{i:03}"));
            let mut opts = options(&run_dir);
            if opts.policy.cancel.load(Ordering::SeqCst) {
                break;
            }
            opts.outputs = self.outputs.clone();
            let report = engine
                .run(graph, &opts, Arc::new(SilentObserver))
                .map_err(|e| crate::exit::invalid(e.to_string()))?;
            report
                .write_into(&run_dir)
                .with_context(|| format!("writing {}", run_dir.join("report.json").display()))?;
            let row = row_of(&report, combo.clone(), &self.measures, &self.measured_nodes);
            on_row(i, &row, &report);
            rows.push(row);
            if report.cancelled {
                break;
            }
        }
        Ok(rows)
    }

    /// `sweep.csv` and the charts of `rows` under `out_dir`; the charts that could not be
    /// drawn (a missing font), for the caller to warn of.
    pub fn write(&self, out_dir: &Path, rows: &[Row]) -> std::io::Result<Vec<String>> {
        write_all(
            out_dir,
            &self.varies,
            &self.measures,
            &self.measured_nodes,
            &self.versus,
            rows,
        )
    }

    /// The line a front end prints as row `i` comes in: `[i/n] label: ok in s; measures`.
    pub fn progress_line(&self, i: usize, row: &Row) -> String {
        let shown: Vec<String> = self
            .measures
            .iter()
            .zip(&row.measures)
            .map(|(m, v)| match v {
                Some(v) => format!("{m}={v:.4e}"),
                None => format!("{m}=—"),
            })
            .collect();
        format!(
            "[{}/{}] {}: {} in {:.2} s{}{}",
            i + 1,
            self.combos.len(),
            self.label(i),
            if row.ok { "ok" } else { "FAILED" },
            row.run_seconds,
            if shown.is_empty() { "" } else { "; " },
            shown.join(" ")
        )
    }

    /// `node.param=value` for each varied parameter of combination `i`.
    pub fn label(&self, i: usize) -> String {
        self.varies
            .iter()
            .zip(&self.combos[i])
            .map(|(v, x)| format!("{}={}", v.name(), cell(x)))
            .collect::<Vec<_>>()
            .join(" ")
    }
}

/// One varied parameter and its values, in sweep order.
#[derive(Clone, Debug)]
pub struct Vary {
    pub node: String,
    pub param: String,
    pub values: Vec<Value>,
}

impl Vary {
    pub fn name(&self) -> String {
        format!("{}.{}", self.node, self.param)
    }
}

pub fn cell(v: &Value) -> String {
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
pub struct Row {
    pub values: Vec<Value>,
    pub measures: Vec<Option<f64>>,
    /// Per measured node: the compute time of its value (for a cache hit, as first measured).
    pub node_seconds: Vec<Option<f64>>,
    pub run_seconds: f64,
    pub ok: bool,
}

/// Writes `sweep.csv` and every chart under `out_dir`; returns the charts that could not be
/// written (a missing font), which the caller reports as a warning.
pub fn write_all(
    out_dir: &Path,
    varies: &[Vary],
    measures: &[PortRef],
    measured_nodes: &[String],
    versus: &[PortRef],
    rows: &[Row],
) -> std::io::Result<Vec<String>> {
    std::fs::create_dir_all(out_dir)?;
    write_csv(
        &out_dir.join("sweep.csv"),
        varies,
        measures,
        measured_nodes,
        rows,
    )?;
    let mut chart_errors = Vec::new();
    for (mi, m) in measures.iter().enumerate() {
        let measure_name = m.to_string();
        let is_time = m.port == "seconds";
        // One chart per measure: against the varied parameter that reads best along an axis,
        // a series per value of the others (the same points against another parameter would
        // only regroup them).
        if let Some(vi) = x_axis(varies) {
            let c = chart_against(varies, vi, rows, mi, &measure_name);
            if let Err(e) = chart::write(
                &out_dir.join(format!("{}.{}_vs_{}", m.node, m.port, varies[vi].name())),
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
        let mut groups: Groups = BTreeMap::new();
        for r in rows {
            let (Some(t), Some(y)) = (r.node_seconds[ni], r.measures[mi]) else {
                continue;
            };
            let others: Vec<usize> = (0..varies.len())
                .filter(|&j| !r.values[j].is_number())
                .collect();
            let (key, name) = legend_key(varies, &r.values, &others);
            groups
                .entry(key)
                .or_insert_with(|| (name, Vec::new()))
                .1
                .push((t, y));
        }
        let c = Chart {
            title: format!("{}.{} against the time of `{}`", m.node, m.port, m.node),
            x_label: "seconds",
            y_label: &m.port,
            // In sweep order (e.g. increasing rank), so a line traces one method's trade-off.
            series: series_of(groups, false),
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
    for x in versus {
        let xi = measures.iter().position(|m| m == x).unwrap_or(0);
        for (mi, m) in measures.iter().enumerate().filter(|(_, m)| *m != x) {
            let c = chart_versus(varies, rows, (xi, x), (mi, m));
            if let Err(e) = chart::write(
                &out_dir.join(format!("{}.{}_vs_{}.{}", m.node, m.port, x.node, x.port)),
                &c,
            ) {
                chart_errors.push(e);
            }
        }
    }
    Ok(chart_errors)
}

/// The most runs a sweep makes unless told otherwise (`--max-runs`): three varies of 1 000
/// values once asked for 10⁹ graphs and ran out of memory making them (issue 43).
pub const MAX_RUNS: usize = 10_000;

/// The number of runs `varies` make, refused beyond `limit` before anything is allocated.
pub fn grid_size(varies: &[Vary], limit: usize) -> Result<usize, String> {
    let sizes: Vec<String> = varies.iter().map(|v| v.values.len().to_string()).collect();
    let runs = varies
        .iter()
        .try_fold(1usize, |n, v| n.checked_mul(v.values.len()));
    match runs {
        Some(n) if n <= limit => Ok(n),
        _ => Err(format!(
            "the varies make {} runs ({}), more than the limit of {limit}: vary fewer values, or raise the limit (--max-runs)",
            runs.map_or("more than 2^64".to_string(), |n| n.to_string()),
            sizes.join(" × ")
        )),
    }
}

pub fn cartesian(varies: &[Vary]) -> Vec<Vec<Value>> {
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
) -> std::io::Result<()> {
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
    )
    .map_err(std::io::Error::other)?;
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
        writeln!(out, "{}", cells.join(",")).map_err(std::io::Error::other)?;
    }
    mesoflow_runtime::write_atomic(path, out)?;
    Ok(())
}

/// The varied parameter a measure is charted against: the numeric one with the most values,
/// else the one with the most values (the first of equals); none when nothing varies.
fn x_axis(varies: &[Vary]) -> Option<usize> {
    let numeric = |v: &Vary| v.values.iter().all(Value::is_number);
    (0..varies.len()).max_by_key(|&i| {
        let v = &varies[i];
        // max_by_key keeps the last of equals: rank earlier parameters higher on ties.
        (numeric(v), v.values.len(), std::cmp::Reverse(i))
    })
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
    let mut groups: Groups = BTreeMap::new();
    for r in rows {
        let Some(y) = r.measures[mi] else { continue };
        let others: Vec<usize> = (0..varies.len()).filter(|j| *j != vi).collect();
        let (key, name) = legend_key(varies, &r.values, &others);
        groups
            .entry(key)
            .or_insert_with(|| (name, Vec::new()))
            .1
            .push((position(&r.values[vi]), y));
    }
    Chart {
        title: format!("{measure} against {}", varies[vi].name()),
        x_label: &varies[vi].param,
        y_label: measure,
        // Against the parameter itself, joined along it.
        series: series_of(groups, true),
        x_names: (!numeric).then(|| varies[vi].values.iter().map(cell).collect()),
    }
}

/// Measure `m` against measure `x`: each series traces the first varied parameter (e.g. the
/// rank) with the other varied values fixed (one series per combination), so a line is one
/// configuration's cost–error trade-off, joined in the parameter's order.
fn chart_versus<'a>(
    varies: &[Vary],
    rows: &[Row],
    (xi, x): (usize, &'a PortRef),
    (mi, m): (usize, &'a PortRef),
) -> Chart<'a> {
    let mut groups: Groups = BTreeMap::new();
    for r in rows {
        let (Some(a), Some(b)) = (r.measures[xi], r.measures[mi]) else {
            continue;
        };
        let others: Vec<usize> = (1..varies.len()).collect();
        let (key, name) = legend_key(varies, &r.values, &others);
        groups
            .entry(key)
            .or_insert_with(|| (name, Vec::new()))
            .1
            .push((a, b));
    }
    Chart {
        title: format!(
            "{m} against {x}, along {}",
            varies.first().map_or(String::new(), |v| v.name())
        ),
        x_label: &x.port,
        y_label: &m.port,
        // In the sweep's order of the first varied parameter: the trade-off along it.
        series: series_of(groups, false),
        x_names: None,
    }
}

/// A chart's series, keyed by the other varied values' ranks (so the legend reads in value
/// order: rank 1, 2, 4, 16, not 1, 16, 2, 4), each with its name and points.
type Groups = BTreeMap<Vec<usize>, (String, Vec<(f64, f64)>)>;

/// The legend's order and name of a run among the varied parameters `others`: each value's rank
/// among its parameter's values (numbers by value, anything else as listed).
fn legend_key(varies: &[Vary], values: &[Value], others: &[usize]) -> (Vec<usize>, String) {
    let rank = |j: usize| {
        let all = &varies[j].values;
        let v = &values[j];
        if all.iter().all(Value::is_number) {
            let x = v.as_f64().unwrap_or(f64::NAN);
            all.iter()
                .filter(|w| w.as_f64().is_some_and(|w| w < x))
                .count()
        } else {
            all.iter().position(|w| w == v).unwrap_or(0)
        }
    };
    let name: Vec<String> = others
        .iter()
        .map(|&j| format!("{}={}", varies[j].name(), cell(&values[j])))
        .collect();
    (others.iter().map(|&j| rank(j)).collect(), name.join(" "))
}

/// A chart's series from its groups of points: sorted along x with `along_x`, else joined in
/// the order the runs gave them.
fn series_of(groups: Groups, along_x: bool) -> Vec<Series> {
    groups
        .into_values()
        .map(|(name, mut points)| {
            if along_x {
                points.sort_by(|p, q| p.0.total_cmp(&q.0));
            }
            Series {
                name,
                points,
                scatter: false,
            }
        })
        .collect()
}

/// Each measured node once, in the order of first mention.
pub fn measured_nodes(measures: &[PortRef]) -> Vec<String> {
    let mut nodes: Vec<String> = Vec::new();
    for m in measures {
        if !nodes.contains(&m.node) {
            nodes.push(m.node.clone());
        }
    }
    nodes
}

/// The outputs a sweep's runs ask for: the measured scalars, the first output of a node whose
/// timing is measured (a timing is read from the report, not an output), and the graph's sinks,
/// so a measure is reported even when a sink's cached result would make its node unnecessary.
/// An error names the `--measure` that cannot be measured.
pub fn sweep_outputs(
    registry: &Registry,
    graph: &CheckedGraph,
    measures: &[PortRef],
) -> Result<Vec<PortRef>, (PortRef, String)> {
    let first_output = |kind: &str| {
        registry
            .node(kind)
            .and_then(|n| n.signature().outputs.first().map(|o| o.name.clone()))
    };
    let mut outputs: Vec<PortRef> = Vec::new();
    for m in measures {
        let Some(node) = graph.index(&m.node).map(|i| &graph.nodes[i]) else {
            return Err((
                m.clone(),
                format!("--measure {m}: no node `{}` in the graph", m.node),
            ));
        };
        let sig = registry.node(&node.kind).map(|n| n.signature());
        let ty = sig.and_then(|s| s.output(&m.port).map(|o| o.ty.clone()));
        let timing =
            m.port == "seconds" || sig.is_some_and(|s| s.timings.iter().any(|t| t.name == m.port));
        match ty.as_deref() {
            Some("Scalar") => outputs.push(m.clone()),
            _ if timing => outputs.extend(first_output(&node.kind).map(|port| PortRef {
                node: m.node.clone(),
                port,
            })),
            Some(other) => {
                return Err((
                    m.clone(),
                    format!(
                        "--measure {m}: `{}` is a {other}; a measure must be a scalar output",
                        m.port
                    ),
                ))
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
                return Err((
                    m.clone(),
                    format!(
                        "--measure {m}: `{}` ({}) has no scalar output or timing `{}`{hint}; it has {}",
                        m.node,
                        node.kind,
                        m.port,
                        names.join(", ")
                    ),
                ));
            }
        }
    }
    for sink in graph.sinks() {
        let Some(i) = graph.index(sink) else { continue };
        if let Some(port) = first_output(&graph.nodes[i].kind) {
            outputs.push(PortRef {
                node: sink.to_string(),
                port,
            });
        }
    }
    Ok(outputs)
}

/// One row from one run's report: each measure (a scalar output or a timing) and each measured
/// node's compute time (for a cache hit, as measured when it was computed).
pub fn row_of(
    report: &RunReport,
    values: Vec<Value>,
    measures: &[PortRef],
    measured_nodes: &[String],
) -> Row {
    Row {
        values,
        measures: measures
            .iter()
            .map(|m| {
                report.node(&m.node).and_then(|n| {
                    n.metrics
                        .get(&m.port)
                        .or_else(|| n.timings.get(&m.port))
                        .copied()
                })
            })
            .collect(),
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
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn legends_read_in_value_order() {
        let varies = vec![
            Vary {
                node: "pca".into(),
                param: "rank".into(),
                values: vec![json!(16), json!(1), json!(4), json!(2)],
            },
            Vary {
                node: "lod".into(),
                param: "level".into(),
                values: vec![json!(0), json!(2)],
            },
        ];
        let mut keys: Vec<(Vec<usize>, String)> = cartesian(&varies)
            .iter()
            .map(|values| legend_key(&varies, values, &[0]))
            .collect();
        keys.sort();
        keys.dedup();
        let names: Vec<&str> = keys.iter().map(|k| k.1.as_str()).collect();
        assert_eq!(
            names,
            ["pca.rank=1", "pca.rank=2", "pca.rank=4", "pca.rank=16"]
        );
    }

    #[test]
    fn a_measure_is_charted_against_the_numeric_parameter_with_most_values() {
        let vary = |param: &str, values: Vec<serde_json::Value>| Vary {
            node: "n".into(),
            param: param.into(),
            values,
        };
        let solver = vary("solver", vec![json!("a"), json!("b"), json!("c")]);
        let level = vary("level", vec![json!(0), json!(2)]);
        let rank = vary(
            "rank",
            vec![json!(1), json!(2), json!(4), json!(8), json!(16)],
        );
        assert_eq!(x_axis(&[]), None);
        assert_eq!(x_axis(std::slice::from_ref(&solver)), Some(0));
        assert_eq!(x_axis(&[solver.clone(), level.clone()]), Some(1));
        assert_eq!(x_axis(&[level.clone(), rank.clone()]), Some(1));
        // Equals: the first.
        assert_eq!(x_axis(&[level.clone(), level]), Some(0));
    }
}
