// Diagnosis: the satellite's diagnoses (an operator's, or one a live twin's detector started from its alarm),
// one chosen: the evidence (detection, false-alarm rate, window, suspected wheels, what could not be tested),
// the ranked hypotheses with onset, magnitude and posterior score (the server's ranking, unchanged), and the
// residuals of the top hypotheses: flown as a twin session (what-if panel) from before the earliest onset.
// Each hypothesis flies on the simulated 3D monitor ("Fly on simulated monitor": the diagnosis' own replay from
// before its onset, against the telemetry of that window, named on the monitors' panels); the nominal twin is
// one click back ("none" row, or "Back to nominal twin").
import { api, errorText } from "./api.js";
import { $, el, fill, table } from "./dom.js";
import { satParam, state } from "./state.js";
import { flyHypotheses } from "./whatif.js";

const SHOWN = 10;           // hypotheses listed
const FLOWN = 3;            // top hypotheses flown for their residuals
const LEAD_S = 120;         // the twin starts this long before the earliest onset
const AFTER_S = 240;        // and flies this long after it
const POLL_MS = 2000;       // a running diagnosis is polled this often
let shown = null;           // id of the diagnosis in the detail view
let pollTimer = null;

const wheelText = (w) => (w === null || w === undefined ? "" : Array.isArray(w) ? w.map((x) => `RW${x}`).join("+") : `RW${w}`);
const magnitudeText = (m) => (m === null || m === undefined ? "" : Array.isArray(m)
  ? m.map(magnitudeText).join(" / ") : Math.abs(m) < 0.01 ? m.toExponential(2) : m.toFixed(3));
const scoreText = (s) => (s >= 0.001 ? s.toFixed(3) : s.toExponential(1));
const topText = (d) => {
  const h = d.result && d.result.hypotheses[0];
  return h ? `${h.fault} ${wheelText(h.wheel)} (${scoreText(h.score)})` : d.status === "failed" ? d.error || "failed" : "…";
};
const origin = (d) => (d.trigger === "live twin" ? `alarm ${d.alarm_id ?? "?"} (live twin)` : `operator ${d.created_by}`);

export async function loadDiagnoses() {
  const runs = await api(`/diagnoses?satellite=${satParam()}`);
  const rows = runs.map((d) => el("tr", { class: `diag-${d.status}`, dataset: { diagnosisId: d.id }, onclick: () => showDiagnosis(d.id) },
    el("td", {}, d.alarm_utc || d.start_utc), el("td", {}, origin(d)), el("td", {}, d.status), el("td", {}, topText(d))));
  fill($("diagnoses").querySelector("tbody"),
    rows.length ? rows : el("tr", {}, el("td", { colspan: 4, class: "muted" }, "no diagnosis of this satellite yet")));
  return runs;
}

/** The diagnosis an alarm started (alarms panel): shown in the diagnosis panel. */
export async function showAlarmDiagnosis(alarmId) {
  const runs = await api(`/diagnoses?alarm_id=${alarmId}`);
  if (!runs.length) {
    fill($("diagnosis-detail"), el("p", { class: "muted" }, `alarm ${alarmId} started no diagnosis (yet)`));
    return null;
  }
  $("diagnosis-panel").scrollIntoView({ block: "start" });
  return showDiagnosis(runs[0].id);
}

export async function showDiagnosis(id) {
  clearTimeout(pollTimer);
  shown = id;
  const box = $("diagnosis-detail");
  let d;
  try {
    d = await api(`/diagnoses/${id}`);
  } catch (err) {
    fill(box, el("p", { class: "error" }, errorText(err)));
    return null;
  }
  box.dataset.diagnosisId = d.id;
  box.dataset.status = d.status;
  const head = el("h3", {}, `diagnosis ${d.id.slice(0, 8)} of ${d.satellite}, ${d.start_utc} → ${d.end_utc} (${origin(d)})`);
  if (d.status === "running") {
    fill(box, head, el("p", {}, "running: detection, pruning and the twin replays of the hypotheses…"));
    pollTimer = setTimeout(() => showDiagnosis(id), POLL_MS);
    return d;
  }
  loadDiagnoses().catch((err) => fill(box, el("p", { class: "error" }, errorText(err))));  // the list shows it done
  if (d.status === "failed") {
    fill(box, head, el("p", { class: "error" }, d.error));
    return d;
  }
  const r = d.result;
  fill(box, head, evidence(r), hypothesesTable(d),
    el("button", { type: "button", id: "diagnosis-fly", onclick: () => flyTop(d) }, `residuals of the top ${FLOWN} (twin session)`),
    el("div", { id: "diagnosis-fly-status" }),
    el("div", { class: "monitor-flight" },
      el("button", { type: "button", id: "monitor-nominal", onclick: () => backToNominal() }, "Back to nominal twin"),
      el("span", { id: "monitor-flight-status", dataset: { state: "idle" } })));
  api("/monitors/simulated").then((m) => markFlown(m), () => {});  // which row the monitor flies now, if any
  return d;
}

