// How values read: ISO 8601 UTC times, engineering notation with SI prefixes, enumeration labels,
// limit levels, and quaternion hemisphere continuity. Pure functions (no DOM).

const PREFIXES = { "-15": "f", "-12": "p", "-9": "n", "-6": "µ", "-3": "m", "0": "", "3": "k", "6": "M", "9": "G",
  "12": "T", "15": "P" };
// units a SI prefix reads naturally on (others get ×10ⁿ engineering notation)
const PREFIXABLE = new Set(["m", "m/s", "rad", "rad/s", "rad/s^2", "N*m", "N·m", "N", "A*m^2", "A·m²", "A", "V", "W",
  "T", "s", "Hz", "N*m*s", "kg*m^2", "J"]);

/** ISO 8601 UTC of Unix seconds: 2021-04-09T00:00:00Z (digits = fractional-second digits). */
export function isoUtc(s, digits = 0) {
  if (s === null || s === undefined || !Number.isFinite(s)) return "—";
  const iso = new Date(Math.round(s * 1000)).toISOString();
  return digits > 0 ? `${iso.slice(0, 20 + Math.min(digits, 3))}Z` : `${iso.slice(0, 19)}Z`;
}

export const isoUtcNs = (ns, digits = 0) => isoUtc(ns / 1e9, digits);

/** Unix seconds of an ISO 8601 UTC text field ("2021-04-09T00:00:00Z"; no zone = UTC; NaN if not a time). */
export function inputUtc(v) {
  const text = (v || "").trim().replace(" ", "T");
  if (!/^\d{4}-\d\d-\d\dT\d\d:\d\d(:\d\d(\.\d+)?)?(Z|[+-]\d\d:\d\d)?$/.test(text)) return NaN;
  return Date.parse(/(Z|[+-]\d\d:\d\d)$/.test(text) ? text : `${text}Z`) / 1000;
}
/** The text an ISO 8601 UTC field shows for Unix seconds (milliseconds kept). */
export const utcInput = (s) => isoUtc(s, 3);

/** "12 s", "4 min 3 s", "2 h 5 min", "3 d 4 h": an age for people. */
export function age(seconds) {
  const s = Math.max(0, Math.round(seconds));
  if (s < 120) return `${s} s`;
  if (s < 7200) return `${Math.floor(s / 60)} min ${s % 60} s`;
  if (s < 172800) return `${Math.floor(s / 3600)} h ${Math.floor((s % 3600) / 60)} min`;
  return `${Math.floor(s / 86400)} d ${Math.floor((s % 86400) / 3600)} h`;
}

const trim = (text) => (text.includes(".") && !text.includes("e") ? text.replace(/\.?0+$/, "") : text);

/** A number with `digits` significant digits in engineering notation: SI prefix on the unit when it
 * takes one (2e-5 rad → "20 µrad"), ×10³ⁿ otherwise (2e-5 → "20e-6"); plain between 1e-3 and 1e4. */
export function eng(v, unit = "", digits = 4) {
  if (v === null || v === undefined || Number.isNaN(v)) return "—";
  const u = unit && unit !== "1" ? unit : "";
  if (!Number.isFinite(v)) return `${v > 0 ? "+" : "-"}∞${u ? ` ${u}` : ""}`;
  const a = Math.abs(v);
  let e3 = a === 0 ? 0 : Math.floor(Math.log10(a) / 3) * 3;
  if (Math.abs(Number((v / 10 ** e3).toPrecision(digits))) >= 1000) e3 += 3;
  const prefixed = PREFIXABLE.has(u) && PREFIXES[e3] !== undefined;
  if (!prefixed && (a === 0 || (a >= 1e-3 && a < 1e4))) return withUnit(trim(Number(v.toPrecision(digits)).toString()), u);
  const mantissa = trim((v / 10 ** e3).toPrecision(digits));
  if (prefixed) return `${mantissa} ${PREFIXES[e3]}${u}`;
  return withUnit(`${mantissa}e${e3}`, u);
}

const withUnit = (text, u) => (u ? `${text} ${u}` : text);

