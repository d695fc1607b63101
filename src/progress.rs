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

/// The summary table, warnings and errors, as printed after a run.
pub fn summary(report: &RunReport) -> String {
    summary_with(report, false)
}

/// The run table; with `explain`, a last column `why` gives each computed node's reason (what
/// changed since the last run into the same output folder).
pub fn summary_with(report: &RunReport, explain: bool) -> String {
    let header = ["node", "kind", "device", "status", "seconds", "bytes"];
    let rows: Vec<[String; 6]> = report
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
            ]
        })
        .collect();
    let mut width = header.map(str::len);
    for r in &rows {
        for (w, c) in width.iter_mut().zip(r) {
            *w = (*w).max(c.chars().count());
        }
    }
    let line = |cells: [&str; 6]| {
        let mut s = String::new();
        for (i, (c, w)) in cells.iter().zip(width).enumerate() {
            if i >= 4 {
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
            line([&r[0], &r[1], &r[2], &r[3], &r[4], &r[5]]),
            Some(i),
        ));
    }
    if !report.skipped.is_empty() {
        out.push_str(&format!(
            "not needed (downstream results cached): {}\n",
            report.skipped.join(", ")
        ));
    }
    for w in &report.warnings {
        out.push_str(&format!("warning: node `{}`: {}\n", w.node, w.message));
    }
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