function evidence(r) {
  const det = r.detection;
  const items = [
    det.detected
      ? `anomaly detected at ${det.alarm_utc} on ${det.channel}`
      : "no anomaly detected in the window",
    `false-alarm rate of the detector: ${det.false_alarms_per_day.toExponential(1)} per day`,
    `analysis window ${det.window_utc[0]} → ${det.window_utc[1]}`,
    `confidence (posterior of the top hypothesis): ${r.confidence.toFixed(3)}`,
  ];
  if (r.suspected_wheels.length) items.push(`momentum balance suspects ${r.suspected_wheels.map((w) => `RW${w}`).join(", ")}`);
  for (const [what, why] of Object.entries(r.untestable || {})) items.push(`not testable: ${what}: ${why}`);
  return el("ul", { class: "diagnosis-evidence" }, items.map((t) => el("li", {}, t)));
}

function hypothesesTable(d) {
  const flyButton = (h, rank) => (h.fault === "none"
    ? el("button", { type: "button", class: "fly-monitor", dataset: { rank }, title: "no fault: the nominal twin",
      onclick: () => backToNominal() }, "Nominal twin on simulated monitor")
    : el("button", { type: "button", class: "fly-monitor", dataset: { rank },
      title: "fly this hypothesis from before its onset on the simulated 3D monitor, against the telemetry",
      onclick: (ev) => flyOnMonitor(d, rank, ev.target) }, "Fly on simulated monitor"));
  const rows = d.result.hypotheses.slice(0, SHOWN).map((h, i) => el("tr", { dataset: { rank: i + 1 } },
    [String(i + 1), h.fault, wheelText(h.wheel), h.onset_utc || "",
      h.onset_sigma_s === null || h.onset_sigma_s === undefined ? "" : h.onset_sigma_s.toFixed(1),
      magnitudeText(h.magnitude), scoreText(h.score)].map((c) => el("td", {}, c)),
    el("td", {}, flyButton(h, i + 1))));
  return table(["#", "fault", "wheel", "onset (UTC)", "± s", "magnitude", "score", "3D monitor"], rows,
    { class: "diagnosis-hypotheses" });
}

function flightStatus(state, text) {
  const status = $("monitor-flight-status");
  if (!status) return;
  status.dataset.state = state;
  status.className = state === "failed" ? "error" : "";
  fill(status, text);
}

/** Mark the hypothesis row the simulated monitor flies (state of GET /monitors/simulated). */
function markFlown(m) {
  for (const row of document.querySelectorAll("#diagnosis-detail .diagnosis-hypotheses tbody tr")) {
    const flown = m.flight && m.flight.diagnosis_id === shown && Number(row.dataset.rank) === m.flight.rank;
    row.classList.toggle("on-monitor", Boolean(flown));
  }
  const monitors = m.running ? "" : " (no 3D monitors run on this server)";
  flightStatus(m.showing === "hypothesis" ? "shown" : "nominal", `simulated monitor: ${m.label}${monitors}`);
}

// The residual that shows a flown hypothesis (summaries of POST /monitors/simulated/flight): its sensor's for a
// sensor fault, else the wheel speeds as the tachometers read them (a speed bias included).
const SENSOR_RESIDUALS = {
  gyro_bias: ["gyro_rms_deg_h", "gyro RMS", " °/h", 2],
  magnetometer_bias: ["magnetometer_rms_nt", "magnetometer RMS", " nT", 0],
  star_tracker_outage: ["star_tracker_mismatch", "share of star-tracker samples valid in one and not the other", "", 3],
};
const WHEEL_RESIDUAL = ["wheel_speed_rms_rpm", "wheel-speed RMS", " rpm", 2];

