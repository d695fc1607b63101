// mesoflow studio: the page. Plain JavaScript, no build step; it talks to `mesoflow serve`
// through /api (JSON), /api/pixels (raw f32 pixels, tone-mapped here) and /api/events
// (server-sent events). `window.studio` exposes the state for the browser tests.
"use strict";

const TOKEN = new URLSearchParams(location.search).get("token") || "";
const S = {
  state: null, kinds: {}, selected: null, live: {}, progress: {}, run: null, lastRun: null,
  view: { x: 20, y: 20, k: 1 }, preview: { port: null, exposure: 0, srgb: true, zoom: 0,
  against: "", pair: null, viewDir: null, lightDir: null, mdfView: 0, param: 0, xdim: 0,
  ydim: 1, cdim: -1, yaw: 30 }, draws: 0, errorsByField: {}, sweep: null, tab: "node",
  finishedRuns: 0,
};
window.studio = S;

// ---- the server -------------------------------------------------------------------------
function url(path) {
  return path + (path.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(TOKEN);
}
async function getJson(path) {
  const r = await fetch(url(path));
  const body = await r.json().catch(() => ({ error: r.statusText }));
  if (!r.ok) throw Object.assign(new Error(body.error || r.statusText), { status: r.status, body });
  return body;
}
async function post(path, data) {
  const r = await fetch(url(path), { method: "POST", body: JSON.stringify(data || {}),
    headers: { "Content-Type": "application/json" } });
  const body = await r.json().catch(() => ({ error: r.statusText }));
  return { ok: r.ok, status: r.status, body };
}
async function getPixels(node, port, index) {
  const r = await fetch(url(`/api/pixels?node=${node}&port=${port}&index=${index || 0}`));
  if (!r.ok) {
    const b = await r.json().catch(() => ({}));
    throw new Error(b.error || r.statusText);
  }
  const buf = await r.arrayBuffer();
  return { w: +r.headers.get("X-Width"), h: +r.headers.get("X-Height"),
    c: +r.headers.get("X-Channels"), data: new Float32Array(buf) };
}

// ---- small helpers ----------------------------------------------------------------------
const $ = (sel, root = document) => root.querySelector(sel);
function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") e.className = v;
    else if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
    else if (v !== undefined && v !== null && v !== false) e.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children.flat()) if (c !== null && c !== undefined)
    e.append(c instanceof Node ? c : document.createTextNode(String(c)));
  return e;
}
const SVGNS = "http://www.w3.org/2000/svg";
function sv(tag, attrs = {}, ...children) {
  const e = document.createElementNS(SVGNS, tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
    else if (v !== undefined && v !== null) e.setAttribute(k, v);
  }
  for (const c of children.flat()) if (c !== null && c !== undefined)
    e.append(c instanceof Node ? c : document.createTextNode(String(c)));
  return e;
}
function bytes(n) {
  if (n == null) return "";
  const u = ["B", "KiB", "MiB", "GiB"]; let i = 0;
  while (n >= 1024 && i < u.length - 1) { n /= 1024; i++; }
  return (i ? n.toFixed(1) : n) + " " + u[i];
}
function secs(s) { return s == null ? "" : s < 0.01 ? (s * 1000).toFixed(1) + " ms" : s.toFixed(2) + " s"; }
function fmt(x) {
  if (x == null || Number.isNaN(x)) return "—";
  if (typeof x !== "number") return String(x);
  const a = Math.abs(x);
  return a !== 0 && (a < 1e-3 || a >= 1e5) ? x.toExponential(3) : +x.toPrecision(5) + "";
}
function node(id) { return S.state && S.state.nodes.find(n => n.id === id); }
function reportOf(id) {
  const r = S.state && S.state.report;
  return r ? r.nodes.find(n => n.id === id) : null;
}

// ---- state and events -------------------------------------------------------------------
async function loadState() {
  // A run that finishes while /api/state is in flight must not be undone by the older answer
  // (it said `running`, and no later event would say otherwise): ask again until no run
  // finished meanwhile.
  for (;;) {
    const finished = S.finishedRuns;
    const state = await getJson("/api/state");
    if (S.finishedRuns === finished) { S.state = state; break; }
  }
  const r = S.state.report;
  if (r && !$("#status-line").textContent) {
    const computed = r.nodes.filter(n => n.status === "computed").map(n => n.id);
    $("#status-line").textContent = `last run: computed ${computed.join(", ") || "nothing"} in ${secs(r.seconds)}`;
  }
  if (S.selected && !node(S.selected)) S.selected = null;
  renderAll();
}
function connect() {
  const es = new EventSource(url("/api/events"));
  es.onopen = () => loadState();
  es.onerror = () => setRunState("disconnected", "failed");
  const on = (type, f) => es.addEventListener(type, e => f(JSON.parse(e.data)));
  on("graph", () => loadState());
  on("saved", () => loadState());
  on("run_started", e => {
    S.run = e.run; S.live = {}; S.progress = {};
    setRunState(`run ${e.run} running…`, "running");
    drawGraph();
  });
  on("node_started", e => { S.live[e.id] = "running"; drawGraph(); });
  on("progress", e => { S.progress[e.id] = e.total ? e.done / e.total : 0; drawGraph(); });
  on("node_finished", e => {
    S.live[e.node.id] = e.node.status;
    if (S.state && S.state.report) {
      const nodes = S.state.report.nodes.filter(n => n.id !== e.node.id);
      nodes.push(e.node);
      S.state.report.nodes = nodes;
    }
    drawGraph();
  });
  on("run_skipped", e => setRunState(`run ${e.run} not started: ${e.reason}`, "invalid"));
  on("run_finished", e => {
    S.finishedRuns += 1;
    if (e.error) { setRunState(`run ${e.run}: ${e.error}`, "failed"); return; }
    S.lastRun = { run: e.run, revision: e.revision, ok: e.ok, cancelled: e.cancelled, reran: e.reran };
    S.live = {}; S.progress = {};
    if (S.state) { S.state.report = e.report; S.state.running = false; }
    const what = e.cancelled ? "cancelled (a newer change)" :
      `re-ran ${e.reran.length ? e.reran.join(", ") : "nothing"} in ${secs(e.report.seconds)}`;
    setRunState(`run ${e.run} ${e.ok ? "ok" : "FAILED"}`, e.ok ? "ok" : "failed");
    $("#status-line").textContent = `run ${e.run}: ${what}`;
    $("#status-line").dataset.run = e.run;
    $("#status-line").dataset.reran = e.reran.join(",");
    drawGraph();
    renderReport();
    if (!e.cancelled) refreshPreview();
  });
  on("sweep_started", e => { S.sweep = { id: e.sweep, total: e.total, rows: [], charts: [], running: true }; renderSweepResults(); });
  on("sweep_row", e => { if (S.sweep && S.sweep.id === e.sweep) { S.sweep.rows.push(e.row); renderSweepResults(); } });
  on("sweep_done", e => {
    if (S.sweep && S.sweep.id === e.sweep) {
      Object.assign(S.sweep, { running: false, charts: e.charts, csv: e.csv, error: e.error });
      renderSweepResults();
    }
  });
}
function setRunState(text, cls) {
  const p = $("#run-state");
  p.textContent = text; p.className = "pill " + (cls || "");
}

