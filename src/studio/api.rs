//! The studio's HTTP interface: the page, the JSON API the page uses, the event stream, pixels
//! and files, as plain values ([`Call`] in, [`Reply`] out) that the server (`server.rs`) reads
//! from and writes to the connection. Every request passes [`Guard`] (token and Host) before its
//! body is read.

use super::plan;
use super::preview;
use super::session::{Problem, Refused, Studio};
use super::sweep;
use mesoflow_graph::{GraphFile, NodeDecl, PortRef};
use mesoflow_runtime::{SilentObserver, ValueRef};
use serde::Deserialize;
use serde_json::{json, Value};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

const PAGE: &str = include_str!("assets/index.html");
const STYLE: &str = include_str!("assets/studio.css");
/// The page's script: one plain JavaScript file served as `/studio.js`, written as one file a
/// section (`assets/js/`, in order) and joined here at compile time: still no build step.
const SCRIPT: &str = concat!(
    include_str!("assets/js/00-page.js"),
    include_str!("assets/js/01-server.js"),
    include_str!("assets/js/02-helpers.js"),
    include_str!("assets/js/03-state.js"),
    include_str!("assets/js/04-graph.js"),
    include_str!("assets/js/05-params.js"),
    include_str!("assets/js/06-compose.js"),
    include_str!("assets/js/07-previews.js"),
    include_str!("assets/js/08-report.js"),
    include_str!("assets/js/09-sweeps.js"),
    include_str!("assets/js/09-plan.js"),
    include_str!("assets/js/10-start.js"),
);
/// The largest request body accepted (a graph edit is a few hundred bytes); a larger declared
/// length is refused before anything is read.
pub const MAX_BODY: u64 = 4 << 20;

/// One request as the API sees it: read in full by the server, after the guard admitted it.
pub struct Call {
    pub method: String,
    pub path: String,
    pub query: Vec<(String, String)>,
    pub body: Vec<u8>,
}

/// What the API answers: a whole response, or "stream the events" (the server holds the
/// connection open and writes them as they come).
pub enum Reply {
    Data {
        status: u16,
        content_type: &'static str,
        headers: Vec<(&'static str, String)>,
        body: Vec<u8>,
    },
    Events,
}

impl Reply {
    fn data(content_type: &'static str, body: Vec<u8>) -> Reply {
        Reply::Data {
            status: 200,
            content_type,
            headers: Vec::new(),
            body,
        }
    }
}

pub struct Guard {
    token: String,
    /// Host headers accepted; empty when listening on every interface (the token still holds).
    hosts: Vec<String>,
}

impl Guard {
    pub fn new(token: String, host: &str, port: u16) -> Guard {
        let loopback = ["127.0.0.1", "localhost", "[::1]"];
        let hosts = if host == "0.0.0.0" || host == "::" {
            Vec::new()
        } else {
            loopback
                .iter()
                .copied()
                .chain([host])
                .map(|h| format!("{h}:{port}"))
                .collect()
        };
        Guard { token, hosts }
    }

    /// Whether a request with this Host header, token header and query may be answered.
    pub fn admits(
        &self,
        host: Option<&str>,
        token_header: Option<&str>,
        query: &[(String, String)],
    ) -> Result<(), (u16, &'static str)> {
        let host = host.unwrap_or_default();
        if !self.hosts.is_empty() && !self.hosts.iter().any(|h| h == host) {
            return Err((
                403,
                "this server answers only to its own address (Host header)",
            ));
        }
        let given = query
            .iter()
            .find(|(k, _)| k == "token")
            .map(|(_, v)| v.as_str())
            .or(token_header);
        // Compared in full whatever the first difference, so timing tells nothing.
        let ok = given.is_some_and(|g| {
            g.len() == self.token.len()
                && g.bytes()
                    .zip(self.token.bytes())
                    .fold(0u8, |acc, (a, b)| acc | (a ^ b))
                    == 0
        });
        if ok {
            Ok(())
        } else {
            Err((
                401,
                "a token is required: open the URL that `mesoflow serve` printed",
            ))
        }
    }
}

fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'+' => out.push(b' '),
            b'%' if i + 2 < b.len() => {
                match u8::from_str_radix(std::str::from_utf8(&b[i + 1..i + 3]).unwrap_or("zz"), 16)
                {
                    Ok(v) => {
                        out.push(v);
                        i += 2;
                    }
                    Err(_) => out.push(b'%'),
                }
            }
            c => out.push(c),
        }
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

