// ---- plan -------------------------------------------------------------------------------
// The planner on the graph being edited: a render, a budget (relative RMSE against the truth
// the graph makes, or FLIP against its own model), the candidates as measured, the choice and
// why; "Apply" makes the planned graph the edit (a run and the previews follow).
const PLANNABLE = ["render.mesh", "sss.render", "render.btf", "render.relief"];
function renderPlanForm() {
  const box = $("#tab-plan");
  if (box.dataset.revision === String(S.state.revision)) return;
  box.dataset.revision = S.state.revision;
  const renders = S.state.nodes.filter(n => PLANNABLE.includes(n.kind));
  if (!renders.length) { box.replaceChildren(el("h2", {}, "Plan"), el("p", { class: "muted" }, "no render node to plan (render.mesh, sss.render, …)")); return; }
  const render = el("select", { id: "plan-render" }, renders.map(n => el("option", { value: n.id, selected: S.plan && S.plan.render === n.id }, `${n.id} (${n.kind})`)));
  const against = el("select", { id: "plan-against" }, el("option", { value: "truth" }, "the truth (relative RMSE)"), el("option", { value: "model" }, "its own model (FLIP)"));
  const budget = el("input", { type: "number", id: "plan-budget", value: 0.15, step: 0.01, min: 0.01, max: 1 });
  const slider = el("input", { type: "range", id: "plan-slider", min: 0.01, max: 0.5, step: 0.01, value: 0.15, oninput: e => (budget.value = e.target.value) });
  budget.addEventListener("input", () => (slider.value = budget.value));
  const msg = el("div", { class: "param-error", id: "plan-error" });
  const start = el("button", { class: "primary", id: "plan-start", onclick: async () => {
    const res = await post("/api/plan", { render: render.value, budget: Number(budget.value), against: against.value });
    msg.textContent = res.ok ? "" : (res.body.errors || [res.body]).map(x => x.message || x.error).join("\n");
  } }, "Plan");
  box.replaceChildren(el("h2", {}, "Plan"),
    el("div", { class: "doc" }, "The cheapest configuration of a render within the budget: against the truth the graph makes (every candidate, brute force included, measured against it), or against the graph's own model. Apply makes the planned graph the edit; Save writes it."),
    el("div", { class: "field" }, el("label", {}, "render"), render), el("div", { class: "field" }, el("label", {}, "against"), against),
    el("div", { class: "field" }, el("label", {}, "budget"), slider, budget), start, msg, el("div", { id: "plan-results" }));
  renderPlanResults();
}
function renderPlanResults() {
  const box = $("#plan-results");
  if (!box) return;
  getJson("/api/plan").then(st => {
    S.plan = st;
    if (!st.id) { box.replaceChildren(); return; }
    const parts = [el("h3", { id: "plan-status" }, `plan ${st.id} of ${st.render} at ${st.budget} against ${st.against === "truth" ? "the truth" : "its model"}` + (st.running ? " — running…" : st.error ? " — failed" : " — done"))];
    if (st.error) parts.push(el("div", { class: "error-box" }, st.error));
    const p = st.plan;
    if (p && p.candidates) {
      const head = el("tr", {}, ["candidate", "family", "relative RMSE", "s (full view, est.)", "within"].map(h => el("th", {}, h)));
      const rows = p.candidates.map(c => el("tr", { class: c.candidate === p.chosen ? "chosen" : "", title: (c.warnings || []).concat(c.note ? [c.note] : []).join("\n") },
        el("td", {}, (c.candidate === p.chosen ? "▶ " : "") + c.candidate), el("td", { class: "muted" }, c.family),
        el("td", { class: "num" }, fmt(c.relative_rmse)), el("td", { class: "num" }, fmt(c.full_seconds_estimate)),
        el("td", {}, c.within_budget ? "yes" : "no")));
      parts.push(el("table", { class: "data", id: "plan-table" }, head, rows), el("div", { class: "doc", id: "plan-why" }, p.why || ""));
      if (p.plan_time) parts.push(el("div", { class: "doc" }, `planning took ${secs(p.plan_time.seconds)}, ${p.plan_time.ratio.toFixed(1)}× the longer full render`));
    } else if (p) {
      const decisions = p.decisions || [];
      parts.push(el("table", { class: "data", id: "plan-table" }, el("tr", {}, el("th", {}, "decision")),
        decisions.map(d => el("tr", {}, el("td", {}, Object.entries(d).map(([k, v]) => `${k}: ${typeof v === "object" ? JSON.stringify(v) : fmt(v)}`).join(" · "))))));
      if (p.why) parts.push(el("div", { class: "doc", id: "plan-why" }, p.why));
    }
    if (st.previews && !st.running) parts.push(planPreviews(st));
    if (p && !st.running) parts.push(el("button", { id: "plan-apply", onclick: async () => {
      const res = await post("/api/plan/apply");
      $("#status-line").textContent = res.ok ? `plan ${st.id} applied (revision ${res.body.revision}); Save writes it` : "not applied: " + (res.body.errors || [res.body]).map(x => x.message || x.error).join("\n");
    } }, "Apply the plan"));
    box.replaceChildren(...parts);
  }).catch(() => {});
}
// The probe's truth, the render as given and the plan side by side, and each one's FLIP map
// against the truth (magma): where the plan's error is, at the view's own pixels per degree.
const PLAN_PREVIEW_LABELS = { truth: "the truth (probe)", given: "the render as given", planned: "the plan",
  given_error: "as given: FLIP against the truth", planned_error: "the plan: FLIP against the truth" };
function planPreviews(st) {
  const box = el("div", { class: "plan-previews", id: "plan-previews" });
  for (const name of st.previews) {
    const canvas = el("canvas", { id: `plan-preview-${name}`, class: "plan-preview" });
    const msg = el("div", { class: "muted" });
    box.append(el("figure", {}, canvas, el("figcaption", {}, PLAN_PREVIEW_LABELS[name] || name), msg));
    getPixelsAt(`/api/plan/pixels?image=${name}&plan=${st.id}`)
      .then(px => paint(canvas, px))
      .catch(e => (msg.textContent = e.message));
  }
  return box;
}
