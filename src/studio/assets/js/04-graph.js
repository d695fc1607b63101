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
  renderPlanForm();
  renderReport();
  refreshPreview();
}

// A box's size: a node's from its ports; an open graph node's holds the nodes inside it.
const PAD = 16, HEAD = 64;
function boxSize(n) {
  const ports = 68 + 15 * Math.max(n.ports.length, n.outputs.length);
  if (!(n.inside && S.open.has(n.id))) return { w: 210, h: ports };
  // The inner layout is kept with the box, so drawing it needs no second layout.
  const inner = layout(n.inside), ps = Object.values(inner);
  // Room on the right for the exposed outputs' edges to the box's pins.
  const w = Math.max(210, ...ps.map(p => p.x + p.w)) + 2 * PAD + 40;
  const top = HEAD + 15 * Math.max(n.ports.length, n.outputs.length) + 8;
  return { w, h: top + Math.max(0, ...ps.map(p => p.y + p.h)) + PAD, top, inner };
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
  const pos = {}, GAP = 70;
  let x = 0;
  layers.forEach(layer => {
    layer.forEach((n, i) => {
      const parents = Object.values(n.inputs).map(s => pos[s.split(".")[0]]).filter(Boolean);
      n._order = parents.length ? parents.reduce((a, p) => a + p.y, 0) / parents.length : i * 100;
    });
    layer.sort((a, b) => a._order - b._order);
    let y = 0, w = 0;
    for (const n of layer) {
      const size = boxSize(n);
      pos[n.id] = { x, y, w: size.w, h: size.h, top: size.top, inner: size.inner };
      y += size.h + 22;
      w = Math.max(w, size.w);
    }
    x += w + GAP;
  });
  return pos;
}

// A graph node (a graph file used as a node) has the status of the nodes inside it: failed or
// running if one is, computed if one re-ran, else from the cache.
function innerOf(id) {
  const n = S.state && S.state.nodes.find(m => m.id === id);
  return n && n.inner ? n.inner : null;
}
function statusOf(id) {
  const inner = innerOf(id);
  if (inner) {
    const st = inner.map(statusOf);
    for (const s of ["failed", "running", "computed", "cancelled"]) if (st.includes(s)) return s;
    if (st.length && st.every(s => s === "memory" || s === "disk" || s === "skipped")) return st.includes("disk") ? "disk" : "memory";
    return "stale";
  }
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
  const pos = layout(S.state.nodes);
  S.positions = {};
  drawLevel(vp, S.state.nodes, pos, 0, 0);
  if (!S.fitted) fitView();
  applyView();
}

// One level of boxes at (dx, dy): the edges between them, then the boxes; an open graph node's
// box holds the level inside it.
function drawLevel(vp, nodes, pos, dx, dy) {
  const portY = (p, i) => p.y + 64 + 15 * i;
  for (const n of nodes) {
    n.ports.forEach((port, i) => {
      const src = n.inputs[port.name];
      if (!src) return;
      const [sid, sport] = src.split(".");
      const s = nodes.find(m => m.id === sid), sp = pos[sid];
      if (!s || !sp) return;
      const oi = Math.max(0, s.outputs.findIndex(o => o.name === sport));
      const x1 = dx + sp.x + sp.w, y1 = dy + portY(sp, oi), x2 = dx + pos[n.id].x, y2 = dy + portY(pos[n.id], i);
      const d = Math.max(40, (x2 - x1) / 2);
      vp.append(sv("path", { class: "edge" + (S.selected === n.id || S.selected === sid ? " hot" : ""),
        d: `M${x1},${y1} C${x1 + d},${y1} ${x2 - d},${y2} ${x2},${y2}` }));
    });
  }
  for (const n of nodes) {
    const p = { ...pos[n.id], x: dx + pos[n.id].x, y: dy + pos[n.id].y };
    S.positions[n.id] = p;
    drawBox(vp, n, p);
    if (n.inside && S.open.has(n.id)) {
      const ipos = p.inner, ix = p.x + PAD, iy = p.y + p.top;
      drawLevel(vp, n.inside, ipos, ix, iy);
      // Each exposed output from the inner output it names to the box's own pin.
      n.outputs.forEach((o, i) => {
        const [sid, sport] = (o.inside || "").split(".");
        const s = n.inside.find(m => m.id === sid), sp = ipos[sid];
        if (!s || !sp) return;
        const oi = Math.max(0, s.outputs.findIndex(x => x.name === sport));
        const x1 = ix + sp.x + sp.w, y1 = iy + portY(sp, oi), x2 = p.x + p.w, y2 = portY(p, i);
        vp.append(sv("path", { class: "edge exposed", d: `M${x1},${y1} C${x1 + 30},${y1} ${x2 - 30},${y2} ${x2},${y2}` }));
      });
    }
  }
}

function drawBox(vp, n, p) {
  const status = statusOf(n.id), r = reportOf(n.id);
  const hasError = S.state.errors.some(e => e.node === n.id);
  const open = n.inside && S.open.has(n.id);
  const g = sv("g", { class: `node ${status}${S.selected === n.id ? " selected" : ""}${hasError ? " failed" : ""}${open ? " open" : ""}`,
    "data-id": n.id, "data-status": status, transform: `translate(${p.x},${p.y})`,
    onclick: ev => { ev.stopPropagation(); select(n.id); },
    ondblclick: ev => { if (n.inside) { ev.stopPropagation(); toggleOpen(n.id); } } });
  g.append(sv("rect", { class: "body", width: p.w, height: p.h, rx: 6 }));
  g.append(sv("text", { class: "title", x: 10, y: 18 }, n.id));
  g.append(sv("text", { class: "kind", x: 10, y: 32 }, n.kind));
  const inner = innerOf(n.id);
  const stats = inner ? `graph · ${inner.length} nodes · ${inner.filter(i => statusOf(i) === "computed").length} re-ran` :
    r ? `${status} · ${secs(r.seconds)} · ${bytes(r.bytes)}` :
    status === "skipped" ? "not needed: its dependants were cached" : "not run yet";
  const statsText = sv("text", { class: "stats", x: 10, y: 45 }, stats);
  // Why it ran, on hover: the first run, --no-cache, evicted, or what changed.
  if (r && r.reason) statsText.append(sv("title", {}, "why it ran: " + r.reason));
  g.append(statsText);
  // A graph node opens in place (a click here or a double click on the box) onto its nodes.
  if (n.inside) g.append(sv("text", { class: "toggle", x: p.w - 10, y: 18, "text-anchor": "end", "data-toggle": n.id,
    onclick: ev => { ev.stopPropagation(); toggleOpen(n.id); } }, open ? "▾ close" : "▸ open"));
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

function toggleOpen(id) {
  if (S.open.has(id)) S.open.delete(id); else S.open.add(id);
  drawGraph();
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
