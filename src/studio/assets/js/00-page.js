// mesoflow studio: the page. Plain JavaScript, no build step; it talks to `mesoflow serve`
// through /api (JSON), /api/pixels (raw f32 pixels, tone-mapped here) and /api/events
// (server-sent events). `window.studio` exposes the state for the browser tests.
"use strict";

const TOKEN = new URLSearchParams(location.search).get("token") || "";
const S = {
  state: null, kinds: {}, selected: null, live: {}, progress: {}, run: null, lastRun: null,
  view: { x: 20, y: 20, k: 1 }, preview: { port: null, exposure: 0, srgb: true, zoom: 0,
  against: "", pair: null, viewDir: null, lightDir: null, mdfView: 0, param: 0, xdim: 0,
  ydim: 1, cdim: -1, yaw: 30 }, draws: 0, errorsByField: {}, sweep: null, tab: "node",
  finishedRuns: 0, open: new Set(),
};
window.studio = S;
