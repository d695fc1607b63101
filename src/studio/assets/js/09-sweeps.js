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