// ---- rendering --------------------------------------------------------------------------
function renderAll() {
  const st = S.state;
  $("#graph-name").textContent = st.graph + (st.dirty ? " (edited, not saved)" : "");
  $("#save-button").disabled = !st.dirty;
  $("#save-button").classList.toggle("primary", st.dirty);
  const errs = $("#errors");
  const msgs = [st.load_error, ...st.errors.map(e => e.message)].filter(Boolean);
  errs.hidden = msgs.length === 0;
  errs.textContent = [...new Set(msgs)].join("\n");
  if (msgs.length) setRunState(`${msgs.length} error${msgs.length > 1 ? "s" : ""}`, "invalid");
  else if (st.running) setRunState("running…", "running");
  else if (st.report) setRunState(st.report.ok ? "ok" : "failed", st.report.ok ? "ok" : "failed");
  drawGraph();
  renderNode();
  renderCompose();
  renderSweepForm();
  renderReport();
  refreshPreview();
}

// Layers by longest path from the sources, ordered within a layer by their parents' positions.
function layout(nodes) {
  const depth = {}, byId = Object.fromEntries(nodes.map(n => [n.id, n]));
  const visit = (id, seen = new Set()) => {
    if (depth[id] !== undefined) return depth[id];
    if (seen.has(id)) return 0;
    seen.add(id);
    const n = byId[id];
    let d = 0;
    for (const src of Object.values(n ? n.inputs : {})) {
      const p = src.split(".")[0];
      if (byId[p]) d = Math.max(d, visit(p, seen) + 1);
    }
    return (depth[id] = d);
  };
  nodes.forEach(n => visit(n.id));
  const layers = [];
  nodes.forEach(n => (layers[depth[n.id]] = layers[depth[n.id]] || []).push(n));
  const pos = {}, W = 210, GAP = 70;
  layers.forEach((layer, li) => {
    layer.forEach((n, i) => {
      const parents = Object.values(n.inputs).map(s => pos[s.split(".")[0]]).filter(Boolean);
      n._order = parents.length ? parents.reduce((a, p) => a + p.y, 0) / parents.length : i * 100;
    });
    layer.sort((a, b) => a._order - b._order);
    let y = 0;
    for (const n of layer) {
      const h = 68 + 15 * Math.max(n.ports.length, n.outputs.length);
      pos[n.id] = { x: li * (W + GAP), y, w: W, h };
      y += h + 22;
    }
  });
  return pos;
}

function statusOf(id) {
  if (S.live[id]) return S.live[id];
  const r = reportOf(id);
  if (r) return r.status;
  const rep = S.state && S.state.report;
  return rep && rep.skipped.includes(id) ? "skipped" : "stale";
}

function drawGraph() {
  if (!S.state) return;
  const vp = $("#viewport");
  vp.replaceChildren();
  const nodes = S.state.nodes;
  const pos = layout(nodes);
  S.positions = pos;
  const portY = (p, i) => p.y + 64 + 15 * i;
  for (const n of nodes) {
    n.ports.forEach((port, i) => {
      const src = n.inputs[port.name];
      if (!src) return;
      const [sid, sport] = src.split(".");
      const s = node(sid), sp = pos[sid];
      if (!s || !sp) return;
      const oi = Math.max(0, s.outputs.findIndex(o => o.name === sport));
      const x1 = sp.x + sp.w, y1 = portY(sp, oi), x2 = pos[n.id].x, y2 = portY(pos[n.id], i);
      const dx = Math.max(40, (x2 - x1) / 2);
      vp.append(sv("path", { class: "edge" + (S.selected === n.id || S.selected === sid ? " hot" : ""),
        d: `M${x1},${y1} C${x1 + dx},${y1} ${x2 - dx},${y2} ${x2},${y2}` }));
    });
  }
  for (const n of nodes) {
    const p = pos[n.id], status = statusOf(n.id), r = reportOf(n.id);
    const hasError = S.state.errors.some(e => e.node === n.id);
    const g = sv("g", { class: `node ${status}${S.selected === n.id ? " selected" : ""}${hasError ? " failed" : ""}`,
      "data-id": n.id, "data-status": status, transform: `translate(${p.x},${p.y})`,
      onclick: ev => { ev.stopPropagation(); select(n.id); } });
    g.append(sv("rect", { class: "body", width: p.w, height: p.h, rx: 6 }));
    g.append(sv("text", { class: "title", x: 10, y: 18 }, n.id));
    g.append(sv("text", { class: "kind", x: 10, y: 32 }, n.kind));
    const stats = r ? `${status} · ${secs(r.seconds)} · ${bytes(r.bytes)}` :
      status === "skipped" ? "not needed: its dependants were cached" : "not run yet";
    g.append(sv("text", { class: "stats", x: 10, y: 45 }, stats));
    n.ports.forEach((port, i) => {
      g.append(sv("circle", { class: "pin", cx: 0, cy: 64 + 15 * i, r: 3.5 }));
      g.append(sv("text", { class: "port", x: 8, y: 68 + 15 * i }, port.name));
    });
    n.outputs.forEach((o, i) => {
      g.append(sv("circle", { class: "pin", cx: p.w, cy: 64 + 15 * i, r: 3.5 }));
      g.append(sv("text", { class: "port", x: p.w - 8, y: 68 + 15 * i, "text-anchor": "end" }, o.name));
    });
    if (status === "running") {
      const f = S.progress[n.id] || 0;
      g.append(sv("rect", { class: "bar-bg", x: 8, y: p.h - 7, width: p.w - 16, height: 3 }));
      g.append(sv("rect", { class: "bar", x: 8, y: p.h - 7, width: (p.w - 16) * f, height: 3 }));
    }
    vp.append(g);
  }
  if (!S.fitted) fitView();
  applyView();
}
// Scales and moves the graph so that all of it is in sight (at most life size).
function fitView() {
  const box = $("#graph").getBoundingClientRect(), ps = Object.values(S.positions || {});
  if (!ps.length || !box.width) return;
  const w = Math.max(...ps.map(p => p.x + p.w)), h = Math.max(...ps.map(p => p.y + p.h));
  const k = Math.min(1, (box.width - 40) / w, (box.height - 50) / h);
  S.view = { k, x: 20, y: 20 };
  S.fitted = true;
}
function applyView() {
  $("#viewport").setAttribute("transform", `translate(${S.view.x},${S.view.y}) scale(${S.view.k})`);
}
function setupPanZoom() {
  const svg = $("#graph");
  let drag = null;
  svg.addEventListener("mousedown", e => { drag = { x: e.clientX, y: e.clientY, vx: S.view.x, vy: S.view.y }; svg.classList.add("panning"); });
  window.addEventListener("mousemove", e => {
    if (!drag) return;
    S.view.x = drag.vx + e.clientX - drag.x; S.view.y = drag.vy + e.clientY - drag.y; applyView();
  });
  window.addEventListener("mouseup", () => { drag = null; svg.classList.remove("panning"); });
  svg.addEventListener("wheel", e => {
    e.preventDefault();
    const r = svg.getBoundingClientRect(), mx = e.clientX - r.left, my = e.clientY - r.top;
    const k = Math.min(3, Math.max(0.2, S.view.k * Math.exp(-e.deltaY * 0.0015)));
    S.view.x = mx - (mx - S.view.x) * k / S.view.k; S.view.y = my - (my - S.view.y) * k / S.view.k;
    S.view.k = k; applyView();
  }, { passive: false });
  svg.addEventListener("dblclick", () => { fitView(); applyView(); });
}

