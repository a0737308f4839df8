// Telemetry panel: archived parameters with their dictionary entries, latest values (limit-coloured,
// enumeration labels), plots of the chosen window with residuals (actual − twin) beside them, and
// live samples appended as they arrive.
import { api, errorText, optional } from "./api.js";
import { $, el, fill, download } from "./dom.js";
import { continuousQuaternion, isoUtc, limitLevel, quaternionGroups, valueText } from "./format.js";
import { destroyPlots, plots, plotWidth, stackCanvases, timePlot } from "./plots.js";
import { emit, satParam, state } from "./state.js";

const QUATERNION_POINTS = 20_000;  // quaternion components fetched whole (same instants) for hemisphere continuity
const POINTS_PER_PX = 2;           // min/max per pixel column: the server's downsampler keeps both
const LIVE_REFETCH_FACTOR = 4;     // a live plot holding this many times its budget is fetched again, downsampled
const DEFAULT_PICKS = [/attitude_error/, /^wheel_speed.*1$/, /q.*_0$|ADCFAQ1/i, /omega_est.*x$/];
export const isResidual = (name) => /(^|_)residual(_|$)/.test(name);

let plotted = new Map();  // name -> {u, budget, total}
let generation = 0;  // a newer plotSelected call supersedes one still fetching
let latestRows = new Map();  // name -> <tr>

export function clearTelemetry() {
  generation++;
  destroyPlots($("plots"));
  destroyPlots($("residual-plots"));
  plotted = new Map();
  latestRows = new Map();
  fill($("plots"));
  fill($("residual-plots"));
  fill($("parameter-list"));
  fill($("latest").querySelector("tbody"));
  $("window-label").textContent = "";
}

const infoOf = (name) => state.info[name] || { units: "", description: "" };
const unitSuffix = (name) => (infoOf(name).units && infoOf(name).units !== "1" ? ` [${infoOf(name).units}]` : "");

/** Names and dictionary entries of the satellite's parameters; the list to choose plots from. */
export async function loadParameters() {
  const [names, info] = await Promise.all([
    api(`/parameters?satellite=${satParam()}`),
    optional(`/parameters/info?satellite=${satParam()}`, {}),
  ]);
  state.info = info;
  const all = Object.keys(names).sort();
  const option = (name) => el("option", { value: name, title: infoOf(name).description || name }, `${name}${unitSuffix(name)}`);
  const telemetry = all.filter((n) => !isResidual(n));
  const residuals = all.filter(isResidual);
  fill($("parameter-list"),
    el("optgroup", { label: "telemetry" }, telemetry.map(option)),
    residuals.length ? el("optgroup", { label: "residuals (actual − twin)" }, residuals.map(option)) : null);
  for (const pattern of DEFAULT_PICKS) {
    const pick = telemetry.find((n) => pattern.test(n));
    if (pick) $("parameter-list").querySelector(`option[value="${CSS.escape(pick)}"]`).selected = true;
  }
  if (!$("parameter-list").selectedOptions.length && telemetry.length) $("parameter-list").options[0].selected = true;
  return all;
}

/** GET of the newest value of every parameter (start it early, render it once the dictionary entries are in). */
export const fetchLatest = () => api(`/parameters/latest?satellite=${satParam()}`);

/** Newest value of every parameter: value text with units or enumeration label, coloured by its limits. */
export async function loadLatest(pending = fetchLatest()) {
  const latest = await pending;
  const body = $("latest").querySelector("tbody");
  latestRows = new Map();
  const rows = Object.keys(latest).sort().map((name) => {
    const tr = el("tr", { dataset: { parameter: name } },
      el("td", { title: infoOf(name).description || "" }, name),
      el("td", { class: "value" }), el("td", { class: "time" }));
    latestRows.set(name, tr);
    setLatest(name, latest[name].t_utc_ns / 1e9, latest[name].value);
    return tr;
  });
  fill(body, rows);
  const newest = Math.max(-Infinity, ...Object.values(latest).map((x) => x.t_utc_ns / 1e9));
  return Number.isFinite(newest) ? newest : null;
}

