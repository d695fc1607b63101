//! Measuring the view: the probe graph (`scene.footprint` on the render's own mesh, BTF and
//! profile, with its camera, tiling, shell and scale, and only the nodes those need), run
//! through the engine and its cache, read back as a [`Scene`].

use crate::{texture_sources, PlanError, RenderKind, Scene, TextureView};
use mesoflow_graph::{Catalog, GraphFile, NodeDecl};
use mesoflow_runtime::{Engine, RunOptions, RunReport, SilentObserver};
use serde_json::{Map, Value};
use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

/// The probe node's id in the probe graph (its texture probes are `plan_probe_texture<i>`).
pub const PROBE: &str = "plan_probe";

/// The view parameters the probe takes from the render node: the shared view fields
/// `scene.footprint` has (declared once, in `raytrace::view`), and the shell.
fn view_fields() -> impl Iterator<Item = &'static str> {
    mesoflow_nodes::scene::footprint::Params::VIEW_FIELDS
        .iter()
        .copied()
        .chain(["shell"])
}

/// The nodes `id` depends on, and itself.
pub(crate) fn ancestors(file: &GraphFile, id: &str) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut stack = vec![id.to_string()];
    while let Some(n) = stack.pop() {
        if !seen.insert(n.clone()) {
            continue;
        }
        if let Some(d) = file.node(&n) {
            for from in d.inputs.values() {
                if let Some((up, _)) = from.split_once('.') {
                    stack.push(up.to_string());
                }
            }
        }
    }
    seen
}

/// Parameter `param`'s default in kind `kind`'s schema (`None` where it has none, or null).
pub(crate) fn kind_default(catalog: &dyn Catalog, kind: &str, param: &str) -> Option<Value> {
    catalog
        .signature(kind)?
        .params
        .get("properties")?
        .get(param)?
        .get("default")
        .filter(|d| !d.is_null())
        .cloned()
}

/// The probe graph for `render` (a node of `file`). A view parameter the render node leaves out
/// takes the render kind's own default from `catalog`, not the probe's, so the probe sees the
/// view the render will draw (render kinds differ in their `tiling` and `mm_per_unit`).
pub fn probe_graph(
    file: &GraphFile,
    render: &str,
    kind: RenderKind,
    catalog: &dyn Catalog,
) -> GraphFile {
    let r = file.node(render).cloned().unwrap_or(NodeDecl {
        kind: String::new(),
        params: Map::new(),
        inputs: Default::default(),
    });
    let mut params = Map::new();
    for k in view_fields() {
        if let Some(v) = r
            .params
            .get(k)
            .cloned()
            .or_else(|| kind_default(catalog, &r.kind, k))
        {
            params.insert(k.into(), v);
        }
    }
    if kind == RenderKind::Sss {
        params.remove("tiling");
    }
    let mut inputs = BTreeMap::new();
    for (port, from) in [
        ("mesh", r.inputs.get("mesh")),
        ("btf", kind.btf_port().and_then(|p| r.inputs.get(p))),
        ("profile", r.inputs.get("profile")),
    ] {
        if let Some(f) = from {
            inputs.insert(port.to_string(), f.clone());
        }
    }
    let mut out = file.clone();
    let mut keep = BTreeSet::new();
    // One probe more per texture a decision needs measured, on the render's mesh and camera.
    for (i, src) in texture_sources(file, render).iter().enumerate() {
        let id = format!("{PROBE}_texture{i}");
        let mut t = BTreeMap::new();
        if let Some(m) = inputs.get("mesh") {
            t.insert("mesh".to_string(), m.clone());
        }
        t.insert("texture".to_string(), src.clone());
        out.nodes.push((
            id.clone(),
            NodeDecl {
                kind: "scene.footprint".into(),
                params: params.clone(),
                inputs: t,
            },
        ));
        keep.extend(ancestors(&out, &id));
    }
    out.nodes.push((
        PROBE.into(),
        NodeDecl {
            kind: "scene.footprint".into(),
            params,
            inputs,
        },
    ));
    keep.extend(ancestors(&out, PROBE));
    out.nodes.retain(|(id, _)| keep.contains(id));
    out
}

/// A probe run that failed, as the error naming each node that did.
pub(crate) fn failed(report: &RunReport) -> Result<(), PlanError> {
    if report.ok {
        return Ok(());
    }
    let errors: Vec<String> = report
        .nodes
        .iter()
        .filter_map(|n| n.error.as_ref().map(|e| format!("{}: {e}", n.id)))
        .collect();
    Err(PlanError::Probe(errors.join("; ")))
}

/// The scene a probe run measured: the probe's metrics, and each texture probe's texels per
/// pixel by the output it measured.
pub fn scene_of(report: &RunReport, file: &GraphFile, render: &str) -> Result<Scene, PlanError> {
    failed(report)?;
    let metrics = report
        .node(PROBE)
        .map(|n| n.metrics.clone())
        .unwrap_or_default();
    let mut scene = Scene::from_metrics(&metrics)?;
    for (i, src) in texture_sources(file, render).iter().enumerate() {
        if let Some(v) = report
            .node(&format!("{PROBE}_texture{i}"))
            .and_then(|n| TextureView::from_metrics(&n.metrics))
        {
            scene.textures.insert(src.clone(), v);
        }
    }
    Ok(scene)
}

/// Measures what `render`'s view shows: builds the probe graph, checks it, runs it on `engine`
/// with `opts` (its cache, device and cancel flag; the outputs asked for are replaced by the
/// probe's own), and reads the scene. `name` names the graph in errors.
pub fn measure(
    engine: &Engine,
    name: &str,
    file: &GraphFile,
    render: &str,
    kind: RenderKind,
    mut opts: RunOptions,
) -> Result<Scene, PlanError> {
    let probe = probe_graph(file, render, kind, engine.registry());
    let checked = mesoflow_graph::check(name, &probe, engine.registry())
        .map_err(|e| PlanError::Probe(e.to_string().trim_end().to_string()))?;
    opts.outputs.clear();
    let report = engine
        .run(&checked, &opts, Arc::new(SilentObserver))
        .map_err(|e| PlanError::Probe(e.to_string()))?;
    scene_of(&report, file, render)
}
