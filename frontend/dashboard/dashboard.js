// acs-twin operator dashboard: plain JS over the REST API (/api/v1, Bearer token), no build step.
// Panels: passes with completeness, parameter plots on one shared time axis (zoom, CSV/PNG export),
// alarms with acknowledge/shelve, what-if twin sessions compared with the actual pass telemetry (or a
// nominal simulation) on the pass time axis, monitors.
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
    throw Object.assign(new Error(message), { field: body && body.field });
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
  state.window = null;
  clearWhatif();
  const [passes] = await Promise.allSettled([loadPasses(), loadParameters(), loadAlarms(), loadScenarios()]);
  if (passes.status === "fulfilled" && !passes.value) await telemetryWindow().catch((e) => setStatus(e.message, true));
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
  return passes.length;
}

function selectPass(row, p) {
  for (const r of $("passes").querySelectorAll("tr.selected")) r.classList.remove("selected");
  row.classList.add("selected");
  const t0 = (p.received_start_ns ?? p.aos_ns) / 1e9, t1 = (p.received_end_ns ?? p.los_ns) / 1e9;
  state.window = [t0, t1];
  $("window-label").textContent = `pass ${p.id} · ${hhmmss(t0)} → ${hhmmss(t1)} UTC`;
  defaultWhatifStart();
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

function addPlot(container, title, t, columns, labels, colours, dashes = []) {
  const opts = {
    title, width: plotWidth(container), height: 170,
    cursor: { sync: { key: SYNC_KEY, setSeries: false }, drag: { x: true, y: false } },
    scales: { x: { time: true } },
    tzDate: (ts) => uPlot.tzDate(new Date(ts * 1e3), "Etc/UTC"),  // the whole dashboard speaks UTC
    axes: [AXIS, AXIS],
    legend: { live: true },
    series: [{}].concat(labels.map((label, i) => ({ label, stroke: colours[i % colours.length], width: 1.2, dash: dashes[i] }))),
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
// Default: a twin session aligned to the selected pass's telemetry at a chosen start, flying the fault
// hypothesis and its alternatives; residuals (twin − telemetry) per variant on the pass's time axis.
// Alternative: the previous nominal-vs-fault simulation job (no telemetry involved).
const GPS_MARGIN_S = 60;    // telemetry the twin reads before its start for the orbit fit (backend GPS_MARGIN_S)
const START_MARGIN_S = 60;  // default start: this much after the GPS margin into the pass
const RANK_KEYS = ["wheel_speed_max_rpm", "attitude_max_deg", "rate_max_deg_s"];  // best-match order
const WHEEL_DASHES = [[], [6, 3], [2, 3], [8, 3, 2, 3]];  // RW1 solid, RW2 dashed, RW3 dotted, RW4 dash-dot

async function loadScenarios() {
  const names = await api("/scenarios");
  $("scenario").replaceChildren(...names.map((n) => new Option(n, n)));
  if (names.includes("somov-ge4-scan")) $("scenario").value = "somov-ge4-scan";
}

const utcInput = (s) => new Date(s * 1000).toISOString().slice(0, 23);
const inputUtc = (v) => (v ? Date.parse(v.endsWith("Z") ? v : v + "Z") / 1000 : NaN);

function defaultWhatifStart() {
  if (!state.window) return;
  const [t0, t1] = state.window;
  const duration = Number($("duration").value);
  const latest = Math.max(t0 + GPS_MARGIN_S, t1 - duration);
  $("whatif-start").value = utcInput(Math.min(t0 + GPS_MARGIN_S + START_MARGIN_S, latest));
}

async function telemetryWindow() {
  // no predicted pass (e.g. the emulated demo satellite): the archived telemetry's span is the window
  const names = Array.from($("parameter-list").options).map((o) => o.value);
  if (!names.length) return;
  const s = await api(`/parameters/${encodeURIComponent(names[0])}/samples?satellite=${sat()}&max_points=100`);
  if (!s.t_utc_ns.length) return;
  state.window = [s.t_utc_ns[0] / 1e9, s.t_utc_ns[s.t_utc_ns.length - 1] / 1e9];
  $("window-label").textContent = `telemetry ${hhmmss(state.window[0])} → ${hhmmss(state.window[1])} UTC`;
  defaultWhatifStart();
}

function faultSpec(value, onset) {
  const [target, index, type] = value.split(":");
  const spec = { target, index: Number(index), type, onset_s: onset };
  if (type === "gain") spec.gain = 0.5;
  if (type === "bias") spec.value = 1e-4;
  return spec;
}

function faultText(value, onset) {
  // TARGET:INDEX:TYPE@ONSET[,gain=G|,value=V], the twin sessions' hypothesis syntax
  const spec = faultSpec(value, onset);
  const extra = spec.gain !== undefined ? `,gain=${spec.gain}` : spec.value !== undefined ? `,value=${spec.value}` : "";
  return `${value}@${onset}${extra}`;
}

function parseAlternatives() {
  const alternatives = {};
  if ($("alt-nominal").checked) alternatives.nominal = [];
  for (const line of $("alternatives").value.split("\n").map((l) => l.trim()).filter(Boolean)) {
    const colon = line.indexOf(":");
    const name = line.slice(0, colon).trim();
    if (colon < 1 || !name || name.includes(" ")) throw Object.assign(new Error(`alternatives: "${line}" is not "name: fault …"`), { field: "alternatives" });
    alternatives[name] = line.slice(colon + 1).trim().split(/\s+/).filter(Boolean);
  }
  return alternatives;
}

function clearWhatif() {
  state.whatif = null;
  state.twin = null;
  $("whatif-summary").replaceChildren();
  const box = $("whatif-plots");
  const old = state.plots.filter((u) => box.contains(u.root));
  for (const u of old) u.destroy();
  state.plots = state.plots.filter((u) => !old.includes(u));
  box.replaceChildren();
}

function showError(prefix, err) {
  $("whatif-status").textContent = `${prefix}: ${err.message}` + (err.field ? ` (field: ${err.field})` : "");
  $("whatif-status").classList.add("error");
  $("whatif-progress").hidden = true;
}

async function runWhatif(event) {
  event.preventDefault();
  clearWhatif();
  $("whatif-status").classList.remove("error");
  const onset = Number($("onset").value), duration = Number($("duration").value);
  const checked = Array.from(document.querySelectorAll("input[name=fault]:checked")).map((c) => c.value);
  try {
    if ($("whatif-against").value === "actual") await startTwin(checked, onset, duration);
    else await startSimulation(checked, onset, duration);
  } catch (err) {
    showError("rejected", err);
  }
}

async function startTwin(checked, onset, duration) {
  const start = inputUtc($("whatif-start").value);
  if (!Number.isFinite(start)) throw Object.assign(new Error("choose a start instant within the pass"), { field: "align_utc" });
  const body = { satellite: state.satellite, dictionary: $("whatif-dictionary").value.trim(), scenario: $("scenario").value,
    align_utc: isoOf(start), duration_s: duration, faults: checked.map((v) => faultText(v, onset)),
    alternatives: parseAlternatives() };
  if ($("whatif-epoch").value) body.scenario_epoch_utc = isoOf(inputUtc($("whatif-epoch").value));
  const session = await api("/twin/sessions", { method: "POST", json: body });
  state.twinAlternatives = body.alternatives;  // as sent: the table names each variant's faults
  $("whatif-status").textContent = `twin ${session.id.slice(0, 8)} ${session.status}`;
  $("whatif-progress").hidden = false;
  poll(`/twin/sessions/${session.id}`, `twin ${session.id.slice(0, 8)}`, (s) => showTwin(s));
}

async function startSimulation(checked, onset, duration) {
  const variants = [{ name: "nominal" }, { name: "what-if", faults: checked.map((v) => faultSpec(v, onset)) }];
  const body = { library: $("scenario").value, set: [`duration_s=${duration}`, `variants=${JSON.stringify(variants)}`] };
  const job = await api("/simulations", { method: "POST", json: body });
  $("whatif-status").textContent = `job ${job.id} queued`;
  $("whatif-progress").hidden = false;
  poll(`/simulations/${job.id}`, `job ${job.id}`, (j) => showWhatif(j.id, j));
}

function poll(path, label, done) {
  clearTimeout(state.whatifPoll);
  state.whatifPoll = setTimeout(async () => {
    let run;
    try { run = await api(path); } catch (err) { showError(label, err); return; }
    $("whatif-progress").value = run.progress;
    $("whatif-status").textContent = `${label}: ${run.status} ${Math.round(100 * run.progress)} %`;
    if (run.status === "queued" || run.status === "running") { poll(path, label, done); return; }
    if (run.status !== "succeeded") { showError(label, new Error(`${run.status}${run.error ? ` — ${run.error}` : ""}`)); return; }
    try { await done(run); } catch (err) { showError(label, err); }
  }, WHATIF_POLL_MS);
}

// -- against the actual pass: residuals of every variant ------------------------------------------
function bestVariant(summaries) {
  // smallest largest-residual, compared key by key in RANK_KEYS order (wheel speeds first: the faults act there)
  const better = (a, b) => {
    for (const k of RANK_KEYS) if (summaries[a][k] !== summaries[b][k]) return summaries[a][k] < summaries[b][k];
    return false;
  };
  return Object.keys(summaries).reduce((best, name) => (better(name, best) ? name : best));
}

function twinTable(variants, summaries, hypotheses) {
  const best = bestVariant(summaries);
  const table = document.createElement("table");
  table.id = "twin-summary-table";
  const compared = variants.map((n) => summaries[n].samples).join("/");
  table.createCaption().textContent = `best match with the telemetry: ${best} (ranked by ${RANK_KEYS.join(", then ")};` +
    ` ${compared} instants compared)`;
  const head = table.createTHead().insertRow();
  for (const h of ["variant", "faults", "att. max °", "rate max °/s", "wheel max rpm"]) head.insertCell().textContent = h;
  const body = table.createTBody();
  for (const name of variants) {
    const s = summaries[name], tr = body.insertRow();
    tr.dataset.variant = name;
    tr.classList.toggle("best", name === best);
    tr.insertCell().textContent = name;
    tr.insertCell().textContent = hypotheses[name].join(" ") || "none";
    for (const k of ["attitude_max_deg", "rate_max_deg_s", "wheel_speed_max_rpm"]) tr.insertCell().textContent = Number(s[k].toPrecision(4));
  }
  return table;
}

async function showTwin(session) {
  const answers = await Promise.all(session.variants.map((_, i) =>
    api(`/twin/sessions/${session.id}/residuals?variant=${i}&max_points=1500`)));
  const hypotheses = { twin: session.faults };
  for (const name of session.variants.slice(1)) hypotheses[name] = state.twinAlternatives[name] || [];
  $("whatif-summary").replaceChildren(twinTable(session.variants, answers[0].summaries, hypotheses));
  state.twin = { t0: session.align_utc_ns / 1e9, answers };
  drawWhatifOnPassAxis();
}

function alignedColumns(answers, pick) {
  // variants share the twin's instants but each keeps those with telemetry: union axis, nulls elsewhere
  const t = Array.from(new Set(answers.flatMap((a) => a.t_s))).sort((x, y) => x - y);
  const index = new Map(t.map((x, i) => [x, i]));
  const cols = answers.flatMap((a) => pick(a).map((values) => {
    const col = new Array(t.length).fill(null);
    a.t_s.forEach((x, i) => { col[index.get(x)] = values[i]; });
    return col;
  }));
  return { t, cols };
}

function drawTwin(box) {
  const { t0, answers } = state.twin;
  const names = answers.map((a) => a.variant);
  const nWheels = answers[0].wheel_speed_rpm.length ? answers[0].wheel_speed_rpm[0].length : 0;
  const charts = [
    ["attitude difference (°): twin − telemetry", (a) => [a.attitude_deg], names],
    ["rate difference (°/s): twin − telemetry", (a) => [a.rate_deg_s], names],
    ["wheel-speed differences (rpm): twin − telemetry",
      (a) => Array.from({ length: nWheels }, (_, w) => a.wheel_speed_rpm.map((row) => row[w])),
      names.flatMap((n) => Array.from({ length: nWheels }, (_, w) => `${n} RW${w + 1}`))],
  ];
  for (const [title, pick, labels] of charts) {
    const { t, cols } = alignedColumns(answers, pick);
    const perVariant = cols.length / names.length;  // one colour per variant, one dash pattern per wheel
    const colours = cols.map((_, i) => COLOURS[Math.floor(i / perVariant) % COLOURS.length]);
    const dashes = cols.map((_, i) => WHEEL_DASHES[i % perVariant % WHEEL_DASHES.length]);
    const div = document.createElement("div");
    div.className = "twin-chart";
    box.appendChild(div);
    addPlot(div, title, t.map((s) => t0 + s), cols, labels, colours, dashes);
  }
}

// -- against the nominal simulation ----------------------------------------------------------------
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

state.whatif = null;  // {nominal, whatif} series of the last simulation run, in seconds from its start
state.twin = null;    // {t0, answers} residuals of the last twin session, per variant
state.twinAlternatives = {};  // alternatives of the last twin session request, by name

async function showWhatif(id, job) {
  $("whatif-summary").replaceChildren(summaryTable(job.summary));
  const get = (name, member) => api(`/simulations/${id}/series/${name}?member=${member}&max_points=1500`);
  const [nominal, whatif] = await Promise.all([get("wheel_speed_rad_s", 0), get("wheel_speed_rad_s", 1)]);
  state.whatif = { nominal, whatif };
  drawWhatifOnPassAxis();
}

function drawSimulation(box) {
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

function drawWhatifOnPassAxis() {
  const box = $("whatif-plots");
  if (!state.whatif && !state.twin) return;
  const old = state.plots.filter((u) => box.contains(u.root));
  for (const u of old) u.destroy();
  state.plots = state.plots.filter((u) => !old.includes(u));
  box.replaceChildren();
  if (state.twin) drawTwin(box);
  else drawSimulation(box);
}

function showAgainst() {
  const twin = $("whatif-against").value === "actual";
  for (const el of document.querySelectorAll("#whatif .twin-only")) el.hidden = !twin;
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
  $("whatif-against").addEventListener("change", showAgainst);
  $("duration").addEventListener("input", defaultWhatifStart);
  window.addEventListener("resize", () => {
    for (const u of state.plots) u.setSize({ width: plotWidth(u.root.parentElement), height: 170 });
  });
  if (state.token) await login();
}

start();
