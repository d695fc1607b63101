//! The studio's state: the graph being edited (its text on disk, the edited file, the check's
//! errors), the engine and caches that every run shares, the last report, and the run worker
//! that re-runs the graph after each change, cancelling a run that a newer change made stale.

use super::events::Hub;
use crate::interrupt::cancel_flag;
use mesoflow_graph::{check, CheckedGraph, GraphError, GraphFile, Override};
use mesoflow_runtime::{DeviceMode, Engine, NodeReport, RunObserver, RunOptions, RunReport};
use serde_json::{json, Value};
use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// Why an edit was refused: the validator's messages, with the node and field they name.
#[derive(Debug)]
pub struct Refused {
    pub errors: Vec<Problem>,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct Problem {
    pub node: Option<String>,
    pub field: Option<String>,
    pub message: String,
}

impl Problem {
    pub fn of(e: &GraphError) -> Problem {
        Problem {
            node: e.node().map(str::to_string),
            field: e.field().map(str::to_string),
            message: e.to_string(),
        }
    }

    pub fn plain(message: impl Into<String>) -> Problem {
        Problem {
            node: None,
            field: None,
            message: message.into(),
        }
    }
}

/// The graph as the studio holds it.
pub struct Doc {
    /// The file's text as last read or written, and what it parsed as (`None`: it does not
    /// parse, and `load_error` says why).
    pub disk_text: String,
    pub disk: Option<GraphFile>,
    pub load_error: Option<String>,
    /// The graph being edited; differs from `disk` until saved.
    pub file: GraphFile,
    /// The check's errors; empty when the graph can run.
    pub errors: Vec<GraphError>,
    /// Files the graph would read outside the studio's folders: it is not run while any remain.
    pub blocked: Vec<Problem>,
    pub checked: Option<CheckedGraph>,
    /// Bumped by every change, so a client knows its view is stale.
    pub revision: u64,
    pub report: Option<RunReport>,
}

#[derive(Default)]
struct RunState {
    pending: bool,
    running: bool,
    cancel: Option<Arc<AtomicBool>>,
    runs: u64,
}

pub struct Studio {
    pub graph_path: PathBuf,
    pub base_dir: PathBuf,
    pub out_dir: PathBuf,
    /// Folders files may be read from through the server (canonical).
    pub roots: Vec<PathBuf>,
    pub engine: Engine,
    pub device: DeviceMode,
    pub require_gpu: bool,
    /// `--verify-cache`: every cache hit is recomputed and compared.
    pub verify_cache: bool,
    pub hub: Arc<Hub>,
    pub doc: Mutex<Doc>,
    runs: Mutex<RunState>,
    wake: Condvar,
    pub sweep: Mutex<super::sweep_state::SweepState>,
    pub plan: Mutex<super::plan_state::PlanState>,
}

/// Errors that a structural edit may leave behind: a node just added has no inputs yet, and a
/// removed node's dependants lose theirs. Everything else must be fixed before the edit is kept.
fn tolerated(e: &GraphError) -> bool {
    matches!(
        e,
        GraphError::MissingInput { .. } | GraphError::MissingParam { .. }
    )
}

/// Whether `path` lies inside one of `roots` (canonical folders), links and `..` followed. A
/// path that does not exist yet is judged by its nearest existing ancestor.
pub fn inside(roots: &[PathBuf], path: &Path) -> bool {
    let mut p = path.to_path_buf();
    loop {
        if let Ok(real) = p.canonicalize() {
            return roots.iter().any(|r| real.starts_with(r));
        }
        if !p.pop() {
            return false;
        }
    }
}

impl Studio {
    pub fn new(
        graph_path: PathBuf,
        out_dir: PathBuf,
        cache_dir: Option<PathBuf>,
        engine: Engine,
        device: DeviceMode,
    ) -> anyhow::Result<Studio> {
        let base_dir = crate::session::graph_dir(&graph_path);
        std::fs::create_dir_all(&out_dir)?;
        let mut roots = vec![base_dir.canonicalize()?, out_dir.canonicalize()?];
        if let Some(c) = &cache_dir {
            std::fs::create_dir_all(c)?;
            roots.push(c.canonicalize()?);
        }
        let text = std::fs::read_to_string(&graph_path)
            .map_err(|e| crate::exit::invalid(format!("{}: {e}", graph_path.display())))?;
        let studio = Studio {
            graph_path,
            base_dir,
            out_dir,
            roots,
            engine,
            device,
            require_gpu: crate::session::require_gpu(),
            verify_cache: false,
            hub: Arc::new(Hub::default()),
            doc: Mutex::new(Doc {
                disk_text: String::new(),
                disk: None,
                load_error: None,
                file: GraphFile {
                    description: None,
                    interface: None,
                    nodes: Vec::new(),
                    base: None,
                    source: None,
                    values: Default::default(),
                    uses: Vec::new(),
                    expected_warnings: Default::default(),
                },
                errors: Vec::new(),
                blocked: Vec::new(),
                checked: None,
                revision: 0,
                report: None,
            }),
            runs: Mutex::new(RunState::default()),
            wake: Condvar::new(),
            sweep: Mutex::new(Default::default()),
            plan: Mutex::new(Default::default()),
        };
        studio.load_text(text);
        Ok(studio)
    }

