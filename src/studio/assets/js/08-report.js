// ---- report -----------------------------------------------------------------------------
function renderReport() {
  const box = $("#tab-report");
  const r = S.state && S.state.report;
  if (!r) { box.replaceChildren(el("p", { class: "muted" }, "no run yet")); return; }
  const head = el("tr", {}, ["node", "kind", "status", "why it ran", "time", "bytes", "metrics"].map(h => el("th", {}, h)));
  const rows = r.nodes.map(n => el("tr", { "data-id": n.id }, el("td", {}, n.id), el("td", { class: "muted" }, n.kind), el("td", {}, n.status),
    el("td", { class: "why" }, n.reason || ""), el("td", { class: "num" }, secs(n.seconds)), el("td", { class: "num" }, bytes(n.bytes)),
    el("td", {}, Object.entries(n.metrics).map(([k, v]) => `${k} ${fmt(v)}`).join(", ") + (n.error ? " " + n.error : ""))));
  box.replaceChildren(el("h2", {}, `Last run: ${r.ok ? "ok" : "failed"}${r.cancelled ? " (cancelled)" : ""}, ${secs(r.seconds)}`),
    r.adapter ? el("div", { class: "doc" }, "GPU: " + r.adapter) : null,
    el("table", { class: "data", id: "report-table" }, head, rows),
    r.warnings.length ? el("div", {}, el("h3", {}, "Warnings"), r.warnings.map(w => el("div", { class: "doc" }, `${w.node}: ${w.message}${w.expected ? " (the graph expects it)" : ""}`))) : null,
    r.skipped.length ? el("div", { class: "doc" }, "not needed (their dependants were cached): " + r.skipped.join(", ")) : null,
    r.files.length ? el("div", {}, el("h3", {}, "Files"), r.files.map(f => el("div", {}, el("a", { href: url(`/api/file?path=${encodeURIComponent(f)}`), target: "_blank" }, f)))) : null);
}
