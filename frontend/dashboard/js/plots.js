// Time-series plots (vendored uPlot) that an operator can read: ISO 8601 UTC 24-hour time axis, y ticks
// that keep their sign and never clip (axis width measured from the tick text, SI prefix or ×1eN on the
// axis label), units and descriptions, enumeration labels on the axis and in the legend, limit lines.
// Every plot shares one time axis (zoom and cursor move them all).
import { axisScale, axisTicks, isoUtc, valueText } from "./format.js";

const SYNC_KEY = "acs-twin-time";
export const COLOURS = ["#4aa3ff", "#ff7043", "#48c774", "#ffd54f", "#ba68c8", "#4dd0e1", "#f06292", "#a1887f"];
export const DASHES = [[], [6, 3], [2, 3], [8, 3, 2, 3]];
const LIMIT_COLOURS = { yellow: "#ffb347", red: "#ff5a5a" };
const AXIS_STYLE = { stroke: "#c8ccd2", grid: { stroke: "#2e333b", width: 1 }, ticks: { stroke: "#2e333b" } };
const TICK_GAP_PX = 18;  // tick length + gap between the tick and its text, plus a margin
export const PLOT_HEIGHT = 190;

export const plots = new Set();  // live uPlot instances (one shared time axis)
let syncing = false;

const measure = document.createElement("canvas").getContext("2d");

function textWidth(font, text) {
  measure.font = font;
  return Math.max(0, ...String(text).split("\n").map((line) => measure.measureText(line).width));
}

/** Axis width from the widest rendered tick label, so "-168.85" is never drawn as "68.85". */
function axisSize(u, values, axisIdx) {
  const axis = u.axes[axisIdx];
  if (!values) return 40;
  const font = axis.font ? axis.font[0] : "12px system-ui";
  return Math.ceil(Math.max(...values.map((v) => textWidth(font, v)), 10) + TICK_GAP_PX);
}

/** 24-hour UTC tick labels; the date under the first tick and where the day changes. */
export function timeTicks(u, splits, axisIdx, space, incr) {
  let day = null;
  return splits.map((s) => {
    const iso = isoUtc(s, incr < 1 ? 3 : 0);
    const time = incr >= 60 && incr % 60 === 0 ? iso.slice(11, 16) : iso.slice(11, incr < 1 ? 23 : 19);
    const label = iso.slice(0, 10) !== day ? `${time}\n${iso.slice(0, 10)}` : time;
    day = iso.slice(0, 10);
    return label;
  });
}

function yAxis(info, unitLabel) {
  const unit = info ? info.units : "";
  const axis = { ...AXIS_STYLE, size: axisSize, label: unitLabel || unit || "", labelSize: 18, labelGap: 2 };
  const codes = info && info.enumeration ? Object.keys(info.enumeration).map(Number).sort((a, b) => a - b) : [];
  if (codes.length) {
    axis.splits = (u, axisIdx, min, max) => codes.filter((c) => c >= min && c <= max);
    axis.values = (u, splits) => splits.map((c) => info.enumeration[String(c)] ?? String(c));
    axis.label = "";
  } else {
    axis.values = (u, splits) => {
      const labels = axisTicks(splits, unit);
      u.axes[1].label = unitLabel || axisScale(splits, unit).label;  // SI prefix or ×1eN moves to the label
      return labels;
    };
  }
  return axis;
}

function limitLines(info) {
  const lim = info && info.limits;
  if (!lim) return [];
  return ["yellow_low", "yellow_high", "red_low", "red_high"]
    .filter((k) => lim[k] !== null && lim[k] !== undefined && Number.isFinite(lim[k]))
    .map((k) => [lim[k], LIMIT_COLOURS[k.split("_")[0]], k]);
}

function drawLimits(lines) {
  return (u) => {
    const { ctx } = u;
    const { left, top, width, height } = u.bbox;
    ctx.save();
    ctx.setLineDash([6, 4]);
    ctx.lineWidth = 1;
    for (const [value, colour] of lines) {
      const y = u.valToPos(value, "y", true);
      if (y < top || y > top + height) continue;
      ctx.strokeStyle = colour;
      ctx.beginPath();
      ctx.moveTo(left, y);
      ctx.lineTo(left + width, y);
      ctx.stroke();
    }
    ctx.restore();
  };
}

