// acs-twin operator dashboard: plain JS over the REST API (/api/v1, Bearer token), no build step.
// Panels: passes with completeness, parameter plots on one shared time axis (zoom, CSV/PNG export),
// alarms with acknowledge/shelve, what-if runs with progress compared on the pass time axis, monitors.
"use strict";

const state = {
  apiBase: "/api/v1",
  monitors: {},
  token: sessionStorage.getItem("acs-twin-token") || "",
  satellite: sessionStorage.getItem("acs-twin-satellite") || "NOAA-20",
  window: null,        // [t0_s, t1_s] of the selected pass (Unix seconds)
  plots: [],           // uPlot instances sharing the time axis
  series: [],          // {label, t, v} plotted, for CSV export
  syncing: false,
  whatifPoll: null,
};
const $ = (id) => document.getElementById(id);
const SYNC_KEY = "acs-twin-time";
const WHATIF_POLL_MS = 400;
const SHELVE_S = 3600;

function setStatus(text, error = false) {
  const el = $("status");
  el.textContent = text;
  el.classList.toggle("error", error);
}

async function api(path, options = {}) {
  const headers = Object.assign({ Authorization: `Bearer ${state.token}` }, options.headers || {});
  if (options.json !== undefined) {
    headers["Content-Type"] = "application/json";
    options.body = JSON.stringify(options.json);
  }
  const response = await fetch(state.apiBase + path, { method: options.method || "GET", headers, body: options.body });
  const body = response.headers.get("content-type")?.includes("json") ? await response.json() : await response.text();
  if (!response.ok) {
    const message = body && body.message ? body.message : `${response.status} ${response.statusText}`;
    throw new Error(message);
  }
  return body;
}

const sat = () => encodeURIComponent(state.satellite);
const isoOf = (s) => new Date(s * 1000).toISOString();
const hhmmss = (s) => new Date(s * 1000).toISOString().slice(0, 19).replace("T", " ");

// ---- login -------------------------------------------------------------------------------------
async function login(event) {
  if (event) event.preventDefault();
  state.token = $("token").value.trim() || state.token;
  state.satellite = $("satellite").value.trim() || "NOAA-20";
  if (!state.token) { setStatus("enter an API token", true); return; }
  try {
    await api("/scenarios");
  } catch (err) {
    setStatus(`login failed: ${err.message}`, true);
    return;
  }
  sessionStorage.setItem("acs-twin-token", state.token);
  sessionStorage.setItem("acs-twin-satellite", state.satellite);
  $("token").value = "";
  $("app").hidden = false;
  $("logout").hidden = false;
  setStatus(`logged in · ${state.satellite}`);
  await Promise.allSettled([loadPasses(), loadParameters(), loadAlarms(), loadScenarios()]);
  showMonitors();
}

function logout() {
  sessionStorage.removeItem("acs-twin-token");
  state.token = "";
  $("app").hidden = true;
  $("logout").hidden = true;
  setStatus("not logged in");
}

// ---- passes ------------------------------------------------------------------------------------
async function loadPasses() {
  const passes = await api(`/passes?satellite=${sat()}`);
  const body = $("passes").querySelector("tbody");
  body.replaceChildren();
  for (const p of passes) {
    const aos = p.aos_ns / 1e9, los = p.los_ns / 1e9;
    const pct = Math.round(100 * (p.completeness ?? 0));
    const tr = document.createElement("tr");
    tr.dataset.passId = p.id;
    tr.innerHTML = `<td>${p.id}</td><td>${p.station}</td><td>${hhmmss(aos)}</td>` +
      `<td>${((los - aos) / 60).toFixed(1)}</td>` +
      `<td><span class="bar ${pct >= 99 ? "" : pct >= 80 ? "partial" : "poor"}" style="width:${pct / 2}px"></span>${pct} %</td>`;
    tr.addEventListener("click", () => selectPass(tr, p));
    body.appendChild(tr);
  }
  if (!passes.length) body.innerHTML = `<tr><td colspan="5">no passes for ${state.satellite}</td></tr>`;
}