function select(id) {
  if (S.selected !== id) { S.preview.port = null; S.preview.pair = null; }
  S.selected = id;
  drawGraph();
  renderNode();
  refreshPreview();
}

function showTab(name) {
  S.tab = name;
  document.querySelectorAll("#tabs button").forEach(b => b.classList.toggle("active", b.dataset.tab === name));
  document.querySelectorAll(".tab").forEach(t => t.classList.toggle("active", t.id === "tab-" + name));
  if (name === "preview") refreshPreview();
}

// ---- parameters from the kind's JSON Schema ---------------------------------------------
function resolve(schema, root) {
  let s = schema || {}, guard = 0;
  while (s.$ref && guard++ < 10) s = (root.$defs || root.definitions || {})[s.$ref.split("/").pop()] || {};
  if (s.allOf && s.allOf.length === 1) s = Object.assign({}, resolve(s.allOf[0], root), s, { allOf: undefined });
  return s;
}
function choices(s) {
  if (s.enum) return s.enum.map(v => ({ value: v, doc: "" }));
  const alts = s.oneOf || s.anyOf;
  if (alts && alts.every(a => a.const !== undefined || (a.enum && a.enum.length === 1)))
    return alts.map(a => ({ value: a.const !== undefined ? a.const : a.enum[0], doc: a.description || "" }));
  return null;
}
function typeOf(s) {
  const t = Array.isArray(s.type) ? s.type.filter(x => x !== "null") : [s.type];
  return { t: t[0], nullable: Array.isArray(s.type) && s.type.includes("null") };
}

function paramField(nodeId, path, schema, value, root) {
  const s = resolve(schema, root);
  const key = path[path.length - 1];
  const param = path.join(".");
  const doc = schema.description || s.description || "";
  const v = value !== undefined ? value : (schema.default !== undefined ? schema.default : s.default);
  const { t, nullable } = typeOf(s);
  if (t === "object" && s.properties) {
    const fs = el("fieldset", { "data-param": param }, el("legend", { title: doc }, key));
    for (const [k, sub] of Object.entries(s.properties))
      fs.append(paramField(nodeId, [...path, k], sub, v ? v[k] : undefined, root));
    return fs;
  }
  const field = el("div", { class: "field", "data-field": param });
  const errBox = el("div", { class: "param-error", "data-param": param });
  const send = async raw => {
    const res = await post("/api/set", { node: nodeId, param, value: raw });
    if (res.ok) { S.editRevision = res.body.revision; field.classList.remove("invalid"); errBox.textContent = ""; delete S.errorsByField[param]; }
    else {
      field.classList.add("invalid");
      errBox.textContent = (res.body.errors || [res.body]).map(e => e.message || e.error).join("\n");
      S.errorsByField[param] = errBox.textContent;
    }
  };
  field.append(el("label", { title: doc }, key));
  const opts = choices(s);
  if (opts) {
    const sel = el("select", { "data-param": param, onchange: e => send(opts[e.target.selectedIndex].value) },
      opts.map(o => el("option", { title: o.doc, selected: JSON.stringify(o.value) === JSON.stringify(v) }, String(o.value))));
    field.append(sel);
  } else if (t === "boolean") {
    field.append(el("input", { type: "checkbox", "data-param": param, checked: !!v, onchange: e => send(e.target.checked) }));
  } else if (t === "integer" || t === "number") {
    const lo = s.minimum ?? s.exclusiveMinimum, hi = s.maximum ?? s.exclusiveMaximum;
    const num = el("input", { type: "number", "data-param": param, value: v ?? "",
      step: t === "integer" ? 1 : "any", placeholder: nullable ? "default" : "",
      onchange: e => send(e.target.value === "" ? null : Number(e.target.value)) });
    if (lo !== undefined && hi !== undefined && hi - lo <= 10000 && hi > lo) {
      const range = el("input", { type: "range", min: lo, max: hi, step: t === "integer" ? 1 : (hi - lo) / 500,
        value: v ?? lo, "data-slider": param,
        oninput: e => (num.value = e.target.value), onchange: e => send(Number(e.target.value)) });
      field.append(range, " ");
    }
    field.append(num);
  } else if (t === "string") {
    field.append(el("input", { type: "text", "data-param": param, value: v ?? "", onchange: e => send(e.target.value) }));
  } else {
    field.append(el("input", { type: "text", "data-param": param, value: JSON.stringify(v ?? null),
      onchange: e => { let x; try { x = JSON.parse(e.target.value); } catch { x = e.target.value; } send(x); } }));
  }
  if (doc) field.append(el("div", { class: "hint" }, doc));
  if (S.errorsByField[param]) { field.classList.add("invalid"); errBox.textContent = S.errorsByField[param]; }
  field.append(errBox);
  return field;
}

function renderNode() {
  const box = $("#tab-node");
  const n = S.selected && node(S.selected);
  // Rebuilt only when what it shows changed, so an edit's echo does not take the focus away.
  const shown = JSON.stringify(n ? [n.id, n.kind, n.params, n.inputs, S.state.errors.filter(e => e.node === n.id),
    (reportOf(n.id) || {}).error, S.state.nodes.map(m => m.id)] : null);
  if (box.dataset.shown === shown) return;
  box.dataset.shown = shown;
  box.replaceChildren();
  if (!n) { box.append(el("p", { class: "muted" }, "Select a node in the graph.")); return; }
  const sig = S.kinds[n.kind];
  box.append(el("h2", {}, n.id), el("div", { class: "doc" }, n.kind + (sig ? " — " + sig.doc : " (unknown kind)")));
  const errs = S.state.errors.filter(e => e.node === n.id);
  if (errs.length) box.append(el("div", { class: "error-box" }, errs.map(e => e.message).join("\n")));
  const r = reportOf(n.id);
  if (r && r.error) box.append(el("div", { class: "error-box" }, r.error));
  box.append(el("h3", {}, "Inputs"));
  if (!n.ports.length) box.append(el("div", { class: "muted" }, "none"));
  for (const port of n.ports) {
    const types = String(port.type).split("|");
    const sources = S.state.nodes.filter(m => m.id !== n.id).flatMap(m => m.outputs
      .filter(o => types.includes(o.type)).map(o => `${m.id}.${o.name}`));
    const cur = n.inputs[port.name] || "";
    const errBox = el("div", { class: "param-error", "data-input": port.name });
    const sel = el("select", { "data-input": port.name, onchange: async e => {
      const res = await post("/api/connect", { node: n.id, port: port.name, from: e.target.value || null });
      if (res.ok) S.editRevision = res.body.revision;
      errBox.textContent = res.ok ? "" : (res.body.errors || []).map(x => x.message).join("\n");
    } }, el("option", { value: "" }, port.required ? "— (required)" : "—"),
      sources.map(s => el("option", { value: s, selected: s === cur }, s)));
    box.append(el("div", { class: "field" }, el("label", { title: port.doc }, `${port.name}: ${port.type}`), sel, errBox));
  }
  box.append(el("h3", {}, "Parameters"));
  if (sig) {
    const root = sig.params, props = root.properties || {};
    if (!Object.keys(props).length) box.append(el("div", { class: "muted" }, "none"));
    for (const [k, s] of Object.entries(props)) box.append(paramField(n.id, [k], s, n.params[k], root));
  }
  box.append(el("h3", {}, "Node"),
    el("button", { "data-action": "remove", onclick: async () => {
      const res = await post("/api/remove", { id: n.id });
      if (res.ok) S.selected = null;
    } }, `Remove ${n.id}`));
}

