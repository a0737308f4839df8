// Alarms with their whole lifecycle (ISA-18.2 style, as the archive keeps it): active → acknowledged →
// cleared, back in limits unacknowledged ("returned to normal"), shelved until a time and unshelved;
// severity from the limits (red = critical, yellow = warning); history per alarm, per parameter and per
// pass; a banner and an optional sound for unacknowledged alarms.
import { api, errorText } from "./api.js";
import { $, el, fill, table } from "./dom.js";
import { isoUtcNs, severityLabel, eng } from "./format.js";
import { satParam, state } from "./state.js";
import { showAlarmDiagnosis } from "./diagnosis.js";

const DETECTION_PARAMETER = "twin_anomaly";  // a live twin's detector: its alarm starts a diagnosis

const SHELVE_CHOICES_S = [[900, "15 min"], [3600, "1 h"], [8 * 3600, "8 h"]];
let known = new Set();  // ids of unacknowledged alarms already announced (sound once per new alarm)
const shelveChoice = new Map();  // alarm id → the duration an operator picked, kept when the table is redrawn
let audio = null;

/** What an operator reads for the alarm's state. */
export function lifecycle(a) {
  if (a.state === "shelved") return `shelved until ${a.shelved_until_ns ? isoUtcNs(a.shelved_until_ns) : "?"}`;
  if (a.state === "active" && a.level === 0) return "returned to normal, unacknowledged";
  if (a.state === "acknowledged" && a.level === 0) return "acknowledged, back in limits";
  return a.state;
}

const severityClass = (a) => `sev-${severityLabel(a.severity)}`;
const unacknowledged = (a) => a.state === "active";

function actionButtons(a) {
  const act = (action, body) => async (event) => {
    event.stopPropagation();
    try {
      await api(`/alarms/${a.id}/${action}`, { method: "POST", json: body });
      await loadAlarms();
    } catch (err) {
      $("alarm-status").textContent = `alarm ${a.id} (${a.parameter}): ${errorText(err)}`;
    }
  };
  const buttons = [];
  if (a.state === "active" || a.state === "shelved") buttons.push(el("button", { class: "small", onclick: act("acknowledge") }, "ack"));
  if (a.state === "shelved") buttons.push(el("button", { class: "small", onclick: act("unshelve") }, "unshelve"));
  else if (a.state !== "cleared") {
    const choice = el("select", { class: "small", "aria-label": "shelve for", onclick: (e) => e.stopPropagation(),
      onchange: () => shelveChoice.set(a.id, choice.value) },
      SHELVE_CHOICES_S.map(([s, label]) => el("option", { value: s }, label)));
    choice.value = shelveChoice.get(a.id) ?? "3600";
    buttons.push(choice, el("button", { class: "small", onclick: (e) => act("shelve", { duration_s: Number(choice.value) })(e) }, "shelve"));
  }
  buttons.push(el("button", { class: "small", onclick: (e) => { e.stopPropagation(); showHistory(a); } }, "history"));
  if (a.parameter === DETECTION_PARAMETER) {
    buttons.push(el("button", { class: "small diagnosis-link", onclick: (e) => {
      e.stopPropagation();
      showAlarmDiagnosis(a.id).catch((err) => { $("alarm-status").textContent = errorText(err); });
    } }, "diagnosis"));
  }
  return el("td", { class: "actions" }, buttons);
}

export async function loadAlarms() {
  const includeCleared = $("show-cleared").checked;
  const alarms = await api(`/alarms?satellite=${satParam()}&include_cleared=${includeCleared}`);
  const body = $("alarms").querySelector("tbody");
  const rows = alarms.map((a) => {
    const info = state.info[a.parameter] || {};
    return el("tr", { class: `state-${a.state} ${severityClass(a)}${a.level === 0 ? " rtn" : ""}`, dataset: { alarmId: a.id, parameter: a.parameter } },
      el("td", { title: info.description || "" }, a.parameter),
      el("td", { class: "severity" }, severityLabel(a.severity)),
      el("td", { class: "lifecycle" }, lifecycle(a)),
      el("td", {}, isoUtcNs(a.first_t_ns)),
      actionButtons(a));
  });
  fill(body, rows.length ? rows : el("tr", {}, el("td", { colspan: 5, class: "muted" }, "no active alarms")));
  banner(alarms);
  return alarms;
}