pub fn split_url(url: &str) -> (String, Vec<(String, String)>) {
    let (path, query) = url.split_once('?').unwrap_or((url, ""));
    let pairs = query
        .split('&')
        .filter(|p| !p.is_empty())
        .map(|p| {
            let (k, v) = p.split_once('=').unwrap_or((p, ""));
            (percent_decode(k), percent_decode(v))
        })
        .collect();
    (path.to_string(), pairs)
}

fn json_response(status: u16, v: &Value) -> Reply {
    Reply::Data {
        status,
        content_type: "application/json",
        headers: Vec::new(),
        body: v.to_string().into_bytes(),
    }
}

pub fn error(status: u16, message: &str) -> Reply {
    json_response(
        status,
        &json!({ "error": message, "errors": [{ "message": message }] }),
    )
}

fn refused(r: Refused) -> Reply {
    let first = r
        .errors
        .first()
        .map(|p| p.message.clone())
        .unwrap_or_default();
    json_response(422, &json!({ "error": first, "errors": r.errors }))
}

fn body<T: for<'de> Deserialize<'de>>(call: &Call) -> Result<T, String> {
    serde_json::from_slice(&call.body).map_err(|e| format!("bad request body: {e}"))
}

fn q<'a>(query: &'a [(String, String)], key: &str) -> Option<&'a str> {
    query
        .iter()
        .find(|(k, _)| k == key)
        .map(|(_, v)| v.as_str())
}

