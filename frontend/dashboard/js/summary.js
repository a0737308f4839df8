// Pass summary: attitude error, wheel speeds and the alarms of the chosen window on one time axis,
// exported as PNG or as a one-page PDF report.
import { api, errorText } from "./api.js";
import { $, el, fill, download } from "./dom.js";
import { isoUtc, severityLabel } from "./format.js";
import { COLOURS, destroyPlots, stackCanvases, timePlot } from "./plots.js";
import { satParam, state } from "./state.js";
import { pdfOfCanvas } from "./pdf.js";

const ATTITUDE_ERROR = /attitude_error|residual_attitude/;
const WHEEL_SPEED = /^wheel_speed/;
const SEVERITY_COLOURS = { red: "#ff5a5a", yellow: "#ffb347" };
const POINTS = 2000;

function windowQuery() {
  return { satellite: state.satellite, max_points: POINTS, start: isoUtc(state.window[0], 3),
    end: isoUtc(Math.ceil(state.window[1] * 1000) / 1000 + 0.001, 3) };
}

async function seriesOf(names) {
  const answers = await Promise.all(names.map((n) => api(`/parameters/${encodeURIComponent(n)}/samples`, { query: windowQuery() })));
  // one time axis: the union of the instants, nulls where a parameter has no sample
  const t = [...new Set(answers.flatMap((a) => a.t_utc_ns))].sort((a, b) => a - b);
  const index = new Map(t.map((x, i) => [x, i]));
  const columns = answers.map((a) => {
    const col = new Array(t.length).fill(null);
    a.t_utc_ns.forEach((x, i) => { col[index.get(x)] = a.values[i]; });
    return col;
  });
  return { t: t.map((ns) => ns / 1e9), columns };
}

function alarmBands(alarms) {
  // each alarm a band from its first to its last out-of-limits sample, one row per alarm
  return (u) => {
    const { ctx } = u;
    const { left, top, width, height } = u.bbox;
    const row = height / Math.max(1, alarms.length);
    ctx.save();
    ctx.font = `${Math.round(11 * devicePixelRatio)}px system-ui, sans-serif`;
    alarms.forEach((a, i) => {
      const x0 = Math.max(left, u.valToPos(a.first_t_ns / 1e9, "x", true));
      const x1 = Math.min(left + width, Math.max(x0 + 2, u.valToPos(a.last_t_ns / 1e9, "x", true)));
      const y = top + i * row;
      ctx.fillStyle = SEVERITY_COLOURS[a.severity] || "#8a919c";
      ctx.globalAlpha = 0.7;
      ctx.fillRect(x0, y + 2, Math.max(2, x1 - x0), row - 4);
      ctx.globalAlpha = 1;
      ctx.fillStyle = "#e4e6ea";
      ctx.fillText(`${a.parameter} (${severityLabel(a.severity)})`, Math.min(x0 + 4, left + width - 150), y + row / 2 + 4);
    });
    ctx.restore();
  };
}

export async function showSummary() {
  const box = $("summary-plots");
  destroyPlots(box);
  fill(box);
  if (!state.window) { fill(box, el("p", { class: "muted" }, "choose a pass or a window first")); return; }
  $("summary-label").textContent = state.windowLabel;
  try {
    const names = Object.keys(state.info).length ? Object.keys(state.info)
      : Object.keys(await api(`/parameters?satellite=${satParam()}`));
    const attitude = names.filter((n) => ATTITUDE_ERROR.test(n)).sort();
    const wheels = names.filter((n) => WHEEL_SPEED.test(n)).sort();
    const alarms = (await api(`/alarms?satellite=${satParam()}&include_cleared=true`)).filter(
      (a) => a.first_t_ns / 1e9 <= state.window[1] && a.last_t_ns / 1e9 >= state.window[0]);
    const groups = [["attitude error", attitude], ["wheel speeds", wheels]];
    for (const [what, group] of groups) {
      const div = el("div", { class: "summary-chart", dataset: { what } });
      box.append(div);
      if (!group.length) { div.append(el("p", { class: "muted" }, `${what}: no such parameter in ${state.satellite}'s dictionary`)); continue; }
      const { t, columns } = await seriesOf(group);
      const info = state.info[group[0]] || {};
      timePlot(div, t, columns, { title: `${what} [${info.units || ""}]`, labels: group, info: { units: info.units },
        seriesInfo: group.map((n) => state.info[n] || {}), colours: COLOURS, height: 170 });
    }
    const div = el("div", { class: "summary-chart", dataset: { what: "alarms" } });
    box.append(div);
    const t = [state.window[0], state.window[1]];
    timePlot(div, t, [[null, null]], { title: `alarms (${alarms.length})`, labels: ["alarm"], info: { units: "" },
      height: Math.max(90, 26 * alarms.length + 50), extraDraw: alarmBands(alarms) });
  } catch (err) {
    box.append(el("p", { class: "error" }, errorText(err)));
  }
}

const title = () => `acs-twin pass summary: ${state.satellite} · ${state.windowLabel}`;

export function exportSummaryPng() {
  stackCanvases($("summary-plots"), title()).toBlob((blob) => download(`${state.satellite}-summary.png`, blob), "image/png");
}

export async function exportSummaryPdf() {
  const blob = await pdfOfCanvas(stackCanvases($("summary-plots"), ""), title());
  download(`${state.satellite}-summary.pdf`, blob);
}