    pub fn doc(&self) -> MutexGuard<'_, Doc> {
        self.doc.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn check(&self, file: &GraphFile) -> Result<CheckedGraph, Vec<GraphError>> {
        check(
            &self.graph_path.display().to_string(),
            file,
            self.engine.registry(),
        )
        .map_err(|e| e.errors)
    }

    /// The files the graph's nodes would read that lie outside the studio's folders: the
    /// studio reads nothing there, whoever asks.
    fn reads_outside(&self, graph: &CheckedGraph) -> Vec<Problem> {
        let reg = self.engine.registry();
        let mut out = Vec::new();
        for n in &graph.nodes {
            let Some(kind) = reg.node(&n.kind) else {
                continue;
            };
            let Ok(files) = kind
                .prepare(&n.params)
                .and_then(|p| kind.files(&p, &self.base_dir))
            else {
                continue; // the run reports the node's own error
            };
            for f in files.iter().filter(|f| !inside(&self.roots, f)) {
                out.push(Problem {
                    node: Some(n.id.clone()),
                    field: None,
                    message: format!(
                        "node `{}` would read {}, outside the studio's folders (the graph's \
                         folder, the output folder, the cache); move the file there, or use \
                         `mesoflow run`",
                        n.id,
                        f.display()
                    ),
                });
            }
        }
        out
    }

    /// Takes the file's text as the graph (at start, and when an editor changed the file).
    pub fn load_text(&self, text: String) {
        let mut doc = self.doc();
        match GraphFile::parse(&text).map(|f| f.located(&self.graph_path)) {
            Ok(file) => {
                doc.disk = Some(file.clone());
                doc.load_error = None;
                self.set_file(&mut doc, file);
            }
            Err(errors) => {
                doc.disk = None;
                doc.load_error = Some(
                    errors
                        .iter()
                        .map(|e| e.to_string())
                        .collect::<Vec<_>>()
                        .join("\n"),
                );
                doc.errors = errors;
                doc.checked = None;
                doc.revision += 1;
            }
        }
        doc.disk_text = text;
        drop(doc);
        self.hub.publish("graph", json!({ "reason": "file" }));
        self.request_run();
    }

    fn set_file(&self, doc: &mut Doc, file: GraphFile) {
        let checked = self.check(&file);
        let blocked = checked
            .as_ref()
            .map(|g| self.reads_outside(g))
            .unwrap_or_default();
        self.install(doc, file, checked, blocked);
    }

    /// Makes `file` the graph, with its check's result and the reads it would make outside the
    /// studio's folders (`blocked`): a graph with any is kept but not runnable.
    fn install(
        &self,
        doc: &mut Doc,
        file: GraphFile,
        checked: Result<CheckedGraph, Vec<GraphError>>,
        blocked: Vec<Problem>,
    ) {
        match checked {
            Ok(g) => {
                doc.errors.clear();
                doc.checked = blocked.is_empty().then_some(g);
            }
            Err(errors) => {
                doc.errors = errors;
                doc.checked = None;
            }
        }
        doc.blocked = blocked;
        doc.file = file;
        doc.revision += 1;
    }