/// Answers one admitted request.
pub fn handle(studio: &Arc<Studio>, call: &Call) -> Reply {
    let query = &call.query[..];
    let (method, path) = (call.method.as_str(), call.path.as_str());
    match (method, path) {
        ("GET", "/") | ("GET", "/index.html") => {
            let page = PAGE
                .replace("/*STYLE*/", STYLE)
                .replace("/*SCRIPT*/", SCRIPT);
            Reply::data("text/html; charset=utf-8", page.into_bytes())
        }
        ("GET", "/api/events") => Reply::Events,
        ("GET", "/api/state") => json_response(200, &state(studio)),
        ("GET", "/api/kinds") => {
            let reg = studio.engine.registry();
            let kinds: Vec<Value> = mesoflow_graph::Catalog::kinds(reg)
                .into_iter()
                .filter_map(|k| reg.node(k).map(|n| json!(n.signature())))
                .collect();
            json_response(200, &json!(kinds))
        }
        ("GET", "/api/value") => match target(query) {
            Ok(t) => match value(studio, &through_subgraphs(studio, t)) {
                Ok(v) => json_response(200, &preview::describe(&v)),
                Err((s, m)) => error(s, &m),
            },
            Err(m) => error(400, &m),
        },
        ("GET", "/api/pixels") => match target(query) {
            Ok(t) => {
                let index = q(query, "index").and_then(|i| i.parse().ok()).unwrap_or(0);
                let t = through_subgraphs(studio, t);
                match value(studio, &t).map(|v| preview::pixels(&v, index)) {
                    Ok(Some(p)) => pixels_response(p),
                    Ok(None) => error(404, &format!("{t} has no image {index}")),
                    Err((s, m)) => error(s, &m),
                }
            }
            Err(m) => error(400, &m),
        },
        ("GET", "/api/file") => match q(query, "path") {
            Some(p) => file(studio, p),
            None => error(400, "?path= is required"),
        },
        ("GET", "/api/sweep") => json_response(
            200,
            &studio
                .sweep
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .json(),
        ),
        ("POST", "/api/set") => edit_response(set(studio, call)),
        ("POST", "/api/add") => edit_response(add(studio, call)),
        ("POST", "/api/remove") => edit_response(remove(studio, call)),
        ("POST", "/api/connect") => edit_response(connect(studio, call)),
        ("POST", "/api/save") => match studio.save() {
            Ok(changed) => json_response(200, &json!({ "saved": true, "changed": changed })),
            Err(e) => error(409, &e),
        },
        ("POST", "/api/run") => {
            studio.request_run();
            json_response(200, &json!({ "queued": true }))
        }
        ("GET", "/api/plan") => json_response(
            200,
            &studio.plan.lock().unwrap_or_else(|e| e.into_inner()).json(),
        ),
        ("POST", "/api/plan") => match body::<plan::PlanSpec>(call) {
            Ok(spec) => match plan::start(studio, spec) {
                Ok(id) => json_response(200, &json!({ "plan": id })),
                Err(r) => refused(r),
            },
            Err(m) => error(400, &m),
        },
        ("POST", "/api/plan/apply") => edit_response(Ok(plan::apply(studio))),
        ("GET", "/api/plan/pixels") => match q(query, "image").map(|i| plan::preview(studio, i)) {
            Some(Ok(v)) => match preview::pixels(&v, 0) {
                Some(p) => pixels_response(p),
                None => error(404, "not an image"),
            },
            Some(Err((s, m))) => error(s, &m),
            None => error(400, "?image= is required"),
        },
        ("POST", "/api/sweep") => match body::<sweep::SweepSpec>(call) {
            Ok(spec) => match sweep::start(studio, spec) {
                Ok(id) => json_response(200, &json!({ "sweep": id })),
                Err(r) => refused(r),
            },
            Err(m) => error(400, &m),
        },
        _ => error(404, &format!("no such page: {method} {path}")),
    }
}

/// 200 with the graph's new revision, 422 with the validator's errors, 400 for a bad request.
fn edit_response(result: Result<Result<u64, Refused>, String>) -> Reply {
    match result {
        Err(m) => error(400, &m),
        Ok(Err(r)) => refused(r),
        Ok(Ok(revision)) => json_response(200, &json!({ "ok": true, "revision": revision })),
    }
}

#[derive(Deserialize)]
struct SetBody {
    node: String,
    param: String,
    value: Value,
}

fn set(studio: &Studio, call: &Call) -> Result<Result<u64, Refused>, String> {
    let b: SetBody = body(call)?;
    Ok(studio.set_param(&b.node, &b.param, b.value))
}

#[derive(Deserialize)]
struct AddBody {
    kind: String,
    id: Option<String>,
}

fn add(studio: &Studio, call: &Call) -> Result<Result<u64, Refused>, String> {
    let b: AddBody = body(call)?;
    Ok(studio.edit(true, |f: &mut GraphFile| {
        let id = match b.id.filter(|s| !s.is_empty()) {
            Some(id) => id,
            None => fresh_id(f, &b.kind),
        };
        if !mesoflow_graph::file::valid_id(&id) {
            return Err(format!("node id `{id}`: ids are [a-z][a-z0-9_]*"));
        }
        if f.node(&id).is_some() {
            return Err(format!("node id `{id}` is taken"));
        }
        f.nodes.push((
            id,
            NodeDecl {
                kind: b.kind.clone(),
                params: Default::default(),
                inputs: Default::default(),
            },
        ));
        Ok(())
    }))
}

