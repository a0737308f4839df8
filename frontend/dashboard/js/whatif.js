// What-if: a twin session aligned to the chosen window's telemetry at a start instant, flying a fault
// hypothesis and alternatives (residuals twin − telemetry per variant on the window's time axis, the
// server's verdict: the best match only when a variant fits within the sensors' noise, otherwise "no
// hypothesis fits" with every variant's residuals), or a nominal-vs-fault simulation job without telemetry.
import { api, errorText } from "./api.js";
import { $, el, fill } from "./dom.js";
import { inputUtc, isoUtc, utcInput } from "./format.js";
import { COLOURS, DASHES, destroyPlots, timePlot } from "./plots.js";
import { state } from "./state.js";

const POLL_MS = 400;
const START_MARGIN_S = 60;  // default start: this much after the GPS margin into the window
const RESIDUAL_COLUMNS = [  // [summary key, header]: the RMS pair is what the server's verdict holds against the noise
  ["attitude_rms_arcsec", "att. RMS ″"], ["wheel_speed_rms_rpm", "wheel RMS rpm"],
  ["attitude_max_deg", "att. max °"], ["rate_max_deg_s", "rate max °/s"], ["wheel_speed_max_rpm", "wheel max rpm"],
];
let pollTimer = null;
let last = { twin: null, simulation: null, alternatives: {} };

const gpsMarginS = () => state.constants.gps_margin_s ?? 60;  // the twin's orbit-fit margin, from the server

export async function loadScenarios() {
  const names = await api("/scenarios");
  fill($("scenario"), names.map((n) => el("option", { value: n }, n)));
  if (names.includes("somov-ge4-scan")) $("scenario").value = "somov-ge4-scan";
}

