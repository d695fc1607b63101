//! Engine benchmarks (`cargo bench --bench engine`): per-node scheduling overhead on generated
//! 1000-node graphs, cold and cached; disk-cache read throughput against a plain file read; the
//! quickstart cold against cached. Prints a Markdown table; figures go to BENCHMARKS.md.

use mesoflow_graph::{check, CheckedGraph, GraphFile};
use mesoflow_runtime::cache::DiskCache;
use mesoflow_runtime::{
    DeviceMode, Engine, EngineConfig, Key, Outputs, RunOptions, SilentObserver,
};
use std::sync::Arc;
use std::time::Instant;

fn engine(disk: Option<&std::path::Path>) -> Engine {
    Engine::new(
        mesoflow_nodes::registry::builtin(),
        EngineConfig {
            memory_budget: 1 << 30,
            disk: disk.map(DiskCache::new),
        },
    )
}

fn checked(text: &str) -> CheckedGraph {
    let file = GraphFile::parse(text).expect("parse");
    check("bench", &file, &mesoflow_nodes::registry::builtin()).expect("check")
}

fn chain(n: usize) -> String {
    let mut nodes =
        vec![r#""n0": {"kind": "scalar.constant", "params": {"value": 1.0}}"#.to_string()];
    for i in 1..n {
        nodes.push(format!(r#""n{i}": {{"kind": "scalar.affine", "inputs": {{"x": "n{}.y"}}, "params": {{"scale": 1.0, "offset": 1.0}}}}"#, i - 1).replace("n0.y", "n0.value"));
    }
    format!(r#"{{"mesoflow": 1, "nodes": {{ {} }} }}"#, nodes.join(","))
}

fn wide(n: usize) -> String {
    let nodes: Vec<String> = (0..n)
        .map(|i| format!(r#""n{i}": {{"kind": "scalar.constant", "params": {{"value": {i}}}}}"#))
        .collect();
    format!(r#"{{"mesoflow": 1, "nodes": {{ {} }} }}"#, nodes.join(","))
}

fn opts(out: &std::path::Path) -> RunOptions {
    let policy = mesoflow_runtime::RunPolicy {
        device: DeviceMode::Cpu,
        ..Default::default()
    };
    RunOptions::new("bench", ".".into(), out.to_path_buf(), policy)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Median seconds of `reps` runs of `f`.
fn time(reps: usize, mut f: impl FnMut()) -> f64 {
    median(
        (0..reps)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64()
            })
            .collect(),
    )
}

fn main() {
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("out");
    println!("| benchmark | median | per node |\n| --- | ---: | ---: |");
    for (name, text) in [
        ("chain of 1000", chain(1000)),
        ("wide, 1000 independent", wide(1000)),
    ] {
        let g = checked(&text);
        let n = g.nodes.len() as f64;
        let cold = time(15, || {
            let e = engine(None);
            let r = e
                .run(&g, &opts(&out), Arc::new(SilentObserver))
                .expect("run");
            assert!(r.ok);
        });
        let e = engine(None);
        e.run(&g, &opts(&out), Arc::new(SilentObserver))
            .expect("run");
        let cached = time(15, || {
            let r = e
                .run(&g, &opts(&out), Arc::new(SilentObserver))
                .expect("run");
            assert!(r
                .nodes
                .iter()
                .all(|n| n.status == mesoflow_runtime::NodeStatus::Memory));
        });
        println!(
            "| {name}: cold (memory cache only) | {:.2} ms | {:.1} µs |",
            cold * 1e3,
            cold / n * 1e6
        );
        println!(
            "| {name}: cached (memory) | {:.2} ms | {:.1} µs |",
            cached * 1e3,
            cached / n * 1e6
        );
    }

    // Disk cache: a 256 MiB value (an 8192² height field) against reading the same bytes raw.
    let cache_dir = tmp.path().join("cache");
    let cache = DiskCache::new(&cache_dir);
    let registry = mesoflow_nodes::registry::builtin();
    let side = 8192;
    let hf = mesoflow_nodes::types::HeightField {
        width: side,
        height: side,
        data: (0..side * side).map(|i| (i % 977) as f32).collect(),
    };
    let key = Key([42; 32]);
    cache
        .put(
            &key,
            "bench",
            &Outputs::new().with("height", hf),
            &mesoflow_runtime::cache::Record::default(),
        )
        .expect("put");
    let entry = cache.entry_path(&key);
    let bytes = std::fs::metadata(&entry).expect("entry").len() as f64;
    let raw = tmp.path().join("raw.bin");
    std::fs::copy(&entry, &raw).expect("copy");
    let t_cache = time(7, || {
        let (o, _) = cache
            .get(&key, "bench", &registry)
            .expect("get")
            .expect("hit");
        assert_eq!(o.byte_size(), side * side * 4);
    });
    let t_raw = time(7, || {
        assert_eq!(std::fs::read(&raw).expect("read").len() as f64, bytes);
    });
    println!(
        "| disk cache read, 256 MiB HeightField (checksum + decode) | {:.1} ms | {:.2} GB/s |",
        t_cache * 1e3,
        bytes / t_cache / 1e9
    );
    println!(
        "| plain `std::fs::read` of the same bytes | {:.1} ms | {:.2} GB/s |",
        t_raw * 1e3,
        bytes / t_raw / 1e9
    );

    let t_registry = time(15, || {
        std::hint::black_box(mesoflow_nodes::registry::builtin());
    });
    println!(
        "| building the registry (schemas of every kind) | {:.3} ms | |",
        t_registry * 1e3
    );

    // The quickstart, in process: cold (empty caches) against cached (fresh engine, warm disk).
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("graphs/quickstart.json")).expect("quickstart");
    let g = checked(&text);
    let mut o = opts(&out);
    o.base_dir = root.join("graphs");
    let mut run_id = 0;
    let cold = time(7, || {
        run_id += 1;
        let e = engine(Some(&tmp.path().join(format!("qs{run_id}"))));
        assert!(e.run(&g, &o, Arc::new(SilentObserver)).expect("run").ok);
    });
    let warm_dir = tmp.path().join("qs-warm");
    engine(Some(&warm_dir))
        .run(&g, &o, Arc::new(SilentObserver))
        .expect("run");
    let cached = time(15, || {
        let e = engine(Some(&warm_dir));
        assert!(e.run(&g, &o, Arc::new(SilentObserver)).expect("run").ok);
    });
    println!("| quickstart, cold (CPU path) | {:.2} ms | |", cold * 1e3);
    println!(
        "| quickstart, cached (disk) | {:.2} ms | {:.1}% of cold |",
        cached * 1e3,
        cached / cold * 100.0
    );
}