    /// Applies an edit to the graph. A parameter change must pass the validator; a structural
    /// edit may leave only [`tolerated`] errors. Accepted: the graph re-runs (when it checks).
    pub fn edit(
        &self,
        structural: bool,
        apply: impl FnOnce(&mut GraphFile) -> Result<(), String>,
    ) -> Result<u64, Refused> {
        let mut doc = self.doc();
        let mut file = doc.file.clone();
        apply(&mut file).map_err(|m| Refused {
            errors: vec![Problem::plain(m)],
        })?;
        let before: BTreeSet<String> = doc.errors.iter().map(|e| e.to_string()).collect();
        let checked = self.check(&file);
        match &checked {
            Ok(g) => {
                let outside = self.reads_outside(g);
                if !outside.is_empty() {
                    return Err(Refused { errors: outside });
                }
            }
            Err(errors) => {
                let new: Vec<Problem> = errors
                    .iter()
                    .filter(|e| !before.contains(&e.to_string()))
                    .filter(|e| !(structural && tolerated(e)))
                    .map(Problem::of)
                    .collect();
                if !new.is_empty() {
                    return Err(Refused { errors: new });
                }
            }
        }
        // The edit was refused above had it read outside: nothing is blocked.
        self.install(&mut doc, file, checked, Vec::new());
        let revision = doc.revision;
        drop(doc);
        self.hub
            .publish("graph", json!({ "reason": "edit", "revision": revision }));
        self.request_run();
        Ok(revision)
    }

    pub fn set_param(&self, node: &str, param: &str, value: Value) -> Result<u64, Refused> {
        let o = Override {
            node: node.into(),
            param: param.into(),
            value,
        };
        self.edit(false, |f| {
            // `null` restores the default.
            if o.value.is_null() && !o.param.contains('.') {
                let decl = f
                    .node_mut(&o.node)
                    .ok_or_else(|| format!("no node `{}`", o.node))?;
                decl.params.shift_remove(&o.param);
                return Ok(());
            }
            f.apply(&o)
        })
    }

    /// Writes the edited graph to its file, changing only what was edited. A file that does not
    /// parse is left for its editor to fix: the studio never had its graph, so it cannot save it.
    pub fn save(&self) -> Result<bool, String> {
        let mut doc = self.doc();
        let Some(disk) = &doc.disk else {
            return Err(format!(
                "{} does not parse; fix it in an editor (the studio reloads it)",
                self.graph_path.display()
            ));
        };
        let text = mesoflow_graph::source_edit::rewrite(&doc.disk_text, disk, &doc.file);
        // A graph file deleted (or replaced) behind the studio's back is written again: `saved`
        // means the file holds the graph (issue 43).
        let on_disk = std::fs::read_to_string(&self.graph_path).ok();
        let changed = text != doc.disk_text || on_disk.as_deref() != Some(text.as_str());
        if changed {
            mesoflow_runtime::write_atomic(&self.graph_path, &text)
                .map_err(|e| format!("cannot write {}: {e}", self.graph_path.display()))?;
        }
        doc.disk = Some(doc.file.clone());
        doc.disk_text = text;
        drop(doc);
        self.hub.publish("saved", json!({ "changed": changed }));
        Ok(changed)
    }

    /// The file changed on disk: an editor saved it. Unless it is what the studio wrote, it
    /// replaces the graph (edits not yet saved are dropped, as an editor reloading would).
    pub fn file_changed(&self, text: String) {
        if text == self.doc().disk_text {
            return;
        }
        self.load_text(text);
    }

    /// Asks for a run of the current graph; a run in progress is cancelled first.
    pub fn request_run(&self) {
        let mut st = self.runs.lock().unwrap_or_else(|e| e.into_inner());
        st.pending = true;
        if let Some(c) = &st.cancel {
            c.store(true, Ordering::SeqCst);
        }
        self.wake.notify_all();
    }

    pub fn running(&self) -> bool {
        let st = self.runs.lock().unwrap_or_else(|e| e.into_inner());
        st.running || st.pending
    }