/// `render_mesh`, `render_mesh2`, …: the kind's name made an id, numbered when taken.
fn fresh_id(f: &GraphFile, kind: &str) -> String {
    let mut stem: String = kind
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect();
    if !stem.starts_with(|c: char| c.is_ascii_lowercase()) {
        stem.insert(0, 'n');
    }
    (1..)
        .map(|i| {
            if i == 1 {
                stem.clone()
            } else {
                format!("{stem}{i}")
            }
        })
        .find(|id| f.node(id).is_none())
        .unwrap_or(stem)
}

#[derive(Deserialize)]
struct RemoveBody {
    id: String,
}

fn remove(studio: &Studio, call: &Call) -> Result<Result<u64, Refused>, String> {
    let b: RemoveBody = body(call)?;
    Ok(studio.edit(true, |f| {
        if f.node(&b.id).is_none() {
            return Err(format!("no node `{}`", b.id));
        }
        f.nodes.retain(|(id, _)| *id != b.id);
        let prefix = format!("{}.", b.id);
        for (_, d) in &mut f.nodes {
            d.inputs.retain(|_, from| !from.starts_with(&prefix));
        }
        Ok(())
    }))
}

#[derive(Deserialize)]
struct ConnectBody {
    node: String,
    port: String,
    /// `node.port`, or null to disconnect.
    from: Option<String>,
}

fn connect(studio: &Studio, call: &Call) -> Result<Result<u64, Refused>, String> {
    let b: ConnectBody = body(call)?;
    Ok(studio.edit(true, |f| {
        let decl = f
            .node_mut(&b.node)
            .ok_or_else(|| format!("no node `{}`", b.node))?;
        match b.from {
            Some(from) => {
                decl.inputs.insert(b.port.clone(), from);
            }
            None => {
                decl.inputs.remove(&b.port);
            }
        }
        Ok(())
    }))
}

fn state(studio: &Studio) -> Value {
    let doc = studio.doc();
    let reg = studio.engine.registry();
    // A graph node is one box: its exposed ports and parameters, and the nodes inside it (by
    // their path in the report) for its status and its panel.
    let faces = mesoflow_graph::subgraph::faces(&doc.file);
    let nodes: Vec<Value> = doc
        .file
        .nodes
        .iter()
        .map(|(id, d)| {
            if let Some(face) = faces.get(id) {
                let type_of = |r: &str| -> String {
                    let p = PortRef::parse(r);
                    p.as_ref()
                        .and_then(|p| face.decls.get(&p.node))
                        .and_then(|d| reg.node(&d.kind))
                        .and_then(|n| n.signature().output(&p.as_ref()?.port).map(|o| o.ty.clone()))
                        .unwrap_or_default()
                };
                let outputs: Vec<Value> = face
                    .outputs
                    .iter()
                    .map(|(name, r)| json!({ "name": name, "type": type_of(r), "doc": format!("{r} inside"), "inside": r }))
                    .collect();
                let ports: Vec<Value> = face
                    .inputs
                    .iter()
                    .map(|name| json!({ "name": name, "type": "", "required": false, "doc": "an exposed input" }))
                    .collect();
                let mut props = serde_json::Map::new();
                props.insert("path".into(), json!({ "type": "string", "description": "the graph file" }));
                for p in &face.params {
                    props.insert(p.clone(), json!({ "description": "an exposed parameter" }));
                }
                // What the box opens onto: each node inside as a node of its own, under its
                // path (in `inner`'s order, the files'), its inputs inside the box by path too.
                let inside: Vec<Value> = face
                    .inner
                    .iter()
                    .filter_map(|i| face.decls.get(i).map(|d| declared(i, d, reg)))
                    .collect();
                return json!({ "id": id, "kind": d.kind, "params": d.params, "inputs": d.inputs,
                    "outputs": outputs, "ports": ports, "timings": [], "inner": face.inner,
                    "inside": inside, "schema": { "type": "object", "properties": props } });
            }
            declared(id, d, reg)
        })
        .collect();
    let errors: Vec<Problem> = doc
        .errors
        .iter()
        .map(Problem::of)
        .chain(doc.blocked.iter().cloned())
        .collect();
    json!({
        "graph": studio.graph_path.display().to_string(),
        "description": doc.file.description,
        "revision": doc.revision,
        "dirty": doc.disk.as_ref() != Some(&doc.file),
        "load_error": doc.load_error,
        "errors": errors,
        "nodes": nodes,
        "report": doc.report,
        "running": studio.running(),
        "clients": studio.hub.clients(),
        "out_dir": studio.out_dir.display().to_string(),
    })
}

