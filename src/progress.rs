//! Progress bars (indicatif) for the nodes of a run, and the end-of-run summary table.

use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use mesoflow_runtime::{NodeReport, NodeStatus, RunObserver, RunReport};
use std::collections::HashMap;
use std::sync::Mutex;
use std::time::Duration;

pub struct Bars {
    multi: MultiProgress,
    bars: Mutex<HashMap<String, ProgressBar>>,
}

impl Bars {
    pub fn new() -> Self {
        Bars {
            multi: MultiProgress::new(),
            bars: Mutex::new(HashMap::new()),
        }
    }
}

impl RunObserver for Bars {
    fn node_started(&self, id: &str, kind: &str, device: &str) {
        // A spinner with the elapsed time until the node reports progress; then a bar with an
        // ETA (a node that reports nothing never shows an empty `0/0`).
        let bar = self.multi.add(ProgressBar::new_spinner());
        bar.set_style(
            ProgressStyle::with_template("{spinner} {prefix:<28} {elapsed}")
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        );
        bar.set_prefix(format!("{id} ({kind}, {device})"));
        bar.enable_steady_tick(Duration::from_millis(120));
        self.bars
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(id.to_string(), bar);
    }

    fn progress(&self, id: &str, done: u64, total: u64) {
        if let Some(bar) = self.bars.lock().unwrap_or_else(|e| e.into_inner()).get(id) {
            if total == 0 {
                return;
            }
            if bar.length() != Some(total) {
                bar.set_style(
                    ProgressStyle::with_template(
                        "{spinner} {prefix:<28} {wide_bar} {pos}/{len} {elapsed}, eta {eta}",
                    )
                    .unwrap_or_else(|_| ProgressStyle::default_spinner()),
                );
                bar.set_length(total);
            }
            bar.set_position(done);
        }
    }

    fn node_finished(&self, report: &NodeReport) {
        if let Some(bar) = self
            .bars
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .remove(&report.id)
        {
            bar.finish_and_clear();
        }
    }
}

pub fn human_bytes(b: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = b as f64;
    let mut u = 0;
    while v >= 1024.0 && u < UNITS.len() - 1 {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{b} B")
    } else {
        format!("{v:.1} {}", UNITS[u])
    }
}

pub fn status_text(s: NodeStatus) -> &'static str {
    match s {
        NodeStatus::Computed => "computed",
        NodeStatus::Memory => "memory",
        NodeStatus::Disk => "disk",
        NodeStatus::Failed => "FAILED",
        NodeStatus::Cancelled => "cancelled",
    }
}

/// The run's warnings, one line per distinct message: a message several nodes gave (the software
/// adapter's notice, say) names them all once. The report keeps each node's own. Those the graph
/// expects (`expected_warnings`) are counted in one line.
fn warning_lines(report: &RunReport) -> String {
    let mut distinct: Vec<(&str, Vec<&str>)> = Vec::new();
    let expected = report.warnings.iter().filter(|w| w.expected).count();
    for w in report.warnings.iter().filter(|w| !w.expected) {
        match distinct.iter_mut().find(|(m, _)| *m == w.message) {
            Some((_, nodes)) => nodes.push(&w.node),
            None => distinct.push((&w.message, vec![&w.node])),
        }
    }
    distinct
        .into_iter()
        .map(|(message, nodes)| {
            let names: Vec<String> = nodes.iter().map(|n| format!("`{n}`")).collect();
            let which = if names.len() == 1 { "node" } else { "nodes" };
            format!("warning: {which} {}: {message}\n", names.join(", "))
        })
        .chain((expected > 0).then(|| {
            let (s, verb) = if expected == 1 { ("", "is") } else { ("s", "are") };
            format!("{expected} warning{s} the graph expects (its `expected_warnings`) {verb} in report.json\n")
        }))
        .collect()
}

/// The summary table, warnings and errors, as printed after a run.
pub fn summary(report: &RunReport) -> String {
    summary_with(report, false)
}

/// A node's headline: its kind's first scalar output that the node reported (the error of a
/// comparison, the coverage of a render), as `name value`; empty where it has none.
fn headline(registry: &mesoflow_runtime::Registry, n: &mesoflow_runtime::NodeReport) -> String {
    let Some(sig) = registry.node(&n.kind).map(|k| k.signature()) else {
        return String::new();
    };
    sig.outputs
        .iter()
        .filter(|o| o.ty == "Scalar")
        .find_map(|o| {
            n.metrics
                .get(&o.name)
                .map(|v| format!("{} {}", o.name, short(*v)))
        })
        .unwrap_or_default()
}

/// A metric in four significant digits; a whole number as it is.
fn short(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        format!("{}", v as i64)
    } else if v != 0.0 && (v.abs() >= 1e5 || v.abs() < 1e-3) {
        format!("{v:.3e}")
    } else {
        let digits = (3 - v.abs().max(1e-300).log10().floor() as i32).clamp(0, 6) as usize;
        format!("{v:.digits$}")
    }
}

