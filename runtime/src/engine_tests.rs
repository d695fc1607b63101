//! The engine's runs (the scheduler's behaviour) on small test kinds: caching, verification, concurrency, failures,
//! files on warm runs.

use crate::engine::{Engine, EngineConfig};
use crate::node::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use crate::registry::Registry;
use crate::report::NodeStatus;
use crate::run::{RunOptions, SilentObserver};
use crate::value::{Artifact, Scalar};
use mesoflow_graph::{check, DevicePreference, GraphFile};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

#[derive(Default, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
struct NoParams {}

/// Outputs how many times it has run: a kind whose results change without a version bump.
struct Drifting(Arc<AtomicUsize>);
impl Node for Drifting {
    type Params = NoParams;
    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "test.drifting",
            version: 1,
            doc: "",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![Port::output("y", "Scalar", "")],
            disk_cache: true,
        }
    }
    fn run(&self, _: &NodeContext, _: &NoParams, _: &Inputs) -> Result<Outputs, NodeError> {
        Ok(Outputs::new().with("y", Scalar(self.0.fetch_add(1, Ordering::SeqCst) as f64)))
    }
}

/// Waits (up to 10 s) until `expected` instances are inside `run` at once; reports whether
/// they met. Run one at a time, they never meet.
struct Rendezvous(Arc<AtomicUsize>, usize);
impl Node for Rendezvous {
    type Params = NoParams;
    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "test.rendezvous",
            version: 1,
            doc: "",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![Port::output("met", "Scalar", "")],
            disk_cache: false,
        }
    }
    fn run(&self, _: &NodeContext, _: &NoParams, _: &Inputs) -> Result<Outputs, NodeError> {
        self.0.fetch_add(1, Ordering::SeqCst);
        let start = Instant::now();
        while self.0.load(Ordering::SeqCst) < self.1 && start.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(1));
        }
        let met = self.0.load(Ordering::SeqCst) >= self.1;
        Ok(Outputs::new().with("met", Scalar(if met { 1.0 } else { 0.0 })))
    }
}

struct Panics;
impl Node for Panics {
    type Params = NoParams;
    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "test.panics",
            version: 1,
            doc: "",
            device: DevicePreference::Cpu,
            inputs: vec![Port::optional("x", "Scalar", "")],
            outputs: vec![Port::output("y", "Scalar", "")],
            disk_cache: false,
        }
    }
    fn run(&self, _: &NodeContext, _: &NoParams, _: &Inputs) -> Result<Outputs, NodeError> {
        panic!("index out of bounds")
    }
}

fn run(
    engine: &Engine,
    text: &str,
    verify: bool,
    dir: &std::path::Path,
) -> crate::report::RunReport {
    let file = GraphFile::parse(text).unwrap();
    let graph = check("t.json", &file, engine.registry()).unwrap();
    let mut opts = RunOptions::new("t.json", dir.into(), dir.join("out"), Default::default());
    opts.policy.verify_cache = verify;
    engine.run(&graph, &opts, Arc::new(SilentObserver)).unwrap()
}

#[test]
fn verify_cache_catches_a_kind_changed_without_a_version_bump() {
    let dir = tempfile::tempdir().unwrap();
    let mut r = Registry::new();
    r.register(Drifting(Arc::new(AtomicUsize::new(0))));
    let config = || EngineConfig {
        memory_budget: 1 << 20,
        disk: Some(crate::cache::DiskCache::new(dir.path().join("c"))),
    };
    let g = r#"{"mesoflow": 1, "nodes": {"d": {"kind": "test.drifting"}}}"#;
    let first = run(&Engine::new(r.clone(), config()), g, false, dir.path());
    assert_eq!(first.nodes[0].status, NodeStatus::Computed);
    let plain = run(&Engine::new(r.clone(), config()), g, false, dir.path());
    assert_eq!(
        plain.nodes[0].status,
        NodeStatus::Disk,
        "without verification the stale hit is used"
    );
    let verified = run(&Engine::new(r, config()), g, true, dir.path());
    assert!(!verified.ok);
    assert_eq!(verified.nodes[0].status, NodeStatus::Failed);
    let err = verified.nodes[0].error.as_deref().unwrap();
    assert!(
        err.contains("node `d`") && err.contains("without a version bump"),
        "{err}"
    );
}

