// acs-twin operator dashboard: ES modules over the REST API and the live WebSocket, no build step.
// This module wires the panels together and owns the honest states: server unreachable (retry),
// token refused (expired or revoked), unknown satellite, satellite without telemetry.
import { api, errorText, optional, session, setToken } from "./api.js";
import { $, el, fill } from "./dom.js";
import { isoUtc } from "./format.js";
import { clearAlarms, loadAlarms } from "./alarms.js";
import { clearDiagnoses, loadDiagnoses } from "./diagnosis.js";
import { applyRole, loadArchive, wireArchive } from "./archive.js";
import { connectLive, disconnectLive, renderAges } from "./live.js";
import { showMonitors } from "./monitors.js";
import { clearPasses, followLive, loadPasses, trimLiveWindow, windowFromInputs } from "./passes.js";
import { plots, resetZoom, resizePlots } from "./plots.js";
import { emit, on, state } from "./state.js";
import { exportSummaryPdf, exportSummaryPng, showSummary } from "./summary.js";
import {
  appendLive, clearTelemetry, exportCsv, exportPng, fetchLatest, loadLatest, loadParameters, plotSelected,
} from "./telemetry.js";
import * as whatif from "./whatif.js";

const RETRY_S = 5;
let config = { api_base: "/api/v1", monitors: {} };
let retryTimer = null;
let alarmTimer = null;
let archiveTimer = null;
const ARCHIVE_RELOAD_MS = 300;  // commits in a burst (several uploads) reload once
let painted = false;
let monitorsShown = false;
let monitorsTimer = null;
const MONITORS_AFTER_MS = 3000;
let authEnabled = true;

function setStatus(text, error = false) {
  $("status").textContent = text;
  $("status").classList.toggle("error", error);
}

/** The page-wide notice for a state the operator must know about (null clears it). */
function notice(kind, ...content) {
  const box = $("notice");
  box.hidden = !kind;
  box.className = kind ? `notice ${kind}` : "notice";
  box.dataset.kind = kind || "";
  fill(box, ...content);
}

function unreachable(err) {
  clearTimeout(retryTimer);
  let left = RETRY_S;
  const text = el("span", {});
  const tick = () => {
    text.textContent = `Server unreachable (${location.origin}): ${err.message}. Retrying in ${left} s. `;
    if (left-- <= 0) { boot(); return; }
    retryTimer = setTimeout(tick, 1000);
  };
  notice("unreachable", text, el("button", { type: "button", onclick: () => boot() }, "Retry now"));
  setStatus("server unreachable", true);
  tick();
}

function showLogin(reason) {
  disconnectLive();
  $("app").hidden = true;
  $("login").hidden = false;
  $("logout").hidden = true;
  if (reason) notice("unauthorized", reason);
  setStatus(reason ? "not logged in" : "log in with an API token", Boolean(reason));
}

session.onUnauthorized = () => {
  setToken("");
  showLogin("Token expired or revoked: the API refused it. Log in with a valid token.");
};

async function boot() {
  clearTimeout(retryTimer);
  if (session.token) { notice(null); await enter(); return; }  // a refused token or a silent server says so there
  let health;
  try {
    health = await api("/health");
  } catch (err) {
    if (err.kind === "unreachable") { unreachable(err); return; }
    health = {};
  }
  notice(null);
  authEnabled = health.auth_enabled !== false;
  if (authEnabled && !session.token) { showLogin(""); return; }
  await enter();
}

async function login(event) {
  event.preventDefault();
  const token = $("token").value.trim();
  if (!token && authEnabled) { setStatus("enter an API token", true); return; }
  setToken(token);
  $("token").value = "";
  notice(null);
  await enter();
}

function logout() {
  setToken("");
  showLogin("");
}

