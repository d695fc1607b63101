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
  // A graph node opens onto the nodes inside it: each one's status and why it ran.
  const inner = innerOf(id);
  if (inner) return el("div", {}, el("h3", {}, "Inside"), el("table", { class: "data", id: "inner-nodes" },
    inner.map(i => { const r = reportOf(i); return el("tr", { "data-id": i, class: "link", title: "open the box and select it",
      onclick: () => { S.open.add(id); select(i); } }, el("td", {}, i), el("td", {}, statusOf(i)),
      el("td", { class: "num" }, r ? secs(r.seconds) : ""), el("td", { class: "why" }, (r && r.reason) || "")); })));
  const r = reportOf(id);
  if (!r) return el("p", { class: "muted" }, "not in the last run");
  const rows = [["status", r.status], ["device", r.device], ["seconds", secs(r.seconds)], ["bytes", bytes(r.bytes)]];
  if (r.reason) rows.push(["why it ran", r.reason]);
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
