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