// ---- composing: add nodes -----------------------------------------------------------------
function renderCompose() {
  const box = $("#tab-compose");
  if (box.dataset.built) return;
  box.dataset.built = "1";
  const kinds = Object.keys(S.kinds).sort();
  const kindSel = el("select", { id: "add-kind" }, kinds.map(k => el("option", { value: k, title: S.kinds[k].doc }, k)));
  const idBox = el("input", { type: "text", id: "add-id", placeholder: "id (optional)" });
  const doc = el("div", { class: "doc" });
  const msg = el("div", { class: "param-error", id: "add-error" });
  const showDoc = () => { const k = S.kinds[kindSel.value]; doc.textContent = k ? k.doc : ""; };
  kindSel.addEventListener("change", showDoc);
  showDoc();
  box.append(el("h2", {}, "Add a node"),
    el("div", { class: "doc" }, "New nodes start unconnected; connect their inputs in the Node tab (only outputs of a matching type are offered, and the server checks again)."),
    el("div", { class: "row" }, kindSel), doc, el("div", { class: "row" }, idBox,
      el("button", { id: "add-button", onclick: async () => {
        const res = await post("/api/add", { kind: kindSel.value, id: idBox.value || null });
        msg.textContent = res.ok ? "" : (res.body.errors || []).map(x => x.message).join("\n");
        if (res.ok) { idBox.value = ""; await loadState(); select(S.state.nodes[S.state.nodes.length - 1].id); showTab("node"); }
      } }, "Add")), msg);
}

// ---- previews ---------------------------------------------------------------------------
let previewToken = 0;
async function refreshPreview() {
  const box = $("#tab-preview");
  const n = S.selected && node(S.selected);
  const mine = ++previewToken;
  if (!n) { box.replaceChildren(el("p", { class: "muted" }, "Select a node to see its outputs.")); return; }
  if (!S.preview.port || !n.outputs.some(o => o.name === S.preview.port)) S.preview.port = n.outputs.length ? n.outputs[0].name : null;
  // Drawn again only when the value may differ: another node or port, or a new key after a run.
  const r = reportOf(n.id);
  const key = `${n.id}.${S.preview.port}.${r ? r.key + r.status : ""}.${S.state.errors.length}`;
  if (key === S.previewKey && box.childElementCount) return;
  S.previewKey = key;
  const head = el("div", { class: "preview-tabs" }, n.outputs.map(o => el("button", {
    class: o.name === S.preview.port ? "active" : "", "data-port": o.name,
    onclick: () => { S.preview.port = o.name; S.preview.pair = null; S.previewKey = null; refreshPreview(); } }, `${o.name}: ${o.type}`)));
  const body = el("div", { id: "preview-body" });
  const frag = [el("h2", {}, n.id), head, body, metricsTable(n.id)];
  if (!S.preview.port) { box.replaceChildren(...frag); body.append(el("p", { class: "muted" }, "no outputs")); return; }
  let meta;
  try { meta = await getJson(`/api/value?node=${n.id}&port=${S.preview.port}`); }
  catch (e) {
    if (mine !== previewToken) return;
    box.replaceChildren(...frag); body.append(el("div", { class: "error-box" }, e.message)); return;
  }
  if (mine !== previewToken) return;
  box.replaceChildren(...frag);
  body.dataset.view = meta.view;
  body.append(el("div", { class: "caption" }, `${meta.type} · ${bytes(meta.bytes)}`));
  const views = { scalar: viewScalar, image: viewImage, normals: viewImage, height: viewHeight,
    btf: viewBtf, mdf: viewMdf, brdfmap: viewBrdfMap, profile: viewProfile, points: viewPoints,
    mesh: viewMesh, table: viewTable, files: viewFiles };
  const f = views[meta.view];
  if (f) await f(body, n, meta);
  else body.append(el("p", { class: "muted" }, `no preview for ${meta.type}`));
}

function metricsTable(id) {
  const r = reportOf(id);
  if (!r) return el("p", { class: "muted" }, "not in the last run");
  const rows = [["status", r.status], ["device", r.device], ["seconds", secs(r.seconds)], ["bytes", bytes(r.bytes)]];
  for (const [k, v] of Object.entries(r.metrics || {})) rows.push([k, fmt(v)]);
  for (const [k, v] of Object.entries(r.timings || {})) rows.push([k + " (timing)", fmt(v)]);
  return el("div", {}, el("h3", {}, "Metrics"), el("table", { class: "data", id: "metrics" },
    rows.map(([k, v]) => el("tr", {}, el("td", {}, k), el("td", { class: "num" }, v)))));
}

const srgb = x => x <= 0.0031308 ? 12.92 * x : 1.055 * Math.pow(x, 1 / 2.4) - 0.055;
// Draws f32 pixels: × 2^exposure, sRGB-encoded unless linear, clamped. `map` overrides per pixel.
function paint(canvas, px, opts = {}) {
  const { w, h, c, data } = px;
  canvas.width = w; canvas.height = h;
  const ctx = canvas.getContext("2d");
  const img = ctx.createImageData(w, h);
  const gain = Math.pow(2, opts.exposure || 0), enc = opts.srgb === false ? (x => x) : srgb;
  for (let i = 0; i < w * h; i++) {
    let rgb;
    if (opts.map) rgb = opts.map(i);
    else if (c === 1) { const v = data[i]; rgb = [v, v, v]; }
    else rgb = [data[i * c], data[i * c + Math.min(1, c - 1)], data[i * c + Math.min(2, c - 1)]];
    for (let k = 0; k < 3; k++) {
      let v = rgb[k];
      if (!opts.map || opts.tone) v = enc(Math.max(0, v * gain));
      img.data[i * 4 + k] = Number.isFinite(v) ? Math.max(0, Math.min(255, Math.round(v * 255))) : 0;
    }
    img.data[i * 4 + 3] = 255;
  }
  ctx.putImageData(img, 0, 0);
  const z = S.preview.zoom;
  // "fit": as wide as its frame, pixels still square and unsmoothed.
  canvas.style.width = z ? w * z + "px" : "100%"; canvas.style.height = z ? h * z + "px" : "auto";
  S.draws++;
  canvas.dataset.draws = S.draws;
}

function toneControls(onChange, extra = []) {
  const p = S.preview;
  return el("div", { class: "controls" },
    el("label", {}, "exposure ", el("input", { type: "range", min: -8, max: 8, step: 0.25, value: p.exposure, id: "exposure",
      oninput: e => { p.exposure = +e.target.value; e.target.nextSibling.textContent = ` ${p.exposure >= 0 ? "+" : ""}${p.exposure}`; onChange(); } }),
      ` ${p.exposure >= 0 ? "+" : ""}${p.exposure}`),
    el("label", {}, el("input", { type: "checkbox", checked: p.srgb, id: "srgb",
      onchange: e => { p.srgb = e.target.checked; onChange(); } }), " sRGB"),
    el("label", {}, "zoom ", el("select", { id: "zoom", onchange: e => { p.zoom = +e.target.value; onChange(); } },
      [0, 1, 2, 4, 8, 16].map(z => el("option", { value: z, selected: z === p.zoom }, z ? z + "×" : "fit")))),
    ...extra);
}