#[test]
fn independent_nodes_run_at_the_same_time() {
    // Workers of its own, whatever the machine's or RAYON_NUM_THREADS (one worker cannot
    // overlap anything, and a test that returned early would pass with the feature broken):
    // three, as the scheduler itself waits on one of them here, where the command line runs it
    // on the main thread.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(3)
        .build()
        .expect("a pool of three workers");
    pool.install(independent_nodes_meet);
}

fn independent_nodes_meet() {
    let dir = tempfile::tempdir().unwrap();
    let mut r = Registry::new();
    r.register(Rendezvous(Arc::new(AtomicUsize::new(0)), 2));
    let engine = Engine::new(
        r,
        EngineConfig {
            memory_budget: 1 << 20,
            disk: None,
        },
    );
    let rep = run(
        &engine,
        r#"{"mesoflow": 1, "nodes": {"a": {"kind": "test.rendezvous"}, "b": {"kind": "test.rendezvous"}}}"#,
        false,
        dir.path(),
    );
    assert!(rep.ok);
    assert!(
        rep.nodes.iter().all(|n| n.metrics["met"] == 1.0),
        "{:?}",
        rep.nodes
    );
}

#[test]
fn memory_cache_serves_a_second_run_and_a_panic_is_a_node_failure() {
    let dir = tempfile::tempdir().unwrap();
    let mut r = Registry::new();
    r.register(Drifting(Arc::new(AtomicUsize::new(0))));
    r.register(Panics);
    let engine = Engine::new(
        r,
        EngineConfig {
            memory_budget: 1 << 20,
            disk: None,
        },
    );
    let g = r#"{"mesoflow": 1, "nodes": {"d": {"kind": "test.drifting"}, "p": {"kind": "test.panics", "inputs": {"x": "d.y"}}}}"#;
    let first = run(&engine, g, false, dir.path());
    assert!(!first.ok);
    assert_eq!(first.nodes[0].status, NodeStatus::Computed);
    assert_eq!(first.nodes[1].status, NodeStatus::Failed);
    assert!(
        first.nodes[1].error.as_deref().unwrap().contains("panic"),
        "{:?}",
        first.nodes[1].error
    );
    let second = run(&engine, g, false, dir.path());
    assert_eq!(second.nodes[0].status, NodeStatus::Memory);
    assert_eq!(
        second.nodes[0].metrics["y"], 0.0,
        "the cached value, not a recomputation"
    );
}

#[derive(Default, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
struct WriterParams {
    path: String,
}

/// Writes a file and passes a number on: a writer whose result feeds another node.
struct Writer;
impl Node for Writer {
    type Params = WriterParams;
    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "test.writer",
            version: 1,
            doc: "",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![
                Port::output("file", "File", ""),
                Port::output("n", "Scalar", ""),
            ],
            disk_cache: true,
        }
    }
    fn timings(&self) -> &'static [(&'static str, &'static str)] {
        &[("inner_ms", "a timing")]
    }
    fn run(&self, ctx: &NodeContext, p: &WriterParams, _: &Inputs) -> Result<Outputs, NodeError> {
        ctx.timing("inner_ms", 1.5);
        ctx.timing("nan_ms", f64::NAN);
        ctx.warn("written thin");
        Ok(Outputs::new()
            .with(
                "file",
                Artifact {
                    path: p.path.clone(),
                    bytes: b"written".to_vec(),
                },
            )
            .with("n", Scalar(1.0)))
    }
}

/// Adds one to its input.
struct Next;
impl Node for Next {
    type Params = NoParams;
    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "test.next",
            version: 1,
            doc: "",
            device: DevicePreference::Cpu,
            inputs: vec![Port::input("x", "Scalar", "")],
            outputs: vec![Port::output("y", "Scalar", "")],
            disk_cache: true,
        }
    }
    fn run(&self, _: &NodeContext, _: &NoParams, i: &Inputs) -> Result<Outputs, NodeError> {
        Ok(Outputs::new().with("y", Scalar(i.get::<Scalar>("x")?.0 + 1.0)))
    }
}

fn writer_registry() -> Registry {
    let mut r = Registry::new();
    r.register(Writer);
    r.register(Next);
    r
}

fn disk_engine(dir: &std::path::Path) -> Engine {
    Engine::new(
        writer_registry(),
        EngineConfig {
            memory_budget: 1 << 20,
            disk: Some(crate::cache::DiskCache::new(dir.join("cache"))),
        },
    )
}

