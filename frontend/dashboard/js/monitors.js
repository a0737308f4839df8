// The twin monitors (viser, one port per role) embedded as frames once they answer: until then each
// shows that it is starting, with the time waited, instead of a broken frame. Behind the server's token
// gate the frame opens with the dashboard's token (?token=…: the gate answers with a redirect that keeps it
// in an HttpOnly cookie, out of the frame's URL), so the embedded monitor and the "open on its own
// screen" link work without a second login; each frame is a viewer with its own playback.
import { session } from "./api.js";
import { $, el, fill } from "./dom.js";

const PROBE_MS = 1000;
const PROBE_TIMEOUT_MS = 2500;
let timers = [];

async function answers(url) {
  // any HTTP answer counts (cross-origin: opaque); a refused connection rejects
  const abort = new AbortController();
  const timer = setTimeout(() => abort.abort(), PROBE_TIMEOUT_MS);
  try {
    await fetch(url, { mode: "no-cors", cache: "no-store", signal: abort.signal });
    return true;
  } catch {
    return false;
  } finally {
    clearTimeout(timer);
  }
}

function withToken(url) {
  if (!session.token) return url;
  const u = new URL(url, window.location.href);
  u.searchParams.set("token", session.token);
  return u.href;
}

function embed(figure, role, url) {
  const frame = el("iframe", { src: withToken(url), title: `${role} monitor` });
  figure.querySelector(".starting").replaceWith(frame);
  figure.dataset.state = "ready";
}

function watch(figure, role, url, started) {
  const note = figure.querySelector(".starting-text");
  const tick = async () => {
    if (await answers(url)) { embed(figure, role, url); return; }
    note.textContent = `${role} monitor starting… ${Math.round((performance.now() - started) / 1000)} s`
      + " (the twin's engine compiles on first start)";
    timers.push(setTimeout(tick, PROBE_MS));
  };
  tick();
}

export function showMonitors(monitors) {
  for (const t of timers) clearTimeout(t);
  timers = [];
  const box = $("monitors");
  const entries = Object.entries(monitors || {});
  if (!entries.length) { fill(box, el("p", { class: "muted" }, "no twin monitors configured")); return; }
  const started = performance.now();
  fill(box, entries.map(([role, url]) => {
    const figure = el("figure", { dataset: { role, state: "starting" } },
      el("figcaption", {}, `${role} — `, el("a", { href: url, target: "_blank", rel: "noopener" }, "open on its own screen")),
      el("div", { class: "starting" }, el("progress", {}), el("span", { class: "starting-text" }, `${role} monitor: connecting…`)));
    watch(figure, role, url, started);
    return figure;
  }));
}