/// The run table; with `explain`, a last column `why` gives each computed node's reason (what
/// changed since the last run into the same output folder). The last column before it is each
/// node's headline metric.
pub fn summary_with(report: &RunReport, explain: bool) -> String {
    let registry = mesoflow_nodes::registry::builtin();
    let header = [
        "node", "kind", "device", "status", "seconds", "bytes", "metric",
    ];
    let rows: Vec<[String; 7]> = report
        .nodes
        .iter()
        .map(|n| {
            [
                n.id.clone(),
                n.kind.clone(),
                match (&report.adapter, n.device.as_str(), n.status) {
                    (Some(a), "gpu", NodeStatus::Computed) => format!("gpu ({a})"),
                    _ => n.device.clone(),
                },
                status_text(n.status).to_string(),
                format!("{:.3}", n.seconds),
                human_bytes(n.bytes),
                headline(&registry, n),
            ]
        })
        .collect();
    let mut width = header.map(str::len);
    for r in &rows {
        for (w, c) in width.iter_mut().zip(r) {
            *w = (*w).max(c.chars().count());
        }
    }
    let line = |cells: [&str; 7]| {
        let mut s = String::new();
        for (i, (c, w)) in cells.iter().zip(width).enumerate() {
            if i == 4 || i == 5 {
                s.push_str(&format!("{c:>w$}  "));
            } else {
                s.push_str(&format!("{c:<w$}  "));
            }
        }
        s.trim_end().to_string() + "\n"
    };
    let why = |s: String, i: Option<usize>| -> String {
        if !explain {
            return s;
        }
        let reason = match i {
            None => "why",
            Some(i) => report.nodes[i].reason.as_deref().unwrap_or(""),
        };
        if reason.is_empty() {
            s
        } else {
            format!("{}  {reason}\n", s.trim_end())
        }
    };
    let mut out = why(line(header), None);
    for (i, r) in rows.iter().enumerate() {
        out.push_str(&why(
            line([&r[0], &r[1], &r[2], &r[3], &r[4], &r[5], &r[6]]),
            Some(i),
        ));
    }
    if !report.skipped.is_empty() {
        out.push_str(&format!(
            "not needed (downstream results cached): {}\n",
            report.skipped.join(", ")
        ));
    }
    out.push_str(&warning_lines(report));
    for n in report
        .nodes
        .iter()
        .filter(|n| n.status == NodeStatus::Failed)
    {
        out.push_str(&format!(
            "error: {}\n",
            n.error.as_deref().unwrap_or("failed")
        ));
    }
    out.push_str(&format!(
        "{} in {:.2} s\n",
        if report.cancelled {
            "cancelled"
        } else if report.ok {
            "ok"
        } else {
            "FAILED"
        },
        report.seconds
    ));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesoflow_runtime::report::Warning;

    #[test]
    fn the_table_shows_a_nodes_first_scalar_output() {
        // image.compare's first scalar output is its RMSE; a node without one shows nothing.
        let report: RunReport = serde_json::from_value(serde_json::json!({
            "mesoflow": 1, "graph": "g.json", "ok": true, "seconds": 0.0, "warnings": [],
            "nodes": [
                {"id": "compare", "kind": "image.compare", "device": "cpu", "status": "computed",
                 "seconds": 0.1, "bytes": 10, "key": "k",
                 "metrics": {"bias": -0.01, "relative_rmse": 0.2004, "rmse": 0.031234}},
                {"id": "save", "kind": "image.write", "device": "cpu", "status": "computed",
                 "seconds": 0.0, "bytes": 0, "key": "k2", "metrics": {}}
            ]
        }))
        .unwrap();
        let registry = mesoflow_nodes::registry::builtin();
        let sig = registry.node("image.compare").unwrap().signature();
        let first = sig
            .outputs
            .iter()
            .find(|o| o.ty == "Scalar")
            .unwrap()
            .name
            .clone();
        let table = summary(&report);
        let row = table.lines().find(|l| l.starts_with("compare")).unwrap();
        assert!(row.contains(&first), "{table}");
        assert_eq!(headline(&registry, &report.nodes[1]), "");
        assert_eq!(short(0.031234), "0.03123");
        assert_eq!(short(12.5), "12.50");
        assert_eq!(short(8.0), "8");
        assert_eq!(short(3.0e-5), "3.000e-5");
    }

    #[test]
    fn a_warning_several_nodes_gave_is_one_line() {
        let report: RunReport = serde_json::from_value(serde_json::json!({
            "mesoflow": 1, "graph": "g.json", "ok": true, "seconds": 0.0, "nodes": [],
            "warnings": []
        }))
        .unwrap();
        let warn = |node: &str, message: &str| Warning {
            node: node.into(),
            message: message.into(),
            expected: false,
        };
        let report = RunReport {
            warnings: vec![
                warn("a", "the only GPU adapter is llvmpipe"),
                warn("b", "outside the model's domain"),
                warn("c", "the only GPU adapter is llvmpipe"),
            ],
            ..report
        };
        assert_eq!(
            warning_lines(&report),
            "warning: nodes `a`, `c`: the only GPU adapter is llvmpipe\n\
             warning: node `b`: outside the model's domain\n"
        );
    }
}
