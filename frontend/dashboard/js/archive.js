// Archive management from the UI, each form naming the role the API requires: telemetry uploads
// (CCSDS packets, CSV, JSONL) with the ingest report as tables, TLEs, ground stations and pass
// prediction, telemetry dictionaries.
import { api, errorText } from "./api.js";
import { $, el, fill, table } from "./dom.js";
import { eng, isoUtc, isoUtcNs } from "./format.js";
import { emit, satParam, state } from "./state.js";

const ROLE_RANK = { viewer: 1, operator: 2, admin: 3 };

export async function loadArchive() {
  const [dictionaries, tle] = await Promise.all([
    api("/dictionaries"),
    api(`/satellites/${satParam()}/tle`).catch(() => null),
  ]);
  for (const id of ["upload-dictionary"]) {
    const keep = $(id).value;
    fill($(id), dictionaries.map((d) => el("option", { value: d }, d)));
    if (keep && dictionaries.includes(keep)) $(id).value = keep;
  }
  $("tle-current").textContent = tle ? `newest TLE: ${tleText(tle)}` : `no TLE for ${state.satellite} yet`;
  applyRole();
}

const tleText = (tle) => [tle.name, tle.line1, tle.line2].filter(Boolean).join(" / ")
  + (tle.epoch_ns ? ` (epoch ${isoUtcNs(tle.epoch_ns)})` : "");

/** Forms whose route needs a higher role than the token's are disabled, saying which role they need. */
export function applyRole() {
  const have = ROLE_RANK[state.role] ?? ROLE_RANK.operator;  // unknown role: let the API answer
  for (const form of document.querySelectorAll("#archive-panel form[data-role]")) {
    const need = form.dataset.role;
    const allowed = have >= ROLE_RANK[need];
    for (const input of form.elements) input.disabled = !allowed;
    form.querySelector(".role").textContent = allowed ? `needs ${need}` : `needs ${need}: your token is ${state.role}`;
  }
}

function report(box, result) {
  const archive = result.archive || {};
  const decoding = result.decoding || {};
  const scalar = (o) => Object.entries(o).filter(([, v]) => v === null || typeof v !== "object");
  const parts = [
    el("h4", {}, `upload ${archive.upload_id ?? ""} into ${result.satellite} (${result.dictionary || "dictionary"})`),
    table(["archive", "value"], scalar(archive).map(([k, v]) => [k, String(v)]), { class: "report-archive" }),
    table(["decoding", "value"], scalar(decoding).map(([k, v]) => [k, String(v)]), { class: "report-decoding" }),
  ];
  if (archive.gaps && archive.gaps.length) {
    parts.push(table(["APID", "after (UTC)", "before (UTC)", "missing packets"],
      archive.gaps.map((g) => [String(g.apid), isoUtcNs(g.after_t_ns), isoUtcNs(g.before_t_ns), String(g.missing)]), { class: "report-gaps" }));
  }
  for (const [key, list] of Object.entries(decoding).filter(([, v]) => Array.isArray(v) && v.length)) {
    const columns = Object.keys(list[0]);
    parts.push(el("h4", {}, `${key} (${list.length})`),
      table(columns, list.slice(0, 50).map((row) => columns.map((c) => String(row[c] ?? ""))), { class: `report-${key}` }));
  }
  fill(box, parts);
}

async function submit(event, run) {
  event.preventDefault();
  const form = event.target;
  const out = form.querySelector(".result");
  fill(out, "working…");
  try {
    await run(form, out);
  } catch (err) {
    fill(out, el("span", { class: "error" }, errorText(err)));
  }
}

async function upload(form, out) {
  const file = $("upload-file").files[0];
  if (!file) throw Object.assign(new Error("choose a file to upload"), { field: "file" });
  const format = $("upload-format").value;
  const result = await api("/telemetry/uploads", {
    method: "POST", body: await file.arrayBuffer(), headers: { "Content-Type": "application/octet-stream" },
    query: { satellite: state.satellite, dictionary: $("upload-dictionary").value, format, source: file.name },
  });
  report(out, result);
  emit("archive-changed");
}

async function uploadTle(form, out) {
  const text = $("tle-text").value.trim();
  const answer = await api(`/satellites/${satParam()}/tles`, { method: "POST", body: text, headers: { "Content-Type": "text/plain" } });
  fill(out, `TLE stored (${Object.keys(answer).length ? JSON.stringify(answer) : "ok"})`);
  await loadArchive();
}

async function saveStation(form, out) {
  const body = { name: $("station-name").value.trim(), lat_deg: Number($("station-lat").value),
    lon_deg: Number($("station-lon").value), alt_m: Number($("station-alt").value),
    min_elevation_deg: Number($("station-mask").value) };
  await api("/ground-stations", { method: "POST", json: body });
  fill(out, `station ${body.name} saved (${eng(body.lat_deg, "", 6)}°, ${eng(body.lon_deg, "", 6)}°)`);
}

async function predict(form, out) {
  const hours = Number($("predict-hours").value);
  const start = state.window ? state.window[0] : Date.now() / 1000;
  const passes = await api(`/satellites/${satParam()}/passes/predict`, { method: "POST",
    query: { station: $("predict-station").value.trim(), start: isoUtc(start), end: isoUtc(start + hours * 3600) } });
  await api(`/satellites/${satParam()}/passes/reception`, { method: "POST" });
  fill(out, `${passes.length} passes predicted`);
  emit("archive-changed");
}

async function uploadDictionary(form, out) {
  const file = $("dictionary-file").files[0];
  if (!file) throw Object.assign(new Error("choose a dictionary file"), { field: "file" });
  const name = $("dictionary-name").value.trim() || file.name;
  const answer = await api(`/dictionaries/${encodeURIComponent(name)}`, { method: "POST", body: await file.arrayBuffer(),
    headers: { "Content-Type": "application/octet-stream" },
    query: { apid: $("dictionary-apid").value, time_code: $("dictionary-time-code").value.trim() } });
  fill(out, table(["APID", "packet"], Object.entries(answer.packets).map(([apid, p]) => [apid, p]), { class: "report-dictionary" }));
  await loadArchive();
}

export function wireArchive() {
  $("upload-form").addEventListener("submit", (e) => submit(e, upload));
  $("tle-form").addEventListener("submit", (e) => submit(e, uploadTle));
  $("station-form").addEventListener("submit", (e) => submit(e, saveStation));
  $("predict-form").addEventListener("submit", (e) => submit(e, predict));
  $("dictionary-form").addEventListener("submit", (e) => submit(e, uploadDictionary));
}
