// Passes of the satellite with completeness and gaps; choosing a pass, a window or live follow sets the
// window every plot shows.
import { api } from "./api.js";
import { $, el, fill } from "./dom.js";
import { inputUtc, isoUtcNs, utcInput } from "./format.js";
import { emit, satParam, state } from "./state.js";

export const DEFAULT_LIVE_WINDOW_S = 7200;  // following the newest telemetry: the last two hours

export function clearPasses() {
  fill($("passes").querySelector("tbody"));
}

function completenessCell(p) {
  const pct = Math.round(100 * (p.completeness ?? 0));
  const quality = pct >= 99 ? "" : pct >= 80 ? "partial" : "poor";
  const gaps = p.packets_missing ? `${p.packets_missing} missing` : "no gaps";
  return el("td", { title: `${p.packets_received} packets received, ${gaps}` },
    el("span", { class: `bar ${quality}`, style: { width: `${pct / 2}px` } }), `${pct} %`);
}

export async function loadPasses() {
  const passes = await api(`/passes?satellite=${satParam()}`);
  const body = $("passes").querySelector("tbody");
  const rows = passes.map((p) => {
    const tr = el("tr", { dataset: { passId: p.id } },
      el("td", {}, String(p.id)),
      el("td", { title: p.origin === "data" ? "made from the telemetry itself: no predicted pass covered it" : "predicted from the TLE" },
        p.station || "station unknown", p.origin === "data" ? " (from data)" : ""),
      el("td", {}, isoUtcNs(p.aos_ns)),
      el("td", {}, ((p.los_ns - p.aos_ns) / 60e9).toFixed(1)),
      completenessCell(p),
      el("td", { class: p.packets_missing ? "yellow" : "" }, String(p.packets_missing ?? 0)));
    tr.addEventListener("click", () => selectPass(tr, p));
    return tr;
  });
  fill(body, rows.length ? rows : el("tr", {}, el("td", { colspan: 6, class: "muted" },
    `no passes for ${state.satellite}: predict them from a TLE and a station (Archive panel)`)));
  return passes;
}

function markSelected(row) {
  for (const r of $("passes").querySelectorAll("tr.selected")) r.classList.remove("selected");
  if (row) row.classList.add("selected");
}

export function selectPass(row, p) {
  markSelected(row);
  const t0 = (p.received_start_ns ?? p.aos_ns) / 1e9;
  const t1 = (p.received_end_ns ?? p.los_ns) / 1e9;
  setWindow([Math.min(t0, p.aos_ns / 1e9), Math.max(t1, p.los_ns / 1e9)], `pass ${p.id}`, false, p);
}

/** Set the plotted window and tell the panels. following = the window tracks the newest telemetry. */
export function setWindow(window, what, following, pass = null) {
  state.window = window;
  state.following = following;
  state.pass = pass;
  describe(what, following);
  emit("window", state.window);
}

/** Following live: the window starts where the plotted telemetry starts (never before the data). */
export function trimLiveWindow(first, last) {
  if (!state.following || !state.window || !Number.isFinite(first)) return;
  state.window = [Math.max(state.window[0], first), Math.max(state.window[1], last)];
  describe("newest telemetry", true);
}

function describe(what, following) {
  const [t0, t1] = state.window;
  state.windowLabel = `${what} · ${isoUtcNs(t0 * 1e9)} → ${following ? "now (live)" : isoUtcNs(t1 * 1e9)}`;
  $("window-label").textContent = state.windowLabel;
  $("window-start").value = utcInput(t0);
  $("window-end").value = utcInput(t1);
}

export function followLive(newestS) {
  markSelected(null);
  const end = newestS ?? Date.now() / 1000;
  setWindow([end - DEFAULT_LIVE_WINDOW_S, end], "newest telemetry", true);
}

export function windowFromInputs() {
  const t0 = inputUtc($("window-start").value), t1 = inputUtc($("window-end").value);
  if (!Number.isFinite(t0) || !Number.isFinite(t1) || t1 <= t0) {
    $("window-label").textContent = "window: give a start before the end (UTC)";
    return;
  }
  markSelected(null);
  setWindow([t0, t1], "window", false);
}