/// A node as the page draws it: its declaration and its kind's ports and timings.
fn declared(id: &str, d: &NodeDecl, reg: &mesoflow_runtime::Registry) -> Value {
    let sig = reg.node(&d.kind).map(|n| n.signature());
    json!({ "id": id, "kind": d.kind, "params": d.params, "inputs": d.inputs,
            "outputs": sig.map(|s| json!(s.outputs)).unwrap_or(json!([])),
            "ports": sig.map(|s| json!(s.inputs)).unwrap_or(json!([])),
            "timings": sig.map(|s| json!(s.timings)).unwrap_or(json!([])) })
}

fn target(query: &[(String, String)]) -> Result<PortRef, String> {
    match (q(query, "node"), q(query, "port")) {
        (Some(node), Some(port)) => Ok(PortRef {
            node: node.into(),
            port: port.into(),
        }),
        _ => Err("?node=…&port=… are required".into()),
    }
}

/// A graph node's exposed output is the inner output it names (`p.y` is `p/b.y`).
fn through_subgraphs(studio: &Studio, t: PortRef) -> PortRef {
    mesoflow_graph::subgraph::through(&studio.doc().file, t)
}

/// A value of the current graph, from the caches the runs filled; computed (with what it needs)
/// only when no run has produced it, e.g. an input skipped because its dependants were cached.
fn value(studio: &Studio, t: &PortRef) -> Result<ValueRef, (u16, String)> {
    let graph = studio.doc().checked.clone().ok_or((
        409,
        "the graph has errors; fix them to see values".to_string(),
    ))?;
    let attempt = |cached_only: bool| {
        let mut opts = studio.options(&studio.out_dir, Arc::new(AtomicBool::new(false)));
        opts.outputs = vec![t.clone()];
        if cached_only {
            opts.compute_only = Some(Default::default());
        }
        studio
            .engine
            .run_values(&graph, &opts, Arc::new(SilentObserver))
            .map_err(|e| (404, e.to_string()))
    };
    let mut outcome = attempt(true)?;
    if !outcome.values.contains_key(&t.node) {
        outcome = attempt(false)?;
    }
    if let Some(v) = outcome.values.get(&t.node).and_then(|o| o.get(&t.port)) {
        return Ok(v.clone());
    }
    let why = outcome
        .report
        .node(&t.node)
        .and_then(|n| n.error.clone())
        .unwrap_or_else(|| "no value".into());
    Err((404, format!("{t}: {why}")))
}

fn pixels_response(p: preview::Pixels) -> Reply {
    let mut bytes = Vec::with_capacity(p.data.len() * 4);
    for x in &p.data {
        bytes.extend_from_slice(&x.to_le_bytes());
    }
    Reply::Data {
        status: 200,
        content_type: "application/octet-stream",
        headers: vec![
            ("X-Width", p.width.to_string()),
            ("X-Height", p.height.to_string()),
            ("X-Channels", p.channels.to_string()),
        ],
        body: bytes,
    }
}

/// Whether `path` (resolved against the output folder when relative) lies inside one of the
/// studio's folders, symbolic links and `..` followed.
pub fn allowed(roots: &[PathBuf], out_dir: &Path, path: &str) -> Result<PathBuf, (u16, String)> {
    let p = Path::new(path);
    let full = if p.is_absolute() {
        p.to_path_buf()
    } else {
        out_dir.join(p)
    };
    if !super::session::inside(roots, &full) {
        return Err((
            403,
            format!("{path}: outside the graph's folder, the output folder and the cache"),
        ));
    }
    full.canonicalize()
        .map_err(|_| (404, format!("{path}: no such file")))
}