async function viewImage(body, n, meta) {
  const p = S.preview;
  const px = await getPixels(n.id, p.port, 0);
  const normals = meta.view === "normals";
  const others = S.state.nodes.flatMap(m => m.outputs.filter(o => o.type === "Image" && !(m.id === n.id && o.name === p.port))
    .map(o => `${m.id}.${o.name}`));
  const canvas = el("canvas", { id: "preview-canvas" });
  const info = el("div", { class: "caption" });
  let other = null;
  const draw = () => {
    if (other && other.w === px.w && other.h === px.h) {
      // Signed difference, this − other: red where brighter, blue where darker.
      let se = 0;
      const c = px.c, oc = other.c;
      paint(canvas, px, { tone: false, map: i => {
        let d = 0;
        for (let k = 0; k < 3; k++) d += (px.data[i * c + Math.min(k, c - 1)] - other.data[i * oc + Math.min(k, oc - 1)]) / 3;
        se += d * d;
        const v = Math.min(1, Math.abs(d) * Math.pow(2, p.exposure) * 4);
        return d >= 0 ? [v, v * 0.25, v * 0.1] : [v * 0.1, v * 0.35, v];
      } });
      info.textContent = `difference ${n.id}.${p.port} − ${p.against}: RMSE ${fmt(Math.sqrt(se / (px.w * px.h)))} (red: brighter, blue: darker; ×4·2^exposure)`;
    } else {
      paint(canvas, px, normals ? { tone: false, map: i => [0, 1, 2].map(k => px.data[i * 3 + k] * 0.5 + 0.5) } : p);
      info.textContent = `${px.w}×${px.h}, ${px.c} channel${px.c > 1 ? "s" : ""}` + (meta.peak !== undefined ? `, peak ${fmt(meta.peak)}` : "") +
        (other ? ` (the other image is ${other.w}×${other.h}: no difference)` : "");
    }
  };
  const against = el("label", {}, "difference with ", el("select", { id: "against", onchange: async e => {
    p.against = e.target.value; other = null;
    if (p.against) { const [a, b] = p.against.split("."); other = await getPixels(a, b, 0); }
    draw();
  } }, el("option", { value: "" }, "—"), others.map(o => el("option", { value: o, selected: o === p.against }, o))));
  if (p.against && others.includes(p.against)) { const [a, b] = p.against.split("."); other = await getPixels(a, b, 0).catch(() => null); }
  body.append(toneControls(draw, normals ? [] : [against]), el("div", { class: "frame" }, canvas), info);
  draw();
}

async function viewHeight(body, n, meta) {
  const px = await getPixels(n.id, S.preview.port, 0);
  const lo = meta.min, span = Math.max(1e-12, meta.max - meta.min);
  const grey = el("canvas", { id: "preview-canvas" }), relief = el("canvas", { id: "relief-canvas" });
  const at = (x, y) => px.data[((y + px.h) % px.h) * px.w + ((x + px.w) % px.w)];
  const draw = () => {
    paint(grey, px, { tone: false, map: i => { const v = (px.data[i] - lo) / span; return [v, v, v]; } });
    // Shaded relief: Lambert under a light from the upper left, 45° up; heights in texels.
    const L = [-0.5, -0.5, 0.7071];
    paint(relief, px, { tone: false, map: i => {
      const x = i % px.w, y = Math.floor(i / px.w);
      const dx = (at(x + 1, y) - at(x - 1, y)) / 2, dy = (at(x, y + 1) - at(x, y - 1)) / 2;
      const len = Math.hypot(dx, dy, 1);
      const s = Math.max(0, (-dx * L[0] - dy * L[1] + L[2]) / len);
      return [0.08 + 0.85 * s, 0.08 + 0.83 * s, 0.1 + 0.78 * s];
    } });
  };
  body.append(el("div", { class: "controls" }, el("label", {}, "zoom ", el("select", { id: "zoom", onchange: e => { S.preview.zoom = +e.target.value; draw(); } },
    [0, 1, 2, 4, 8].map(z => el("option", { value: z, selected: z === S.preview.zoom }, z ? z + "×" : "fit"))))),
  el("div", { class: "pair" }, el("div", {}, el("div", { class: "frame" }, grey), el("div", { class: "caption" }, `heights ${fmt(meta.min)} … ${fmt(meta.max)} texels`)),
    el("div", {}, el("div", { class: "frame" }, relief), el("div", { class: "caption" }, "shaded relief"))));
  draw();
}

// A hemisphere seen from above: θ is the distance from the centre (orthographic: sin θ), φ the angle.
function hemisphere(role, dirs, chosen, onPick) {
  const R = 90, svg = sv("svg", { class: "hemisphere", width: 2 * R + 12, height: 2 * R + 12, "data-role": role,
    viewBox: `${-R - 6} ${-R - 6} ${2 * R + 12} ${2 * R + 12}` });
  for (const t of [30, 60, 90]) svg.append(sv("circle", { r: R * Math.sin(t * Math.PI / 180), fill: "none", stroke: "#2b3039" }));
  dirs.forEach((d, i) => {
    const r = R * Math.sin(d[0] * Math.PI / 180), a = d[1] * Math.PI / 180;
    const c = sv("circle", { class: "dir" + (i === chosen ? " chosen" : ""), cx: r * Math.cos(a), cy: -r * Math.sin(a), r: 5,
      "data-index": i, "data-theta": Math.round(d[0] * 1000) / 1000, "data-phi": Math.round(d[1] * 1000) / 1000, onclick: () => onPick(i) });
    c.append(sv("title", {}, `θ ${fmt(d[0])}°, φ ${fmt(d[1])}°`));
    svg.append(c);
  });
  return el("div", {}, svg, el("div", { class: "caption" }, `${role} direction (centre: θ 0°; φ 0° to the right)`));
}
function uniqueDirs(list) {
  const out = [];
  for (const d of list) if (!out.some(o => Math.abs(o[0] - d[0]) < 1e-6 && (Math.abs(o[1] - d[1]) < 1e-6 || d[0] < 1e-6 && o[0] < 1e-6))) out.push(d);
  return out;
}
function angle(a, b) {
  const v = d => { const t = d[0] * Math.PI / 180, p = d[1] * Math.PI / 180; return [Math.sin(t) * Math.cos(p), Math.sin(t) * Math.sin(p), Math.cos(t)]; };
  const x = v(a), y = v(b);
  return Math.acos(Math.max(-1, Math.min(1, x[0] * y[0] + x[1] * y[1] + x[2] * y[2])));
}