function selectPass(row, p) {
  for (const r of $("passes").querySelectorAll("tr.selected")) r.classList.remove("selected");
  row.classList.add("selected");
  const t0 = (p.received_start_ns ?? p.aos_ns) / 1e9, t1 = (p.received_end_ns ?? p.los_ns) / 1e9;
  state.window = [t0, t1];
  $("window-label").textContent = `pass ${p.id} · ${hhmmss(t0)} → ${hhmmss(t1)} UTC`;
  plotSelected();
}

// ---- parameter plots on one time axis ------------------------------------------------------------
async function loadParameters() {
  const params = await api(`/parameters?satellite=${sat()}`);
  const list = $("parameter-list");
  list.replaceChildren(...Object.keys(params).sort().map((name) => new Option(name, name)));
}

function plotWidth(container) {
  return Math.max(320, container.clientWidth - 10);
}

function syncScales(source) {
  if (state.syncing) return;
  const { min, max } = source.scales.x;
  state.syncing = true;
  for (const u of state.plots) if (u !== source) u.setScale("x", { min, max });
  state.syncing = false;
}

function addPlot(container, title, t, columns, labels, colours) {
  const opts = {
    title, width: plotWidth(container), height: 170,
    cursor: { sync: { key: SYNC_KEY, setSeries: false }, drag: { x: true, y: false } },
    scales: { x: { time: true } },
    axes: [AXIS, AXIS],
    legend: { live: true },
    series: [{}].concat(labels.map((label, i) => ({ label, stroke: colours[i % colours.length], width: 1.2 }))),
    hooks: { setScale: [(u, key) => { if (key === "x") syncScales(u); }] },
  };
  const u = new uPlot(opts, [t].concat(columns), container);
  state.plots.push(u);
  return u;
}

const AXIS = { stroke: "#c8ccd2", grid: { stroke: "#2e333b", width: 1 }, ticks: { stroke: "#2e333b" } };
const COLOURS = ["#4aa3ff", "#ff7043", "#48c774", "#ffd54f", "#ba68c8", "#4dd0e1", "#f06292"];

async function plotSelected() {
  const names = Array.from($("parameter-list").selectedOptions).map((o) => o.value);
  const box = $("plots");
  for (const u of state.plots) u.destroy();
  state.plots = [];
  state.series = [];
  box.replaceChildren();
  if (!names.length) { box.textContent = "select parameters and a pass"; return; }
  const range = state.window ? `&start=${isoOf(state.window[0])}&end=${isoOf(state.window[1])}` : "";
  for (const name of names) {
    try {
      const s = await api(`/parameters/${encodeURIComponent(name)}/samples?satellite=${sat()}${range}&max_points=2000`);
      const t = s.t_utc_ns.map((ns) => ns / 1e9);
      state.series.push({ label: name, t, v: s.values });
      const div = document.createElement("div");
      box.appendChild(div);
      addPlot(div, `${name} (${s.total_points} samples)`, t, [s.values], [name], COLOURS);
    } catch (err) {
      setStatus(`${name}: ${err.message}`, true);
    }
  }
  drawWhatifOnPassAxis();
}

function resetZoom() {
  for (const u of state.plots) {
    const t = u.data[0];
    if (t.length) u.setScale("x", { min: t[0], max: t[t.length - 1] });
  }
}

function download(name, blob) {
  const a = document.createElement("a");
  a.href = URL.createObjectURL(blob);
  a.download = name;
  document.body.appendChild(a);
  a.click();
  a.remove();
}

function exportCsv() {
  const rows = ["parameter,t_utc,value"];
  const x = state.plots.length ? state.plots[0].scales.x : { min: -Infinity, max: Infinity };
  for (const s of state.series) {
    for (let i = 0; i < s.t.length; i++) {
      if (s.t[i] >= x.min && s.t[i] <= x.max) rows.push(`${s.label},${isoOf(s.t[i])},${s.v[i]}`);
    }
  }
  download("acs-twin-parameters.csv", new Blob([rows.join("\n") + "\n"], { type: "text/csv" }));
}