    pub fn options(&self, out_dir: &Path, cancel: Arc<AtomicBool>) -> RunOptions {
        RunOptions::new(
            &self.graph_path.display().to_string(),
            self.base_dir.clone(),
            out_dir.to_path_buf(),
            mesoflow_runtime::RunPolicy {
                device: self.device,
                require_gpu: self.require_gpu,
                verify_cache: self.verify_cache,
                cancel,
                // Input files are checked against the studio's folders again when a run hashes and
                // opens them: a file accepted by an edit may have become a link to one outside since.
                confine: Some(mesoflow_runtime::Confinement::new(&self.roots)),
                ..Default::default()
            },
        )
    }

    /// The run worker: runs the graph whenever asked, one run at a time, until Ctrl-C.
    pub fn run_worker(self: Arc<Self>) {
        let quit = cancel_flag();
        loop {
            let (run, cancel) = {
                let mut st = self.runs.lock().unwrap_or_else(|e| e.into_inner());
                while !st.pending {
                    if quit.load(Ordering::Relaxed) {
                        return;
                    }
                    st = self
                        .wake
                        .wait_timeout(st, Duration::from_millis(200))
                        .map(|(g, _)| g)
                        .unwrap_or_else(|e| e.into_inner().0);
                }
                st.pending = false;
                st.running = true;
                st.runs += 1;
                let cancel = Arc::new(AtomicBool::new(false));
                st.cancel = Some(cancel.clone());
                (st.runs, cancel)
            };
            let (graph, revision) = {
                let doc = self.doc();
                (doc.checked.clone(), doc.revision)
            };
            if let Some(graph) = graph {
                self.run_once(run, revision, &graph, cancel);
            } else {
                self.hub.publish(
                    "run_skipped",
                    json!({ "run": run, "reason": "the graph has errors" }),
                );
            }
            let mut st = self.runs.lock().unwrap_or_else(|e| e.into_inner());
            st.running = false;
            st.cancel = None;
        }
    }

    fn run_once(&self, run: u64, revision: u64, graph: &CheckedGraph, cancel: Arc<AtomicBool>) {
        let opts = self.options(&self.out_dir, cancel);
        let ids: Vec<&str> = graph.nodes.iter().map(|n| n.id.as_str()).collect();
        self.hub.publish(
            "run_started",
            json!({ "run": run, "revision": revision, "nodes": ids }),
        );
        let observer: Arc<dyn RunObserver> = Arc::new(Live {
            hub: self.hub.clone(),
            run,
            last: Mutex::new(HashMap::new()),
        });
        let result = self.engine.run(graph, &opts, observer);
        let report = match result {
            Ok(r) => r,
            Err(e) => {
                self.hub.publish(
                    "run_finished",
                    json!({ "run": run, "error": e.to_string() }),
                );
                return;
            }
        };
        let _ = crate::session::write_report(&report, &self.out_dir);
        let reran: Vec<&str> = report
            .nodes
            .iter()
            .filter(|n| n.status == mesoflow_runtime::NodeStatus::Computed)
            .map(|n| n.id.as_str())
            .collect();
        self.hub.publish(
            "run_finished",
            json!({ "run": run, "revision": revision, "ok": report.ok,
                    "cancelled": report.cancelled, "reran": reran, "report": report }),
        );
        self.doc().report = Some(report);
    }
}

/// Sends a run's progress to the browsers: each node's start and end, and its progress at most
/// every 100 ms (a node reporting per texel would flood them).
struct Live {
    hub: Arc<Hub>,
    run: u64,
    last: Mutex<HashMap<String, Instant>>,
}

impl RunObserver for Live {
    fn node_started(&self, id: &str, kind: &str, device: &str) {
        self.hub.publish(
            "node_started",
            json!({ "run": self.run, "id": id, "kind": kind, "device": device }),
        );
    }

    fn progress(&self, id: &str, done: u64, total: u64) {
        let now = Instant::now();
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        if last
            .get(id)
            .is_some_and(|t| now.duration_since(*t) < Duration::from_millis(100))
            && done < total
        {
            return;
        }
        last.insert(id.to_string(), now);
        drop(last);
        self.hub.publish(
            "progress",
            json!({ "run": self.run, "id": id, "done": done, "total": total }),
        );
    }

    fn node_finished(&self, report: &NodeReport) {
        self.hub
            .publish("node_finished", json!({ "run": self.run, "node": report }));
    }
}
