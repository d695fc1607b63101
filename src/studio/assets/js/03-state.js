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
  on("plan_started", () => renderPlanResults());
  on("plan_done", e => {
    renderPlanResults();
    $("#status-line").textContent = e.error ? `plan ${e.plan} failed: ${e.error}` : `plan ${e.plan} done: see the Plan tab`;
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