/** One scale for all ticks of an axis: exponent (multiple of 3), decimals and the axis unit label. */
export function axisScale(splits, unit = "") {
  const finite = splits.filter(Number.isFinite);
  const big = Math.max(0, ...finite.map(Math.abs));
  const u = unit && unit !== "1" ? unit : "";
  const plain = big === 0 || (big >= 1e-2 && big < 1e4);
  const e3 = plain ? 0 : Math.floor(Math.log10(big) / 3) * 3;
  const step = finite.length > 1 ? Math.abs(finite[1] - finite[0]) / 10 ** e3 : 1;
  const decimals = step > 0 ? Math.min(12, Math.max(0, -Math.floor(Math.log10(step) + 1e-9))) : 0;
  let label = u;
  if (e3 !== 0) label = PREFIXABLE.has(u) && PREFIXES[e3] !== undefined ? `${PREFIXES[e3]}${u}` : `×1e${e3}${u ? ` ${u}` : ""}`;
  return { e3, decimals, label };
}

/** Tick labels of one axis with the sign kept ("-168.85", "-2000"): the unit goes to the axis label. */
export function axisTicks(splits, unit = "") {
  const { e3, decimals } = axisScale(splits, unit);
  return splits.map((v) => (Number.isFinite(v) ? fixed(v / 10 ** e3, decimals) : ""));
}

const fixed = (x, decimals) => {
  const text = x.toFixed(decimals);
  return /^-0(\.0*)?$/.test(text) ? text.slice(1) : text;
};

/** Text of a value of a parameter described by its dictionary entry (enumeration label or eng + unit). */
export function valueText(v, info) {
  if (info && info.enumeration && v !== null && v !== undefined && Number.isFinite(v)) {
    const label = info.enumeration[String(Math.round(v))];
    if (label !== undefined) return `${label} (${Math.round(v)})`;
  }
  return eng(v, info ? info.units : "", 5);
}

/** Limit level of a value: "red", "yellow" or "" (limits as the dictionary states them; null = none). */
export function limitLevel(v, limits) {
  if (!limits || v === null || v === undefined) return "";
  if (Number.isNaN(v)) return "red";
  const below = (bound) => bound !== null && bound !== undefined && v < bound;
  const above = (bound) => bound !== null && bound !== undefined && v > bound;
  if (below(limits.red_low) || above(limits.red_high)) return "red";
  if (below(limits.yellow_low) || above(limits.yellow_high)) return "yellow";
  return "";
}

/** Severity an operator reads: the archive's red is critical, yellow is a warning. */
export const severityLabel = (severity) => ({ red: "critical", yellow: "warning", nominal: "normal" }[severity] || severity);

/** Quaternion hemisphere continuity: flip q → −q wherever it would jump to the other hemisphere
 * (q and −q are one attitude), so a sign flip does not draw as a jump. columns: 4 arrays, same instants. */
export function continuousQuaternion(columns) {
  const n = columns[0].length;
  const out = columns.map((c) => Float64Array.from(c, (x) => (x === null ? NaN : x)));
  let prev = null;
  for (let i = 0; i < n; i++) {
    const q = [out[0][i], out[1][i], out[2][i], out[3][i]];
    if (q.some(Number.isNaN)) continue;
    if (prev && prev[0] * q[0] + prev[1] * q[1] + prev[2] * q[2] + prev[3] * q[3] < 0) {
      for (let k = 0; k < 4; k++) { out[k][i] = -q[k]; q[k] = -q[k]; }
    }
    prev = q;
  }
  return out.map((c) => Array.from(c, (x) => (Number.isNaN(x) ? null : x)));
}

/** Groups of four parameter names that are one quaternion (same stem, suffix 0-3 or 1-4). */
export function quaternionGroups(names) {
  const stems = new Map();
  for (const name of names) {
    const m = /^(.*?)(\d)$/.exec(name);
    if (!m || !/q/i.test(m[1])) continue;
    if (!stems.has(m[1])) stems.set(m[1], {});
    stems.get(m[1])[m[2]] = name;
  }
  const groups = new Map();
  for (const [stem, members] of stems) {
    for (const digits of [["0", "1", "2", "3"], ["1", "2", "3", "4"]]) {
      if (digits.every((d) => members[d])) {
        const group = digits.map((d) => members[d]);
        for (const name of group) groups.set(name, group);
      }
    }
  }
  return groups;
}