fn file(studio: &Studio, path: &str) -> Reply {
    let real = match allowed(&studio.roots, &studio.out_dir, path) {
        Ok(p) => p,
        Err((s, m)) => return error(s, &m),
    };
    match read_served(&studio.roots, &real) {
        Ok(bytes) => {
            let ext = real
                .extension()
                .map(|e| e.to_string_lossy().to_ascii_lowercase())
                .unwrap_or_default();
            let ty = match ext.as_str() {
                "png" => "image/png",
                "svg" => "image/svg+xml",
                "jpg" | "jpeg" => "image/jpeg",
                "json" => "application/json",
                "csv" | "txt" => "text/plain; charset=utf-8",
                _ => "application/octet-stream",
            };
            Reply::data(ty, bytes)
        }
        Err((s, m)) => error(s, &format!("{path}: {m}")),
    }
}

/// The most bytes `/api/file` serves: the studio shows pictures, reports and tables.
const MOST_SERVED: u64 = 256 << 20;

/// Reads the file at `real` (checked by [`allowed`]) as the studio serves it: opened without
/// following a link at its last component and without blocking (a FIFO would hold the request
/// forever), a regular file only, at most [`MOST_SERVED`] bytes, and — on Linux, asked of the
/// open file itself — still inside the studio's folders: a link planted in a parent folder
/// between the check and the open is caught when the file is opened.
fn read_served(roots: &[PathBuf], real: &Path) -> Result<Vec<u8>, (u16, String)> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK);
    }
    let f = options.open(real).map_err(|e| (404, e.to_string()))?;
    let meta = f.metadata().map_err(|e| (404, e.to_string()))?;
    if !meta.is_file() {
        return Err((403, "not a regular file".into()));
    }
    if meta.len() > MOST_SERVED {
        return Err((
            413,
            format!(
                "{} bytes, over the {MOST_SERVED} the studio serves",
                meta.len()
            ),
        ));
    }
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        let at = std::fs::read_link(format!("/proc/self/fd/{}", f.as_raw_fd()))
            .map_err(|e| (403, format!("where the open file lies is unknown: {e}")))?;
        if !roots.iter().any(|r| at.starts_with(r)) {
            return Err((
                403,
                "outside the graph's folder, the output folder and the cache once opened".into(),
            ));
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = roots;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    f.take(MOST_SERVED)
        .read_to_end(&mut bytes)
        .map_err(|e| (404, e.to_string()))?;
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn query_strings_are_percent_decoded() {
        let (path, q) = split_url("/api/file?path=a%2Fb%20c.png&token=x+y");
        assert_eq!(path, "/api/file");
        assert_eq!(q[0], ("path".into(), "a/b c.png".into()));
        assert_eq!(q[1], ("token".into(), "x y".into()));
        assert_eq!(split_url("/x?p=%zz%4").1[0].1, "%zz%4");
    }

    #[test]
    fn paths_outside_the_roots_are_refused_even_through_dot_dot() {
        let dir = tempfile::tempdir().expect("temp dir");
        let root = dir.path().join("out");
        std::fs::create_dir_all(&root).expect("mkdir");
        std::fs::write(root.join("a.png"), b"x").expect("write");
        std::fs::write(dir.path().join("secret"), b"x").expect("write");
        let roots = vec![root.canonicalize().expect("canonical")];
        assert!(allowed(&roots, &root, "a.png").is_ok());
        assert_eq!(allowed(&roots, &root, "../secret").unwrap_err().0, 403);
        let abs = dir.path().join("secret").display().to_string();
        assert_eq!(allowed(&roots, &root, &abs).unwrap_err().0, 403);
        assert_eq!(allowed(&roots, &root, "missing.png").unwrap_err().0, 404);
    }
}