function flightResidual(f) {
  const sensor = SENSOR_RESIDUALS[f.hypothesis.fault];
  return sensor && f.summaries.hypothesis[sensor[0]] !== undefined ? sensor : WHEEL_RESIDUAL;
}

async function flyOnMonitor(d, rank, button) {
  const buttons = document.querySelectorAll("#diagnosis-detail button.fly-monitor");
  buttons.forEach((b) => { b.disabled = true; });
  const text = button.textContent;
  button.textContent = "flying…";
  flightStatus("flying", `flying hypothesis #${rank} from before its onset (the diagnosis' replay)…`);
  try {
    const f = await api("/monitors/simulated/flight", { method: "POST", json: { diagnosis_id: d.id, rank } });
    const [key, what, unit, digits] = flightResidual(f);
    const rms = (v) => `${f.summaries[v][key].toFixed(digits)}${unit}`;
    markFlown({ running: f.on_monitor, showing: "hypothesis", label: f.label, flight: f });
    flightStatus("shown", `${f.on_monitor ? "on the simulated monitor" : "flown (no 3D monitors run on this server)"}: `
      + `${f.label}; ${what} against the telemetry ${rms("hypothesis")} (nominal twin ${rms("nominal")})`);
  } catch (err) {
    flightStatus("failed", `not flown: ${errorText(err)}`);
  } finally {
    button.textContent = text;
    buttons.forEach((b) => { b.disabled = false; });
  }
}

async function backToNominal() {
  flightStatus("flying", "putting the nominal twin back…");
  try {
    markFlown(await api("/monitors/simulated/flight", { method: "DELETE" }));
  } catch (err) {
    flightStatus("failed", errorText(err));
  }
}

/** One hypothesis in the twin sessions' fault syntax (0-based wheel index), onsets relative to `alignS`;
 * null for a fault a twin session cannot fly (the text says which). */
export function hypothesisFaults(h, alignS) {
  const kinds = h.fault.split("+");
  const wheels = Array.isArray(h.wheel) ? h.wheel : [h.wheel];
  const magnitudes = Array.isArray(h.magnitude) ? h.magnitude : [h.magnitude];
  const onset = h.onset_utc ? Math.max(0, Date.parse(h.onset_utc) / 1000 - alignS) : 0;
  const out = [];
  for (const [i, kind] of kinds.entries()) {
    const w = wheels[i] - 1, m = magnitudes[i];
    const at = `@${onset.toFixed(1)}`;
    if (kind === "none") return [];
    if (kind === "failure" || kind === "stuck") out.push(`wheel:${w}:${kind}${at}`);
    else if (kind === "gain_loss" && m !== null && m !== undefined) out.push(`wheel:${w}:gain${at},gain=${m}`);
    else if (kind === "friction" && m !== null && m !== undefined) out.push(`wheel:${w}:friction${at},value=${m}`);
    else return null;
  }
  return out;
}

function flyTop(d) {
  const status = $("diagnosis-fly-status");
  const top = d.result.hypotheses.slice(0, FLOWN);
  const onsets = top.map((h) => (h.onset_utc ? Date.parse(h.onset_utc) / 1000 : null)).filter((t) => t !== null);
  const windowStart = Date.parse(d.start_utc) / 1000;
  const align = onsets.length ? Math.max(windowStart, Math.min(...onsets) - LEAD_S) : windowStart;
  const alternatives = {}, skipped = [];
  top.forEach((h, i) => {
    const faults = hypothesisFaults(h, align);
    if (faults === null) skipped.push(`${h.fault} ${wheelText(h.wheel)}`);
    else alternatives[`h${i + 1}_${h.fault.replaceAll("+", "_")}`] = faults;
  });
  fill(status, skipped.length ? `not flown (a twin session flies wheel faults only): ${skipped.join(", ")}` : "");
  flyHypotheses({ satellite: d.satellite, dictionary: d.dictionary, scenario: d.scenario, alignS: align,
    durationS: LEAD_S + AFTER_S, alternatives });
}

export function clearDiagnoses() {
  clearTimeout(pollTimer);
  shown = null;
  fill($("diagnoses").querySelector("tbody"));
  fill($("diagnosis-detail"));
}