async function viewBtf(body, n, meta) {
  const p = S.preview;
  const views = uniqueDirs(meta.pairs.map(q => [q[0], q[1]])), lights = uniqueDirs(meta.pairs.map(q => [q[2], q[3]]));
  if (p.viewDir === null || p.viewDir >= views.length) p.viewDir = 0;
  if (p.lightDir === null || p.lightDir >= lights.length) p.lightDir = Math.min(lights.length - 1, Math.floor(lights.length / 3));
  const canvas = el("canvas", { id: "preview-canvas" });
  const label = el("div", { class: "caption", id: "btf-pair" });
  const pick = () => {
    const v = views[p.viewDir], l = lights[p.lightDir];
    let best = 0, bestD = Infinity;
    meta.pairs.forEach((q, i) => { const d = angle(v, [q[0], q[1]]) + angle(l, [q[2], q[3]]); if (d < bestD) { bestD = d; best = i; } });
    return best;
  };
  let px = null;
  const draw = () => px && paint(canvas, px, p);
  const load = async () => {
    p.pair = pick();
    const q = meta.pairs[p.pair];
    label.textContent = `pair ${p.pair} of ${meta.pairs.length}: view θ ${fmt(q[0])}° φ ${fmt(q[1])}°, light θ ${fmt(q[2])}° φ ${fmt(q[3])}°` +
      (meta.ranks ? ` · reconstructed from rank ${meta.ranks.join("/")}` : "");
    label.dataset.pair = p.pair;
    hemis.replaceChildren(hemisphere("view", views, p.viewDir, i => { p.viewDir = i; load(); }),
      hemisphere("light", lights, p.lightDir, i => { p.lightDir = i; load(); }));
    px = await getPixels(n.id, p.port, p.pair);
    draw();
  };
  const hemis = el("div", { class: "row", id: "btf-browser" });
  body.append(hemis, toneControls(draw), el("div", { class: "frame" }, canvas), label);
  await load();
}

async function viewMdf(body, n, meta) {
  const p = S.preview;
  if (p.mdfView >= meta.views.length) p.mdfView = 0;
  const canvas = el("canvas", { id: "preview-canvas" }), label = el("div", { class: "caption", id: "mdf-view" });
  const hemis = el("div", { class: "row" });
  const load = async () => {
    hemis.replaceChildren(hemisphere("view", meta.views, p.mdfView, i => { p.mdfView = i; load(); }));
    const px = await getPixels(n.id, p.port, p.mdfView);
    const scale = Math.max(1e-6, meta.depth * 4);
    paint(canvas, px, { tone: false, map: i => { const d = px.data[i]; if (!Number.isFinite(d)) return [0.25, 0.45, 0.8]; const v = 1 - Math.min(1, d / scale); return [v, v, v]; } });
    const v = meta.views[p.mdfView];
    label.textContent = `view θ ${fmt(v[0])}° φ ${fmt(v[1])}°: distance to the mesostructure (white near, black ≥ ${fmt(scale)} texels, blue: no hit)`;
    label.dataset.view = p.mdfView;
  };
  body.append(hemis, el("div", { class: "frame" }, canvas), label);
  await load();
}

async function viewBrdfMap(body, n, meta) {
  const p = S.preview;
  const canvas = el("canvas", { id: "preview-canvas" }), cap = el("div", { class: "caption" });
  const load = async () => {
    const px = await getPixels(n.id, p.port, p.param);
    let lo = Infinity, hi = -Infinity;
    for (const v of px.data) if (Number.isFinite(v)) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
    paint(canvas, px, { tone: false, map: i => { const v = (px.data[i] - lo) / Math.max(1e-12, hi - lo); return [v, v, v]; } });
    cap.textContent = `${meta.params[p.param]}: ${fmt(lo)} … ${fmt(hi)}`;
  };
  body.append(el("div", { class: "controls" }, el("label", {}, "parameter ", el("select", { onchange: e => { p.param = e.target.selectedIndex; load(); } },
    meta.params.map((q, i) => el("option", { selected: i === p.param }, q))))), el("div", { class: "frame" }, canvas), cap);
  await load();
}

// A plot frame with axes; `lx`/`ly` choose log scales. Returns the SVG and a point mapper.
function plotFrame(xs, ys, { lx, ly, xlabel, ylabel, w = 420, h = 300 }) {
  const f = (v, log) => log ? Math.log10(v) : v;
  const fx = xs.map(v => f(v, lx)).filter(Number.isFinite), fy = ys.map(v => f(v, ly)).filter(Number.isFinite);
  let [x0, x1] = [Math.min(...fx), Math.max(...fx)], [y0, y1] = [Math.min(...fy), Math.max(...fy)];
  if (!(x1 > x0)) { x0 -= 1; x1 += 1; }
  if (!(y1 > y0)) { y0 -= 1; y1 += 1; }
  const m = { l: 52, r: 10, t: 10, b: 34 };
  const X = v => m.l + (f(v, lx) - x0) / (x1 - x0) * (w - m.l - m.r), Y = v => h - m.b - (f(v, ly) - y0) / (y1 - y0) * (h - m.t - m.b);
  const svg = sv("svg", { class: "plot", width: w, height: h });
  const ticks = (a, b, log) => {
    if (log) { const out = []; for (let e = Math.ceil(a); e <= Math.floor(b); e++) out.push(Math.pow(10, e)); return out.length > 1 ? out : [Math.pow(10, a), Math.pow(10, b)]; }
    const step = Math.pow(10, Math.floor(Math.log10((b - a) / 4 || 1))); const out = [];
    for (let v = Math.ceil(a / step) * step; v <= b + 1e-12; v += step * (Math.ceil((b - a) / step / 6) || 1)) out.push(v);
    return out;
  };
  for (const t of ticks(x0, x1, lx)) { svg.append(sv("line", { class: "grid", x1: X(t), x2: X(t), y1: m.t, y2: h - m.b }), sv("text", { x: X(t), y: h - m.b + 12, "text-anchor": "middle" }, fmt(t))); }
  for (const t of ticks(y0, y1, ly)) { svg.append(sv("line", { class: "grid", x1: m.l, x2: w - m.r, y1: Y(t), y2: Y(t) }), sv("text", { x: m.l - 4, y: Y(t) + 3, "text-anchor": "end" }, fmt(t))); }
  svg.append(sv("text", { x: (w + m.l) / 2, y: h - 4, "text-anchor": "middle" }, xlabel), sv("text", { x: 10, y: h / 2, transform: `rotate(-90 10 ${h / 2})`, "text-anchor": "middle" }, ylabel));
  return { svg, X, Y };
}

function viewProfile(body, n, meta) {
  const colours = ["#ff6b6b", "#69db7c", "#74c0fc"];
  const xs = [], ys = [];
  meta.rd.forEach(ch => ch.forEach((v, i) => { if (v > 0 && meta.radii[i] > 0) { xs.push(meta.radii[i]); ys.push(v); } }));
  if (!xs.length) { body.append(el("p", { class: "muted" }, "no positive values to plot")); return; }
  const { svg, X, Y } = plotFrame(xs, ys, { lx: true, ly: true, xlabel: "radius r (mm)", ylabel: "Rd(r) (mm⁻²)" });
  svg.id = "profile-plot";
  meta.rd.forEach((ch, c) => {
    const pts = ch.map((v, i) => v > 0 && meta.radii[i] > 0 ? `${X(meta.radii[i]).toFixed(1)},${Y(v).toFixed(1)}` : null).filter(Boolean);
    svg.append(sv("polyline", { points: pts.join(" "), fill: "none", stroke: colours[c], "stroke-width": 1.6, "data-channel": c }));
  });
  body.append(svg, el("div", { class: "caption" }, `${meta.model}: total diffuse reflectance ${meta.total.map(fmt).join(" / ")}, mean free path ${meta.mfp.map(fmt).join(" / ")} mm (R / G / B)`));
}