function banner(alarms) {
  const open = alarms.filter(unacknowledged);
  const box = $("alarm-banner");
  box.hidden = open.length === 0;
  const critical = open.filter((a) => a.severity === "red");
  box.className = critical.length ? "banner sev-critical" : "banner sev-warning";
  const names = (critical.length ? critical : open).map((a) => a.parameter).slice(0, 4).join(", ");
  fill(box, `${open.length} unacknowledged alarm${open.length === 1 ? "" : "s"}`,
    critical.length ? ` · ${critical.length} critical: ${names}` : ` · warning: ${names}`);
  const fresh = open.filter((a) => !known.has(a.id));
  if (fresh.length && $("alarm-sound").checked) beep(critical.length ? 880 : 660);
  known = new Set(open.map((a) => a.id));
}

function beep(hz) {
  try {
    audio ||= new AudioContext();
    const osc = audio.createOscillator();
    const gain = audio.createGain();
    gain.gain.value = 0.08;
    osc.frequency.value = hz;
    osc.connect(gain).connect(audio.destination);
    osc.start();
    osc.stop(audio.currentTime + 0.35);
    $("alarm-banner").dataset.beeps = String(Number($("alarm-banner").dataset.beeps || 0) + 1);
  } catch (err) {
    console.warn("alarm sound unavailable", err);
  }
}

const eventRow = (e, info) => [isoUtcNs(e.t_ns, 3), e.kind, e.severity ? severityLabel(e.severity) : "",
  e.value === null || e.value === undefined ? "" : eng(e.value, info.units || "", 5), e.actor || ""];

/** Events of one alarm, every alarm of its parameter, and the alarms of the chosen pass. */
export async function showHistory(alarm) {
  const box = $("alarm-history");
  box.hidden = false;
  fill(box, el("p", {}, `loading history of ${alarm.parameter}…`));
  try {
    const info = state.info[alarm.parameter] || {};
    const [events, all] = await Promise.all([
      api(`/alarms/${alarm.id}/events`),
      api(`/alarms?satellite=${satParam()}&include_cleared=true`),
    ]);
    const ofParameter = all.filter((a) => a.parameter === alarm.parameter);
    const parts = [
      el("h3", {}, `${alarm.parameter}: alarm ${alarm.id} (${lifecycle(alarm)})`,
        el("button", { class: "small", onclick: () => { box.hidden = true; } }, "close")),
      table(["time (UTC)", "event", "severity", "value", "by"], events.map((e) => eventRow(e, info)), { class: "history-events" }),
      el("h3", {}, `every alarm of ${alarm.parameter}`),
      table(["id", "severity", "state", "first (UTC)", "last (UTC)"], ofParameter.map((a) =>
        [String(a.id), severityLabel(a.severity), lifecycle(a), isoUtcNs(a.first_t_ns), isoUtcNs(a.last_t_ns)]), { class: "history-parameter" }),
    ];
    if (state.pass) {
      const p = state.pass;
      const inPass = all.filter((a) => a.first_t_ns <= p.los_ns && a.last_t_ns >= p.aos_ns);
      parts.push(el("h3", {}, `alarms during pass ${p.id}`),
        table(["parameter", "severity", "state", "first (UTC)"], inPass.map((a) =>
          [a.parameter, severityLabel(a.severity), lifecycle(a), isoUtcNs(a.first_t_ns)]), { class: "history-pass" }));
    }
    fill(box, parts);
  } catch (err) {
    fill(box, el("p", { class: "error" }, errorText(err)));
  }
}

export function clearAlarms() {
  fill($("alarms").querySelector("tbody"));
  shelveChoice.clear();
  $("alarm-banner").hidden = true;
  $("alarm-history").hidden = true;
  known = new Set();
}
