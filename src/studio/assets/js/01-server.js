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
  return getPixelsAt(`/api/pixels?node=${node}&port=${port}&index=${index || 0}`);
}
async function getPixelsAt(path) {
  const r = await fetch(url(path));
  if (!r.ok) {
    const b = await r.json().catch(() => ({}));
    throw new Error(b.error || r.statusText);
  }
  const buf = await r.arrayBuffer();
  return { w: +r.headers.get("X-Width"), h: +r.headers.get("X-Height"),
    c: +r.headers.get("X-Channels"), data: new Float32Array(buf) };
}