export function defaultStart() {
  if (!state.window) return;
  const [t0, t1] = state.window;
  const duration = Number($("duration").value);
  const latest = Math.max(t0 + gpsMarginS(), t1 - duration);
  $("whatif-start").value = utcInput(Math.min(t0 + gpsMarginS() + START_MARGIN_S, latest));
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

export function clearWhatif() {
  clearTimeout(pollTimer);
  last = { twin: null, simulation: null, alternatives: {} };
  fill($("whatif-summary"));
  destroyPlots($("whatif-plots"));
  fill($("whatif-plots"));
  fill($("whatif-status"));
  $("whatif-progress").hidden = true;
}

function showError(prefix, err) {
  $("whatif-status").textContent = `${prefix}: ${errorText(err)}`;
  $("whatif-status").classList.add("error");
  $("whatif-progress").hidden = true;
}

export async function runWhatif(event) {
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
  if (!Number.isFinite(start)) throw Object.assign(new Error("choose a start instant within the window"), { field: "align_utc" });
  const body = { satellite: state.satellite, dictionary: $("whatif-dictionary").value.trim(), scenario: $("scenario").value,
    align_utc: isoUtc(start, 3), duration_s: duration, faults: checked.map((v) => faultText(v, onset)),
    alternatives: parseAlternatives() };
  if ($("whatif-epoch").value) body.scenario_epoch_utc = isoUtc(inputUtc($("whatif-epoch").value), 3);
  await submitTwin(body);
}

/** Fly fault hypotheses (name -> faults) beside the nominal twin against the telemetry from `alignS` (Unix s):
 * the diagnosis panel's top hypotheses, shown here like any what-if. */
export async function flyHypotheses({ satellite, dictionary, scenario, alignS, durationS, alternatives }) {
  clearWhatif();
  $("whatif-status").classList.remove("error");
  $("whatif-panel").scrollIntoView({ block: "start" });
  const body = { satellite, dictionary, scenario, align_utc: isoUtc(alignS, 3), duration_s: durationS, faults: [], alternatives };
  try {
    await submitTwin(body);
  } catch (err) {
    showError("rejected", err);
  }
}

async function submitTwin(body) {
  const session = await api("/twin/sessions", { method: "POST", json: body });
  last.alternatives = body.alternatives;  // as sent: the table names each variant's faults
  $("whatif-status").textContent = `twin ${session.id.slice(0, 8)} ${session.status}`;
  $("whatif-progress").hidden = false;
  poll(`/twin/sessions/${session.id}`, `twin ${session.id.slice(0, 8)}`, showTwin);
}

async function startSimulation(checked, onset, duration) {
  const variants = [{ name: "nominal" }, { name: "what-if", faults: checked.map((v) => faultSpec(v, onset)) }];
  const body = { library: $("scenario").value, set: [`duration_s=${duration}`, `variants=${JSON.stringify(variants)}`] };
  const job = await api("/simulations", { method: "POST", json: body });
  $("whatif-status").textContent = `job ${job.id} queued`;
  $("whatif-progress").hidden = false;
  poll(`/simulations/${job.id}`, `job ${job.id}`, showSimulation);
}

function poll(path, label, done) {
  clearTimeout(pollTimer);
  pollTimer = setTimeout(async () => {
    let run;
    try { run = await api(path); } catch (err) { showError(label, err); return; }
    $("whatif-progress").value = run.progress;
    $("whatif-status").textContent = `${label}: ${run.status} ${Math.round(100 * run.progress)} %`;
    if (run.status === "queued" || run.status === "running") { poll(path, label, done); return; }
    if (run.status !== "succeeded") { showError(label, new Error(`${run.status}${run.error ? ` — ${run.error}` : ""}`)); return; }
    try { await done(run); } catch (err) { showError(label, err); }
  }, POLL_MS);
}

function verdictCaption(bestMatch, verdict, compared) {
  // the server decides (GET …/residuals: best_match, verdict); the dashboard never ranks on its own
  const head = bestMatch ? `best match with the telemetry: ${bestMatch}` : "no hypothesis fits the telemetry";
  return el("caption", { class: bestMatch ? "fits" : "none-fits" }, `${head} — ${verdict} (${compared} instants compared)`);
}

function twinTable(variants, answer, hypotheses) {
  const { summaries, best_match: bestMatch, verdict } = answer;
  const compared = variants.map((n) => summaries[n].samples).join("/");
  const rows = variants.map((name) => {
    const s = summaries[name];
    return el("tr", { class: name === bestMatch ? "best" : "", dataset: { variant: name } },
      el("td", {}, name), el("td", {}, hypotheses[name].join(" ") || "none"),
      RESIDUAL_COLUMNS.map(([k]) => el("td", {}, s[k] === undefined ? "—" : String(Number(s[k].toPrecision(4))))));
  });
  return el("table", { id: "twin-summary-table" }, verdictCaption(bestMatch, verdict, compared),
    el("thead", {}, el("tr", {}, ["variant", "faults", ...RESIDUAL_COLUMNS.map(([, h]) => h)].map((h) => el("th", {}, h)))),
    el("tbody", {}, rows));
}

async function showTwin(session) {
  const answers = await Promise.all(session.variants.map((_, i) =>
    api(`/twin/sessions/${session.id}/residuals?variant=${i}&max_points=1500`)));
  const hypotheses = { twin: session.faults };
  for (const name of session.variants.slice(1)) hypotheses[name] = last.alternatives[name] || [];
  fill($("whatif-summary"), twinTable(session.variants, answers[0], hypotheses));
  last.twin = { t0: session.align_utc_ns / 1e9, answers };
  draw();
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
  const { t0, answers } = last.twin;
  const names = answers.map((a) => a.variant);
  const nWheels = answers[0].wheel_speed_rpm.length ? answers[0].wheel_speed_rpm[0].length : 0;
  const charts = [
    ["attitude difference: twin − telemetry", "deg", (a) => [a.attitude_deg], names],
    ["rate difference: twin − telemetry", "deg/s", (a) => [a.rate_deg_s], names],
    ["wheel-speed differences: twin − telemetry", "rpm",
      (a) => Array.from({ length: nWheels }, (_, w) => a.wheel_speed_rpm.map((row) => row[w])),
      names.flatMap((n) => Array.from({ length: nWheels }, (_, w) => `${n} RW${w + 1}`))],
  ];
  for (const [title, units, pick, labels] of charts) {
    const { t, cols } = alignedColumns(answers, pick);
    const perVariant = cols.length / names.length;  // one colour per variant, one dash pattern per wheel
    const colours = cols.map((_, i) => COLOURS[Math.floor(i / perVariant) % COLOURS.length]);
    const dashes = cols.map((_, i) => DASHES[i % perVariant % DASHES.length]);
    const div = el("div", { class: "twin-chart" });
    box.append(div);
    timePlot(div, t.map((s) => t0 + s), cols, { title: `${title} [${units}]`, labels, colours, dashes, info: { units } });
  }
}

function summaryTable(summary) {
  // one column per variant (nominal twin, what-if), one row per scalar metric
  const variants = (summary && summary.variants) || [summary || {}];
  const keys = Object.keys(variants[0]).filter((k) => typeof variants[0][k] === "number");
  return el("table", { id: "whatif-summary-table" },
    el("thead", {}, el("tr", {}, el("th", {}, "metric"), variants.map((v) => el("th", {}, v.variant || "run")))),
    el("tbody", {}, keys.map((k) => el("tr", {}, el("td", {}, k),
      variants.map((v) => el("td", {}, String(Number((v[k] ?? NaN).toPrecision(5)))))))));
}

async function showSimulation(job) {
  fill($("whatif-summary"), summaryTable(job.summary));
  const get = (name, member) => api(`/simulations/${job.id}/series/${name}?member=${member}&max_points=1500`);
  const [nominal, whatif] = await Promise.all([get("wheel_speed_rad_s", 0), get("wheel_speed_rad_s", 1)]);
  last.simulation = { nominal, whatif };
  draw();
}

function drawSimulation(box) {
  const { nominal, whatif } = last.simulation;
  const t0 = state.window ? state.window[0] : 0;  // on the chosen window's time axis, for comparison
  const t = nominal.t_s.map((s) => t0 + s);
  const rpm = 30 / Math.PI;
  const cols = [], labels = [];
  nominal.columns.forEach((c, i) => {
    cols.push(nominal.values.map((row) => row[i] * rpm)); labels.push(`RW${i + 1} nominal`);
    cols.push(whatif.values.map((row) => row[i] * rpm)); labels.push(`RW${i + 1} what-if`);
  });
  const n = Math.min(t.length, whatif.t_s.length);
  const div = el("div", { id: "whatif-chart" });
  box.append(div);
  timePlot(div, t.slice(0, n), cols.map((c) => c.slice(0, n)),
    { title: "wheel speeds: nominal vs what-if [rpm]", labels, info: { units: "rpm" } });
}

/** Redraw the what-if result (after a new window, the time axis moved). */
export function draw() {
  const box = $("whatif-plots");
  if (!last.twin && !last.simulation) return;
  destroyPlots(box);
  fill(box);
  if (last.twin) drawTwin(box);
  else drawSimulation(box);
}

export function showAgainst() {
  const twin = $("whatif-against").value === "actual";
  for (const node of document.querySelectorAll("#whatif .twin-only")) node.hidden = !twin;
}