function exportPng() {
  if (!state.plots.length) return;
  const canvases = state.plots.map((u) => u.ctx.canvas);
  const out = document.createElement("canvas");
  out.width = Math.max(...canvases.map((c) => c.width));
  out.height = canvases.reduce((h, c) => h + c.height, 0);
  const ctx = out.getContext("2d");
  ctx.fillStyle = "#1d2026";
  ctx.fillRect(0, 0, out.width, out.height);
  let y = 0;
  for (const c of canvases) { ctx.drawImage(c, 0, y); y += c.height; }
  out.toBlob((blob) => download("acs-twin-parameters.png", blob), "image/png");
}

// ---- alarms ------------------------------------------------------------------------------------
async function loadAlarms() {
  const alarms = await api(`/alarms?satellite=${sat()}`);
  const body = $("alarms").querySelector("tbody");
  body.replaceChildren();
  for (const a of alarms) {
    const tr = document.createElement("tr");
    tr.className = `state-${a.state}`;
    tr.innerHTML = `<td>${a.parameter}</td><td>${a.state}</td><td>${a.severity} (${a.level})</td>` +
      `<td>${hhmmss(a.first_t_ns / 1e9)}</td><td></td>`;
    const cell = tr.lastChild;
    for (const [label, action, body_] of [["ack", "acknowledge", undefined], ["shelve 1 h", "shelve", { duration_s: SHELVE_S }]]) {
      const b = document.createElement("button");
      b.className = "small";
      b.textContent = label;
      b.addEventListener("click", async (e) => {
        e.stopPropagation();
        try { await api(`/alarms/${a.id}/${action}`, { method: "POST", json: body_ }); await loadAlarms(); }
        catch (err) { setStatus(`alarm ${a.id}: ${err.message}`, true); }
      });
      cell.appendChild(b);
    }
    body.appendChild(tr);
  }
  if (!alarms.length) body.innerHTML = `<tr><td colspan="5">no active alarms</td></tr>`;
}

// ---- what-if -----------------------------------------------------------------------------------
async function loadScenarios() {
  const names = await api("/scenarios");
  $("scenario").replaceChildren(...names.map((n) => new Option(n, n)));
  if (names.includes("somov-ge4-scan")) $("scenario").value = "somov-ge4-scan";
}

function faultSpec(value, onset) {
  const [target, index, type] = value.split(":");
  const spec = { target, index: Number(index), type, onset_s: onset };
  if (type === "gain") spec.gain = 0.5;
  if (type === "bias") spec.value = 1e-4;
  return spec;
}

async function runWhatif(event) {
  event.preventDefault();
  const onset = Number($("onset").value), duration = Number($("duration").value);
  const faults = Array.from(document.querySelectorAll("input[name=fault]:checked")).map((c) => faultSpec(c.value, onset));
  const variants = [{ name: "nominal" }, { name: "what-if", faults }];
  const body = { library: $("scenario").value, set: [`duration_s=${duration}`, `variants=${JSON.stringify(variants)}`] };
  $("whatif-summary").replaceChildren();
  $("whatif-plots").replaceChildren();
  try {
    const job = await api("/simulations", { method: "POST", json: body });
    $("whatif-status").textContent = `job ${job.id} queued`;
    $("whatif-progress").hidden = false;
    pollWhatif(job.id);
  } catch (err) {
    $("whatif-status").textContent = `rejected: ${err.message}`;
  }
}

function pollWhatif(id) {
  clearTimeout(state.whatifPoll);
  state.whatifPoll = setTimeout(async () => {
    let job;
    try { job = await api(`/simulations/${id}`); } catch (err) { $("whatif-status").textContent = err.message; return; }
    $("whatif-progress").value = job.progress;
    $("whatif-status").textContent = `job ${id}: ${job.status} ${Math.round(100 * job.progress)} %`;
    if (job.status === "queued" || job.status === "running") { pollWhatif(id); return; }
    if (job.status === "succeeded") await showWhatif(id, job);
    else $("whatif-status").textContent += job.error ? ` — ${job.error}` : "";
  }, WHATIF_POLL_MS);
}