async function enter() {
  try {
    const [constants, me, satellites] = await Promise.all([
      optional("/constants", {}), optional("/whoami", null), optional("/satellites", [])]);
    if (!me) await api("/scenarios");  // a server without /whoami: any viewer route checks the token
    state.constants = constants;
    state.role = me ? me.role : null;
    state.satellites = satellites;
    for (const s of state.satellites) {
      if (s.latest_telemetry_utc) state.lastPacketS[s.name] = Date.parse(s.latest_telemetry_utc) / 1000;
    }
  } catch (err) {
    if (err.kind === "unauthorized" || err.kind === "unreachable") return;  // handled by the session hooks
    setStatus(`login failed: ${errorText(err)}`, true);
    return;
  }
  $("login").hidden = true;
  $("app").hidden = false;
  $("logout").hidden = !authEnabled;
  fill($("satellite-names"), state.satellites.map((s) => el("option", { value: s.name })));
  applyRole();
  connectLive();
  whatif.loadScenarios().catch((err) => setStatus(errorText(err), true));
  monitorsTimer = setTimeout(startMonitors, MONITORS_AFTER_MS);  // a satellite without plots still gets them
  await selectSatellite(defaultSatellite());
}

/** The satellite asked for (URL #satellite= or the field), else the last one if it has data, else the one with
 * the newest data. */
function defaultSatellite() {
  const asked = new URLSearchParams(location.hash.slice(1)).get("satellite") || $("satellite").value.trim();
  if (asked) return asked;
  const last = sessionStorage.getItem("acs-twin-satellite") || "";
  const withData = state.satellites.filter((s) => s.latest_telemetry_utc)
    .sort((a, b) => Date.parse(b.latest_telemetry_utc) - Date.parse(a.latest_telemetry_utc));
  if (!state.satellites.length) return last || "NOAA-20";
  if (withData.some((s) => s.name === last)) return last;
  return withData.length ? withData[0].name : last || state.satellites[0].name;
}

async function selectSatellite(name) {
  state.satellite = name;
  state.window = null;
  state.pass = null;
  state.info = {};
  $("satellite").value = name;
  sessionStorage.setItem("acs-twin-satellite", name);
  clearTelemetry();
  clearPasses();
  clearAlarms();
  clearDiagnoses();
  whatif.clearWhatif();
  fill($("twin-state"));
  notice(null);
  setStatus(`${name}: loading…`);
  loadArchive().catch((err) => setStatus(errorText(err), true));
  let names;
  const latest = fetchLatest();  // in parallel with the parameter list
  latest.catch(() => null);
  try {
    names = await loadParameters();
  } catch (err) {
    if (err.field === "satellite") {
      const known = state.satellites.map((s) => s.name).join(", ");
      notice("unknown", `Unknown satellite "${name}": nothing is archived under that name.`,
        known ? ` Known satellites: ${known}.` : "", " Check the name, or upload its telemetry in the Archive panel.");
      setStatus(`${name}: unknown satellite`, true);
    } else if (err.kind !== "unauthorized" && err.kind !== "unreachable") {
      setStatus(`${name}: ${errorText(err)}`, true);
    }
    renderAges();
    return;
  }
  if (!names.length) {
    notice("empty", `No telemetry yet for ${name}: upload packets, CSV or JSONL in the Archive panel, or connect a stream.`);
    setStatus(`${name}: no telemetry yet`);
    renderAges();
    return;
  }
  loadPasses().catch((err) => setStatus(errorText(err), true));
  loadAlarms().catch((err) => setStatus(errorText(err), true));
  loadDiagnoses().catch((err) => setStatus(errorText(err), true));
  loadTwin();
  // the archive's newest sample time (GET /satellites) lets the plots start before the latest values arrive
  const listed = state.satellites.find((s) => s.name === name);
  const known = listed && listed.latest_telemetry_utc ? Date.parse(listed.latest_telemetry_utc) / 1000 : null;
  if (known !== null) followLive(known);
  const newest = await loadLatest(latest).catch((err) => { setStatus(errorText(err), true); return null; });
  if (newest !== null) state.lastPacketS[name] = Math.max(state.lastPacketS[name] ?? -Infinity, newest);
  renderAges();
  setStatus(`${name} · newest telemetry ${isoUtc(newest)}`);
  if (known === null) followLive(newest);  // plots the newest telemetry (emits "window")
}

async function loadTwin() {
  const twin = await optional(`/satellites/${encodeURIComponent(state.satellite)}/twin`, null).catch(() => null);
  showTwin(twin);
}