function viewPoints(body, n, meta) {
  const p = S.preview;
  const dims = meta.dims;
  if (p.xdim >= dims) p.xdim = 0;
  if (p.ydim >= dims) p.ydim = Math.min(1, dims - 1);
  if (p.cdim >= dims) p.cdim = -1;
  const holder = el("div");
  const draw = () => {
    const xs = meta.points.map(q => q[p.xdim]), ys = meta.points.map(q => dims > 1 ? q[p.ydim] : 0);
    const { svg, X, Y } = plotFrame(xs, ys, { xlabel: `dimension ${p.xdim}`, ylabel: dims > 1 ? `dimension ${p.ydim}` : "" });
    svg.id = "scatter-plot";
    const cs = p.cdim >= 0 ? meta.points.map(q => q[p.cdim]) : null;
    const lo = cs ? Math.min(...cs.filter(Number.isFinite)) : 0, hi = cs ? Math.max(...cs.filter(Number.isFinite)) : 1;
    meta.points.forEach((q, i) => {
      if (!Number.isFinite(xs[i]) || !Number.isFinite(ys[i])) return;
      const t = cs ? (cs[i] - lo) / Math.max(1e-12, hi - lo) : 0.5;
      // A blue–yellow ramp (colour-blind safe) by the chosen value.
      const col = `rgb(${Math.round(40 + 210 * t)},${Math.round(70 + 150 * t)},${Math.round(200 - 170 * t)})`;
      svg.append(sv("circle", { cx: X(xs[i]).toFixed(1), cy: Y(ys[i]).toFixed(1), r: 2.2, fill: col }));
    });
    holder.replaceChildren(svg, el("div", { class: "caption" }, `${meta.n} points` + (meta.step > 1 ? ` (every ${meta.step}th shown)` : "") +
      (cs ? `; colour: dimension ${p.cdim}, ${fmt(lo)} (blue) … ${fmt(hi)} (yellow)` : "") +
      (meta.eigenvalues ? `; eigenvalues ${meta.eigenvalues.slice(0, 4).map(fmt).join(", ")}` : "")));
  };
  const dimSel = (key, withNone) => el("select", { onchange: e => { p[key] = +e.target.value; draw(); } },
    (withNone ? [el("option", { value: -1 }, "—")] : []).concat([...Array(dims).keys()].map(d => el("option", { value: d, selected: d === p[key] }, String(d)))));
  body.append(el("div", { class: "controls" }, el("label", {}, "x ", dimSel("xdim")), el("label", {}, "y ", dimSel("ydim")), el("label", {}, "colour by ", dimSel("cdim", true))), holder);
  draw();
}

function viewMesh(body, n, meta) {
  const canvas = el("canvas", { id: "preview-canvas", width: 440, height: 330 });
  const P = meta.positions, I = meta.indices;
  const [lo, hi] = meta.bounds, c = [0, 1, 2].map(k => (lo[k] + hi[k]) / 2);
  const size = Math.max(...[0, 1, 2].map(k => hi[k] - lo[k])) || 1;
  const draw = () => {
    const ctx = canvas.getContext("2d");
    ctx.fillStyle = "#0d0f12"; ctx.fillRect(0, 0, canvas.width, canvas.height);
    const a = S.preview.yaw * Math.PI / 180, b = 0.45;
    const tr = i => {
      let x = P[3 * i] - c[0], y = P[3 * i + 1] - c[1], z = P[3 * i + 2] - c[2];
      [x, z] = [x * Math.cos(a) + z * Math.sin(a), -x * Math.sin(a) + z * Math.cos(a)];
      [y, z] = [y * Math.cos(b) - z * Math.sin(b), y * Math.sin(b) + z * Math.cos(b)];
      return [canvas.width / 2 + x / size * 280, canvas.height / 2 - y / size * 280, z];
    };
    const tris = [];
    for (let t = 0; t < I.length; t += 3) {
      const [p0, p1, p2] = [tr(I[t]), tr(I[t + 1]), tr(I[t + 2])];
      const ux = p1[0] - p0[0], uy = p1[1] - p0[1], uz = p1[2] - p0[2], vx = p2[0] - p0[0], vy = p2[1] - p0[1], vz = p2[2] - p0[2];
      const nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx, len = Math.hypot(nx, ny, nz) || 1;
      tris.push([p0, p1, p2, (p0[2] + p1[2] + p2[2]) / 3, Math.abs(nz / len) * 0.7 + Math.abs(ny / len) * 0.2]);
    }
    tris.sort((u, v) => u[3] - v[3]);
    for (const [p0, p1, p2, , s] of tris) {
      const g = Math.round(40 + 200 * s);
      ctx.fillStyle = ctx.strokeStyle = `rgb(${g},${g},${Math.round(g * 1.05)})`;
      ctx.beginPath(); ctx.moveTo(p0[0], p0[1]); ctx.lineTo(p1[0], p1[1]); ctx.lineTo(p2[0], p2[1]); ctx.closePath(); ctx.fill(); ctx.stroke();
    }
    S.draws++; canvas.dataset.draws = S.draws;
  };
  body.append(el("div", { class: "controls" }, el("label", {}, "turn ", el("input", { type: "range", min: -180, max: 180, value: S.preview.yaw,
    oninput: e => { S.preview.yaw = +e.target.value; draw(); } }))), el("div", { class: "frame" }, canvas),
  el("div", { class: "caption" }, `${meta.triangles} triangles` + (meta.shown < meta.triangles ? ` (${meta.shown} shown)` : "")));
  draw();
}

function viewScalar(body, n, meta) { body.append(el("div", { class: "big", id: "scalar-value" }, fmt(meta.value))); }
function viewTable(body, n, meta) {
  body.append(el("table", { class: "data" }, meta.rows.map(([k, v]) => el("tr", {}, el("td", {}, k),
    el("td", { class: "num" }, Array.isArray(v) ? v.map(fmt).join(", ") : fmt(v))))));
}
function viewFiles(body, n, meta) {
  for (const f of meta.files) {
    const href = url(`/api/file?path=${encodeURIComponent(f.path)}`);
    body.append(el("div", {}, el("a", { href, target: "_blank" }, f.path), ` (${bytes(f.bytes)})`));
    if (/\.(png|jpe?g|svg)$/i.test(f.path)) body.append(el("img", { class: "chart", src: href, style: "background:#0d0f12" }));
  }
}