function summaryTable(summary) {
  // one column per variant (nominal twin, what-if), one row per scalar metric
  const variants = (summary && summary.variants) || [summary || {}];
  const table = document.createElement("table");
  table.id = "whatif-summary-table";
  const head = table.createTHead().insertRow();
  head.insertCell().textContent = "metric";
  for (const v of variants) head.insertCell().textContent = v.variant || "run";
  const keys = Object.keys(variants[0]).filter((k) => typeof variants[0][k] === "number");
  for (const k of keys) {
    const tr = table.insertRow();
    tr.insertCell().textContent = k;
    for (const v of variants) tr.insertCell().textContent = Number((v[k] ?? NaN).toPrecision(5));
  }
  return table;
}

state.whatif = null;  // {t_s, nominal, whatif} series of the last run, in seconds from its start

async function showWhatif(id, job) {
  $("whatif-summary").replaceChildren(summaryTable(job.summary));
  const get = (name, member) => api(`/simulations/${id}/series/${name}?member=${member}&max_points=1500`);
  const [nominal, whatif] = await Promise.all([get("wheel_speed_rad_s", 0), get("wheel_speed_rad_s", 1)]);
  state.whatif = { nominal, whatif };
  drawWhatifOnPassAxis();
}

function drawWhatifOnPassAxis() {
  const box = $("whatif-plots");
  if (!state.whatif) return;
  const old = state.plots.filter((u) => box.contains(u.root));
  for (const u of old) u.destroy();
  state.plots = state.plots.filter((u) => !old.includes(u));
  box.replaceChildren();
  const { nominal, whatif } = state.whatif;
  const t0 = state.window ? state.window[0] : 0;  // on the selected pass's time axis, for comparison
  const t = nominal.t_s.map((s) => t0 + s);
  const rpm = 30 / Math.PI;
  const cols = [], labels = [];
  nominal.columns.forEach((c, i) => {
    cols.push(nominal.values.map((row) => row[i] * rpm)); labels.push(`RW${i + 1} nominal`);
    cols.push(whatif.values.map((row) => row[i] * rpm)); labels.push(`RW${i + 1} what-if`);
  });
  const n = Math.min(t.length, whatif.t_s.length);
  const div = document.createElement("div");
  div.id = "whatif-chart";
  box.appendChild(div);
  addPlot(div, "wheel speeds (rpm): nominal vs what-if", t.slice(0, n), cols.map((c) => c.slice(0, n)), labels, COLOURS);
}

// ---- monitors ----------------------------------------------------------------------------------
function showMonitors() {
  const box = $("monitors");
  box.replaceChildren();
  const entries = Object.entries(state.monitors);
  if (!entries.length) { box.textContent = "no twin monitors configured"; return; }
  for (const [role, url] of entries) {
    const fig = document.createElement("figure");
    fig.innerHTML = `<figcaption>${role} — <a href="${url}" target="_blank" rel="noopener">open on its own screen</a></figcaption>`;
    const frame = document.createElement("iframe");
    frame.src = url;
    frame.title = `${role} monitor`;
    frame.loading = "lazy";
    fig.appendChild(frame);
    box.appendChild(fig);
  }
}

// ---- start -------------------------------------------------------------------------------------
async function start() {
  try {
    const config = await (await fetch("config.json")).json();
    state.apiBase = config.api_base || state.apiBase;
    state.monitors = config.monitors || {};
  } catch (err) {
    setStatus("no config.json: using /api/v1 and no monitors");
  }
  $("satellite").value = state.satellite;
  $("login").addEventListener("submit", login);
  $("logout").addEventListener("click", logout);
  $("plot-btn").addEventListener("click", plotSelected);
  $("reset-zoom").addEventListener("click", resetZoom);
  $("export-csv").addEventListener("click", exportCsv);
  $("export-png").addEventListener("click", exportPng);
  $("refresh-alarms").addEventListener("click", () => loadAlarms().catch((e) => setStatus(e.message, true)));
  $("whatif").addEventListener("submit", runWhatif);
  window.addEventListener("resize", () => {
    for (const u of state.plots) u.setSize({ width: plotWidth(u.root.parentElement), height: 170 });
  });
  if (state.token) await login();
}

start();