function syncScales(source) {
  if (syncing) return;
  const { min, max } = source.scales.x;
  syncing = true;
  for (const u of plots) if (u !== source && u.data[0].length) u.setScale("x", { min, max });
  syncing = false;
}

export const plotWidth = (container) => Math.max(320, (container.clientWidth || container.parentElement.clientWidth) - 4);

/**
 * A plot of columns against Unix-second times t.
 * spec: {title, labels, info (dictionary entry: units, description, enumeration, limits), unitLabel,
 *        colours, dashes, height, extraDraw}
 */
export function timePlot(container, t, columns, spec) {
  const info = spec.info || null;
  const lines = limitLines(info);
  const series = [{ value: (u, v) => isoUtc(v, 3) }].concat(spec.labels.map((label, i) => ({
    label,
    stroke: (spec.colours || COLOURS)[i % (spec.colours || COLOURS).length],
    width: 1.2,
    dash: spec.dashes ? spec.dashes[i] : undefined,
    spanGaps: false,
    value: (u, v) => (v === null || v === undefined ? "—" : valueText(v, spec.seriesInfo ? spec.seriesInfo[i] : info)),
  })));
  const opts = {
    title: spec.title,
    width: plotWidth(container),
    height: spec.height || PLOT_HEIGHT,
    cursor: { sync: { key: SYNC_KEY, setSeries: false }, drag: { x: true, y: false } },
    scales: { x: { time: true } },
    tzDate: (ts) => uPlot.tzDate(new Date(ts * 1e3), "Etc/UTC"),
    axes: [{ ...AXIS_STYLE, values: timeTicks, label: "UTC", labelSize: 14, size: 44 }, yAxis(info, spec.unitLabel)],
    legend: { live: true },
    series,
    hooks: {
      setScale: [(u, key) => { if (key === "x") syncScales(u); }],
      draw: [drawLimits(lines)].concat(spec.extraDraw ? [spec.extraDraw] : []),
    },
  };
  const u = new uPlot(opts, [t].concat(columns), container);
  if (info && info.description) u.root.title = info.description;
  u.limits = lines;
  plots.add(u);
  return u;
}

export function destroyPlots(inside) {
  for (const u of [...plots]) {
    if (!inside || inside.contains(u.root)) {
      u.destroy();
      plots.delete(u);
    }
  }
}

export function resetZoom() {
  for (const u of plots) {
    const t = u.data[0];
    if (t.length) u.setScale("x", { min: t[0], max: t[t.length - 1] });
  }
}

export function resizePlots() {
  for (const u of plots) u.setSize({ width: plotWidth(u.root.parentElement), height: u.height });
}

/** One PNG-ready canvas of the plots inside a box, stacked under a header, each with its title. */
export function stackCanvases(inside, header = "") {
  const chosen = [...plots].filter((u) => inside.contains(u.root));
  const ratio = window.devicePixelRatio || 1;
  const titlePx = Math.round(20 * ratio);
  const headerPx = header ? Math.round(30 * ratio) : 0;
  const out = document.createElement("canvas");
  out.width = Math.max(1, ...chosen.map((u) => u.ctx.canvas.width));
  out.height = headerPx + chosen.reduce((h, u) => h + titlePx + u.ctx.canvas.height, 0);
  const ctx = out.getContext("2d");
  ctx.fillStyle = "#1d2026";
  ctx.fillRect(0, 0, out.width, out.height);
  ctx.fillStyle = "#e4e6ea";
  if (header) {
    ctx.font = `${Math.round(16 * ratio)}px system-ui, sans-serif`;
    ctx.fillText(header, 8, Math.round(21 * ratio));
  }
  let y = headerPx;
  ctx.font = `${Math.round(12 * ratio)}px system-ui, sans-serif`;
  for (const u of chosen) {
    ctx.fillStyle = "#e4e6ea";
    ctx.fillText(u.root.querySelector(".u-title")?.textContent || "", 8, y + Math.round(15 * ratio));
    y += titlePx;
    ctx.drawImage(u.ctx.canvas, 0, y);
    y += u.ctx.canvas.height;
  }
  return out;
}
