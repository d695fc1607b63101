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