function setLatest(name, t, v) {
  const tr = latestRows.get(name);
  if (!tr) return;
  const info = infoOf(name);
  const cell = tr.children[1];
  cell.textContent = valueText(v, info);
  cell.className = `value ${limitLevel(v, info.limits)}`;
  tr.children[2].textContent = isoUtc(t, 3);
  tr.dataset.t = String(t);
}

function windowQuery(budget) {
  const q = { satellite: state.satellite, max_points: budget };
  if (state.window) {
    q.start = isoUtc(Math.floor(state.window[0] * 1000) / 1000, 3);
    q.end = state.following ? undefined : isoUtc(Math.ceil(state.window[1] * 1000) / 1000 + 0.001, 3);
  }
  return q;
}

async function samples(name, budget) {
  return api(`/parameters/${encodeURIComponent(name)}/samples`, { query: windowQuery(budget) });
}

/** Samples of each name (fetched in parallel); quaternion components whole and hemisphere-continuous. */
async function fetchSeries(names, budget) {
  const groups = quaternionGroups(Array.from($("parameter-list").options).map((o) => o.value).concat(names));
  const wanted = new Set(names);
  const jobs = [];
  const seen = new Set();
  for (const name of names) {
    if (seen.has(name)) continue;
    const group = groups.get(name);
    for (const n of group || [name]) seen.add(n);
    jobs.push(group ? quaternion(group, wanted) : samples(name, budget).then((s) => ({ [name]: s })));
  }
  return Object.assign({}, ...(await Promise.all(jobs)));
}

async function quaternion(group, wanted) {
  const parts = await Promise.all(group.map((n) => samples(n, QUATERNION_POINTS)));
  const aligned = parts.every((p) => p.t_utc_ns.length === parts[0].t_utc_ns.length
    && p.t_utc_ns[p.t_utc_ns.length - 1] === parts[0].t_utc_ns[parts[0].t_utc_ns.length - 1]);
  const columns = aligned ? continuousQuaternion(parts.map((p) => p.values)) : parts.map((p) => p.values);
  const out = {};
  group.forEach((n, k) => { if (wanted.has(n)) out[n] = { ...parts[k], values: columns[k], continuous: aligned }; });
  return out;
}

function plotTitle(name, s) {
  const info = infoOf(name);
  const what = info.description ? ` — ${info.description}` : "";
  const flip = s.continuous ? " · hemisphere-continuous" : "";
  return `${name}${unitSuffix(name)}${what} (${s.total_points} samples${flip})`;
}

/** Plot the chosen parameters over the window; residuals in their own column beside them. */
export async function plotSelected() {
  const mine = ++generation;
  const names = Array.from($("parameter-list").selectedOptions).map((o) => o.value);
  destroyPlots($("plots"));
  destroyPlots($("residual-plots"));
  plotted = new Map();
  fill($("plots"));
  fill($("residual-plots"));
  const listed = Array.from($("parameter-list").options).map((o) => o.value);
  const residualNames = [...new Set(names.filter(isResidual).concat(listed.filter(isResidual)))];
  if (!residualNames.length) {
    $("residual-plots").append(el("p", { class: "muted" },
      "no residuals archived for this satellite yet (the live twin archives actual − twin as residual_* parameters)"));
  }
  if (!names.length) { $("plots").append(el("p", { class: "muted" }, "select parameters to plot")); return; }
  const budget = Math.max(400, POINTS_PER_PX * plotWidth($("plots")));
  const telemetryNames = names.filter((n) => !isResidual(n));
  const series = await fetchSeries(telemetryNames.concat(residualNames), budget).catch((err) => {
    $("plots").append(el("p", { class: "error" }, errorText(err)));
    return {};
  });
  if (mine !== generation) return;
  for (const name of telemetryNames.concat(residualNames)) {
    const s = series[name];
    if (!s) continue;
    const box = el("div", { class: "plot", dataset: { parameter: name } });
    $(isResidual(name) ? "residual-plots" : "plots").append(box);
    if (!s.t_utc_ns.length) { box.append(el("p", { class: "muted" }, `${name}: no samples in this window`)); continue; }
    const u = timePlot(box, s.t_utc_ns.map((ns) => ns / 1e9), [s.values],
      { title: plotTitle(name, s), labels: [name], info: infoOf(name) });
    plotted.set(name, { u, budget: s.continuous ? QUATERNION_POINTS : budget, total: s.total_points });
  }
  const spans = [...plotted.values()].map(({ u }) => u.data[0]).filter((t) => t.length);
  const first = Math.min(...spans.map((t) => t[0])), last = Math.max(...spans.map((t) => t[t.length - 1]));
  emit("plotted", { names, first, last });
}