/** The live twin's state in one line (GET /satellites/{name}/twin and the WebSocket topic "twin"). */
function showTwin(twin) {
  if (!twin) { fill($("twin-state")); return; }
  const residual = twin.attitude_residual_arcsec;
  const parts = [`twin ${twin.state || "?"}`];
  if (residual !== null && residual !== undefined) parts.push(`attitude residual ${residual.toFixed(1)} arcsec`);
  else parts.push(twin.model_note || "no ACS model configured");
  if (Number.isFinite(twin.twin_behind_telemetry_s)) parts.push(`${twin.twin_behind_telemetry_s.toFixed(1)} s behind telemetry`);
  if (twin.issues && twin.issues.length) parts.push(`${twin.issues.length} input issue(s): ${twin.issues[0].message}`);
  const box = $("twin-state");
  box.className = twin.stale ? "stale" : "";
  fill(box, parts.join(" · "));
}

on("plotted", ({ first, last }) => trimLiveWindow(first, last));
on("window", async () => {
  await plotSelected();
  whatif.defaultStart();
  whatif.draw();
});
on("plotted", () => {
  if (!painted && plots.size) {
    painted = true;
    performance.mark("acs-twin:first-meaningful-paint");  // the first data plot is on screen
    startMonitors();  // the 3D frames load after it, never holding it up
  }
});

function startMonitors() {
  clearTimeout(monitorsTimer);
  if (!monitorsShown) showMonitors(config.monitors);
  monitorsShown = true;
}
on("samples", ({ satellite, batch }) => {
  if (!state.satellites.some((s) => s.name === satellite)) state.satellites.push({ name: satellite, latest_telemetry_utc: null });
  if (satellite === state.satellite) appendLive(batch);
});
on("alarms", (data) => {
  if (data && data.satellite && data.satellite !== state.satellite) return;
  clearTimeout(alarmTimer);
  alarmTimer = setTimeout(() => {
    loadAlarms().catch((err) => setStatus(errorText(err), true));
    loadDiagnoses().catch((err) => setStatus(errorText(err), true));
  }, 100);
});
on("twin", (data) => { if (data && data.satellite === state.satellite) showTwin(data); });
on("unauthorized", () => session.onUnauthorized());
on("choose-satellite", (name) => { if (name !== state.satellite) selectSatellite(name); });
on("archive-changed", () => selectSatellite(state.satellite));
on("archive-committed", (data) => {
  // a commit whose samples did not come live (a large upload, a redecode): plots and latest values reload
  if (data.published || data.satellite !== state.satellite) return;
  clearTimeout(archiveTimer);
  archiveTimer = setTimeout(() => emit("archive-changed"), ARCHIVE_RELOAD_MS);
});

async function start() {
  try {
    config = await (await fetch("config.json")).json();
  } catch {
    setStatus("no config.json: using /api/v1 and no monitors");
  }
  session.base = config.api_base || session.base;
  session.onUnreachable = unreachable;
  $("login").addEventListener("submit", login);
  $("logout").addEventListener("click", logout);
  $("satellite-form").addEventListener("submit", (e) => { e.preventDefault(); selectSatellite($("satellite").value.trim()); });
  $("plot-btn").addEventListener("click", plotSelected);
  $("reset-zoom").addEventListener("click", resetZoom);
  $("follow-live").addEventListener("click", () => followLive(state.lastPacketS[state.satellite]));
  $("window-btn").addEventListener("click", windowFromInputs);
  $("export-csv").addEventListener("click", exportCsv);
  $("export-png").addEventListener("click", exportPng);
  $("show-cleared").addEventListener("change", () => loadAlarms().catch((err) => setStatus(errorText(err), true)));
  $("summary-btn").addEventListener("click", showSummary);
  $("summary-png").addEventListener("click", exportSummaryPng);
  $("summary-pdf").addEventListener("click", exportSummaryPdf);
  $("whatif").addEventListener("submit", whatif.runWhatif);
  $("whatif-against").addEventListener("change", whatif.showAgainst);
  $("duration").addEventListener("input", whatif.defaultStart);
  wireArchive();
  window.addEventListener("resize", resizePlots);
  // read-only handle for people debugging in the console (and the browser tests)
  window.acsTwin = { state, plotsIn: (selector) => [...plots].filter((u) => document.querySelector(selector).contains(u.root)) };
  await boot();
}

start();