const WRITER_GRAPH: &str = r#"{"mesoflow": 1, "nodes": {
    "w": {"kind": "test.writer", "params": {"path": "sub/w.txt"}},
    "next": {"kind": "test.next", "inputs": {"x": "w.n"}}}}"#;

fn run_into(
    engine: &Engine,
    text: &str,
    base: &std::path::Path,
    out: &str,
) -> crate::report::RunReport {
    let file = GraphFile::parse(text).unwrap();
    let graph = check("t.json", &file, engine.registry()).unwrap();
    let opts = RunOptions::new("t.json", base.into(), base.join(out), Default::default());
    engine.run(&graph, &opts, Arc::new(SilentObserver)).unwrap()
}

#[test]
fn a_warm_run_into_a_new_folder_writes_the_files_of_writers_that_feed_other_nodes() {
    let dir = tempfile::tempdir().unwrap();
    let first = run_into(&disk_engine(dir.path()), WRITER_GRAPH, dir.path(), "out1");
    assert!(first.ok);
    // A new process (engine) over the warm disk cache, into another folder.
    let second = run_into(&disk_engine(dir.path()), WRITER_GRAPH, dir.path(), "out2");
    assert!(second.ok);
    assert_eq!(second.node("next").unwrap().status, NodeStatus::Disk);
    assert_eq!(second.node("w").unwrap().status, NodeStatus::Disk);
    assert_eq!(
        std::fs::read(dir.path().join("out2/sub/w.txt")).unwrap(),
        b"written"
    );
}

#[test]
fn timings_go_to_the_report_and_survive_the_cache_but_never_the_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let first = run_into(&disk_engine(dir.path()), WRITER_GRAPH, dir.path(), "out");
    let w = first.node("w").unwrap();
    assert_eq!(w.timings["inner_ms"], 1.5);
    assert!(
        !w.timings.contains_key("nan_ms"),
        "a non-finite time is absent"
    );
    assert!(w.timings["seconds"] >= 0.0);
    assert!(!w.metrics.contains_key("inner_ms"));
    let second = run_into(&disk_engine(dir.path()), WRITER_GRAPH, dir.path(), "out");
    let w2 = second.node("w").unwrap();
    assert_eq!(w2.status, NodeStatus::Disk);
    assert_eq!(
        w2.timings, w.timings,
        "a hit reports the cost of the value it served"
    );
    assert_eq!(w2.kind_version, 1);
    assert!(!second.version.is_empty());
}

#[test]
fn a_hit_repeats_the_warnings_of_the_computation_that_made_its_value() {
    let dir = tempfile::tempdir().unwrap();
    let warned = |r: &crate::report::RunReport| -> Vec<(String, String)> {
        r.warnings
            .iter()
            .map(|w| (w.node.clone(), w.message.clone()))
            .collect()
    };
    let expected = vec![("w".to_string(), "written thin".to_string())];
    let engine = disk_engine(dir.path());
    let first = run_into(&engine, WRITER_GRAPH, dir.path(), "out1");
    assert_eq!(warned(&first), expected);
    // The same engine: a memory hit.
    let again = run_into(&engine, WRITER_GRAPH, dir.path(), "out2");
    assert_eq!(again.node("w").unwrap().status, NodeStatus::Memory);
    assert_eq!(warned(&again), expected);
    // A new process over the warm disk cache.
    let disk = run_into(&disk_engine(dir.path()), WRITER_GRAPH, dir.path(), "out3");
    assert_eq!(disk.node("w").unwrap().status, NodeStatus::Disk);
    assert_eq!(warned(&disk), expected);
}

#[test]
fn a_file_that_cannot_be_written_fails_the_run() {
    let dir = tempfile::tempdir().unwrap();
    // A folder stands where the file should go.
    std::fs::create_dir_all(dir.path().join("out/sub/w.txt/x")).unwrap();
    let rep = run_into(&disk_engine(dir.path()), WRITER_GRAPH, dir.path(), "out");
    assert!(!rep.ok);
    let w = rep.node("w").unwrap();
    assert_eq!(w.status, NodeStatus::Failed);
    assert!(
        w.error.as_deref().unwrap().contains("cannot write"),
        "{w:?}"
    );
    assert_eq!(rep.node("next").unwrap().status, NodeStatus::Cancelled);
    // Warm, the hit's write fails the same way.
    let rep = run_into(&disk_engine(dir.path()), WRITER_GRAPH, dir.path(), "out");
    assert!(!rep.ok);
    assert_eq!(rep.node("w").unwrap().status, NodeStatus::Failed);
}