/** Live samples of one satellite ({name: {t_utc_ns, values}}): latest values, and plots that follow. */
export function appendLive(batch) {
  for (const [name, s] of Object.entries(batch)) {
    const n = s.t_utc_ns.length;
    if (n) setLatest(name, s.t_utc_ns[n - 1] / 1e9, s.values[n - 1]);
  }
  if (!state.following) return;
  const groups = quaternionGroups(Object.keys(batch));
  const refetch = [];
  for (const [name, entry] of plotted) {
    const s = batch[name];
    if (!s || !s.t_utc_ns.length) continue;
    let values = s.values;
    const group = groups.get(name);
    if (group && group.every((g) => batch[g])) values = continueFrom(group, batch, name);
    const [t, v] = entry.u.data;
    const last = t.length ? t[t.length - 1] : -Infinity;
    const fresh = s.t_utc_ns.map((ns, i) => [ns / 1e9, values[i]]).filter(([x]) => x > last);
    if (!fresh.length) continue;
    entry.u.setData([t.concat(fresh.map((p) => p[0])), v.concat(fresh.map((p) => p[1]))]);
    if (entry.u.data[0].length > LIVE_REFETCH_FACTOR * entry.budget) refetch.push(name);
  }
  if (refetch.length) plotSelected();
}

function continueFrom(group, batch, name) {
  // the new samples continue the plotted quaternion's hemisphere (q and −q are one attitude)
  const previous = group.map((g) => plotted.get(g)).filter(Boolean);
  const columns = group.map((g) => batch[g].values);
  if (previous.length === 4) {
    const last = previous.map((p) => p.u.data[1][p.u.data[1].length - 1]);
    columns.forEach((c, k) => c.unshift(last[k]));
    const fixed = continuousQuaternion(columns);
    return fixed[group.indexOf(name)].slice(1);
  }
  return continuousQuaternion(columns)[group.indexOf(name)];
}

export function exportCsv() {
  const rows = ["parameter,t_utc,value,units"];
  for (const [name, { u }] of plotted) {
    const { min, max } = u.scales.x;
    const [t, v] = u.data;
    for (let i = 0; i < t.length; i++) if (t[i] >= min && t[i] <= max) rows.push(`${name},${isoUtc(t[i], 3)},${v[i]},${infoOf(name).units || ""}`);
  }
  download(`${state.satellite}-parameters.csv`, new Blob([`${rows.join("\n")}\n`], { type: "text/csv" }));
}

export function exportPng() {
  if (!plots.size) return;
  stackCanvases($("plots-area"), `${state.satellite} · ${state.windowLabel}`).toBlob(
    (blob) => download(`${state.satellite}-parameters.png`, blob), "image/png");
}

export const plottedNames = () => [...plotted.keys()];
export const latestTime = (name) => Number(latestRows.get(name)?.dataset.t);