// ---- report -----------------------------------------------------------------------------
function renderReport() {
  const box = $("#tab-report");
  const r = S.state && S.state.report;
  if (!r) { box.replaceChildren(el("p", { class: "muted" }, "no run yet")); return; }
  const head = el("tr", {}, ["node", "kind", "status", "time", "bytes", "metrics"].map(h => el("th", {}, h)));
  const rows = r.nodes.map(n => el("tr", { "data-id": n.id }, el("td", {}, n.id), el("td", { class: "muted" }, n.kind), el("td", {}, n.status),
    el("td", { class: "num" }, secs(n.seconds)), el("td", { class: "num" }, bytes(n.bytes)),
    el("td", {}, Object.entries(n.metrics).map(([k, v]) => `${k} ${fmt(v)}`).join(", ") + (n.error ? " " + n.error : ""))));
  box.replaceChildren(el("h2", {}, `Last run: ${r.ok ? "ok" : "failed"}${r.cancelled ? " (cancelled)" : ""}, ${secs(r.seconds)}`),
    r.adapter ? el("div", { class: "doc" }, "GPU: " + r.adapter) : null,
    el("table", { class: "data", id: "report-table" }, head, rows),
    r.warnings.length ? el("div", {}, el("h3", {}, "Warnings"), r.warnings.map(w => el("div", { class: "doc" }, `${w.node}: ${w.message}`))) : null,
    r.skipped.length ? el("div", { class: "doc" }, "not needed (their dependants were cached): " + r.skipped.join(", ")) : null,
    r.files.length ? el("div", {}, el("h3", {}, "Files"), r.files.map(f => el("div", {}, el("a", { href: url(`/api/file?path=${encodeURIComponent(f)}`), target: "_blank" }, f)))) : null);
}

// ---- sweeps -----------------------------------------------------------------------------
function sweepables() {
  const out = [];
  for (const n of S.state.nodes) {
    const sig = S.kinds[n.kind];
    if (!sig) continue;
    for (const [k, s0] of Object.entries(sig.params.properties || {})) {
      const s = resolve(s0, sig.params), { t } = typeOf(s);
      if (["integer", "number", "boolean", "string"].includes(t) || choices(s)) out.push(`${n.id}.${k}`);
    }
  }
  return out;
}
function measurables() {
  const out = [];
  for (const n of S.state.nodes) {
    n.outputs.filter(o => o.type === "Scalar").forEach(o => out.push(`${n.id}.${o.name}`));
    (n.timings || []).forEach(t => out.push(`${n.id}.${t.name}`));
    out.push(`${n.id}.seconds`);
  }
  return out;
}
function renderSweepForm() {
  const box = $("#tab-sweep");
  if (box.dataset.revision === String(S.state.revision)) return;
  box.dataset.revision = S.state.revision;
  const params = sweepables(), measures = measurables();
  const vary = el("select", { id: "sweep-param" }, params.map(p => el("option", { value: p }, p)));
  const values = el("input", { type: "text", id: "sweep-values", placeholder: "values, e.g. 4, 8, 16, 32" });
  const picks = el("div", { id: "sweep-measures", style: "max-height:140px;overflow:auto" }, measures.map(m => el("label", { style: "display:block" },
    el("input", { type: "checkbox", value: m, checked: /\.(rmse|psnr|error|mean|flip)/.test(m) && !m.endsWith(".seconds") ? true : false }), " " + m)));
  const versus = el("select", { id: "sweep-versus" }, el("option", { value: "" }, "—"), measures.map(m => el("option", { value: m }, m)));
  const msg = el("div", { class: "param-error", id: "sweep-error" });
  const start = el("button", { class: "primary", id: "sweep-start", onclick: async () => {
    const vals = values.value.split(",").map(s => s.trim()).filter(Boolean).map(s => { try { return JSON.parse(s); } catch { return s; } });
    const measure = [...picks.querySelectorAll("input:checked")].map(i => i.value);
    const vs = versus.value ? [versus.value] : [];
    if (vs.length && !measure.includes(vs[0])) measure.push(vs[0]);
    const res = await post("/api/sweep", { vary: [{ param: vary.value, values: vals }], measure, versus: vs });
    msg.textContent = res.ok ? "" : (res.body.errors || [res.body]).map(x => x.message || x.error).join("\n");
  } }, "Start sweep");
  box.replaceChildren(el("h2", {}, "Sweep"), el("div", { class: "doc" }, "Runs the graph once per value on the studio's engine (upstream nodes compute once); writes sweep.csv and the charts of `mesoflow sweep` under the output folder's sweep/."),
    el("div", { class: "field" }, el("label", {}, "vary"), vary), el("div", { class: "field" }, el("label", {}, "values"), values),
    el("div", { class: "field" }, el("label", {}, "measure"), picks), el("div", { class: "field" }, el("label", {}, "versus (x axis)"), versus),
    start, msg, el("div", { id: "sweep-results" }));
  renderSweepResults();
}
function renderSweepResults() {
  const box = $("#sweep-results");
  if (!box || !S.sweep) return;
  const sw = S.sweep;
  getJson("/api/sweep").then(st => {
    if (st.id !== sw.id) return;
    const cols = st.columns;
    const table = el("table", { class: "data", id: "sweep-table" }, el("tr", {}, cols.map(c => el("th", {}, c))),
      sw.rows.map(r => el("tr", {}, r.cells.map(c => el("td", { class: "num" }, fmt(c))))));
    const parts = [el("h3", {}, `${sw.rows.length} of ${sw.total} runs` + (sw.running ? " — running" : " — done")), table];
    // Each measure against the varied value, drawn as the rows arrive.
    for (let m = 1; m < cols.length && sw.rows.length; m++) {
      const xs = sw.rows.map((r, i) => typeof r.cells[0] === "number" ? r.cells[0] : i), ys = sw.rows.map(r => r.cells[m]);
      if (!ys.some(v => typeof v === "number")) continue;
      const ok = ys.map((y, i) => [xs[i], y]).filter(([, y]) => typeof y === "number");
      const { svg, X, Y } = plotFrame(ok.map(p => p[0]), ok.map(p => p[1]), { xlabel: cols[0], ylabel: cols[m], h: 200 });
      svg.append(sv("polyline", { points: ok.map(([x, y]) => `${X(x)},${Y(y)}`).join(" "), fill: "none", stroke: "#6aa9ff", "stroke-width": 1.6 }));
      ok.forEach(([x, y]) => svg.append(sv("circle", { cx: X(x), cy: Y(y), r: 3, fill: "#6aa9ff" })));
      parts.push(svg);
    }
    if (!sw.running) {
      if (sw.error) parts.push(el("div", { class: "error-box" }, sw.error));
      if (sw.csv) parts.push(el("div", {}, el("a", { href: url(`/api/file?path=${encodeURIComponent(sw.csv)}`), target: "_blank" }, "sweep.csv")));
      for (const c of sw.charts || []) parts.push(el("img", { class: "chart", src: url(`/api/file?path=${encodeURIComponent(c)}`), title: c }));
    }
    box.replaceChildren(...parts);
  }).catch(() => {});
}

// ---- start ------------------------------------------------------------------------------
async function main() {
  document.querySelectorAll("#tabs button").forEach(b => b.addEventListener("click", () => showTab(b.dataset.tab)));
  $("#save-button").addEventListener("click", async () => {
    const r = await post("/api/save");
    $("#status-line").textContent = r.ok ? (r.body.changed ? "saved" : "nothing to save") : "save failed: " + r.body.error;
  });
  $("#run-button").addEventListener("click", () => post("/api/run"));
  setupPanZoom();
  const kinds = await getJson("/api/kinds");
  for (const k of kinds) S.kinds[k.kind] = k;
  await loadState();
  connect();
}
main().catch(e => { document.body.prepend(el("div", { class: "error-box" }, "the studio could not start: " + e.message)); });
