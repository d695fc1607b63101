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
  const sig = S.kinds[n.kind] || (n.schema && { doc: "a graph file used as a node: its exposed inputs, outputs and parameters; ▸ open (or a double click) shows the nodes inside it in place, Preview lists them", params: n.schema });
  box.append(el("h2", {}, n.id), el("div", { class: "doc" }, n.kind + (sig ? " — " + sig.doc : " (unknown kind)")));
  // A node inside a graph node is read here, and set through the graph node.
  const owner = S.state.nodes.find(m => (m.inside || []).some(i => i.id === n.id));
  if (owner) {
    const name = n.id.slice(owner.id.length + 1);
    box.append(el("div", { class: "hint", id: "inner-note" }, `Inside ${owner.id} (its file's node ${name}): set its parameters on ${owner.id}, as an exposed parameter or in its \`set\` as \`${name}.param\` (--set ${n.id}.param on the command line).`));
    box.append(el("h3", {}, "Parameters"), el("table", { class: "data", id: "inner-params" },
      Object.entries(n.params).map(([k, v]) => el("tr", {}, el("td", {}, k), el("td", {}, JSON.stringify(v))))));
    return;
  }
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
