// Live updates over the WebSocket /api/v1/ws (backend/routes/live.py): subscribe to parameters/*,
// alarms, twin and archive (commits, e.g. a large upload archived without live replay); hand each batch
// to the panels; reconnect with back-off; a "last packet N s ago / stale" indicator per satellite, from
// the newest sample time seen.
import { wsUrl } from "./api.js";
import { $, el, fill } from "./dom.js";
import { age, isoUtc } from "./format.js";
import { emit, state } from "./state.js";

const TOPICS = ["parameters/*", "alarms", "twin", "archive"];
const RETRY_S = [1, 2, 5, 10, 20];
const CLOSE_UNAUTHORIZED = 4401, CLOSE_FORBIDDEN = 4403;
let socket = null;
let attempt = 0;
let retryTimer = null;
let tickTimer = null;
let wanted = false;

const staleAfterS = () => state.constants.stale_after_s ?? 10;

function setLink(text, kind) {
  const node = $("live-link");
  node.textContent = text;
  node.className = kind;
}

export function connectLive() {
  wanted = true;
  clearTimeout(retryTimer);
  if (socket) socket.close();
  const ws = new WebSocket(wsUrl());
  socket = ws;
  setLink("live: connecting…", "pending");
  ws.onopen = () => {
    attempt = 0;
    ws.send(JSON.stringify({ op: "subscribe", topics: TOPICS }));
    setLink("live: connected", "ok");
  };
  ws.onmessage = (event) => {
    const message = JSON.parse(event.data);
    if (message.type === "batch") dispatch(message.items);
    else if (message.type === "error") setLink(`live: ${message.message}`, "error");
  };
  ws.onclose = (event) => {
    if (socket !== ws) return;
    socket = null;
    if (event.code === CLOSE_UNAUTHORIZED || event.code === CLOSE_FORBIDDEN) {
      setLink("live: token refused (expired or revoked)", "error");
      emit("unauthorized", "the live stream refused the token");
      return;
    }
    if (!wanted) return;
    const wait = RETRY_S[Math.min(attempt++, RETRY_S.length - 1)];
    setLink(`live: disconnected, retrying in ${wait} s`, "error");
    retryTimer = setTimeout(connectLive, wait * 1000);
  };
  clearInterval(tickTimer);
  tickTimer = setInterval(renderAges, 1000);
}

export function disconnectLive() {
  wanted = false;
  clearTimeout(retryTimer);
  clearInterval(tickTimer);
  if (socket) socket.close();
  socket = null;
  setLink("live: off", "pending");
}

function dispatch(items) {
  const bySatellite = {};
  for (const { topic, data } of items) {
    if (topic.startsWith("parameters/") && data && data.satellite) {
      const name = topic.slice("parameters/".length);
      const batch = (bySatellite[data.satellite] ||= {});
      const entry = (batch[name] ||= { t_utc_ns: [], values: [] });
      entry.t_utc_ns.push(...data.t_utc_ns);
      entry.values.push(...data.values);
      const newest = data.t_utc_ns[data.t_utc_ns.length - 1] / 1e9;
      if (!(state.lastPacketS[data.satellite] >= newest)) state.lastPacketS[data.satellite] = newest;
    } else if (topic === "alarms") {
      emit("alarms", data);
    } else if (topic === "twin") {
      emit("twin", data);
    } else if (topic === "archive" && data && data.satellite) {
      const newest = data.t_last_utc_ns === null ? null : data.t_last_utc_ns / 1e9;
      if (newest !== null && !(state.lastPacketS[data.satellite] >= newest)) state.lastPacketS[data.satellite] = newest;
      emit("archive-committed", data);
    }
  }
  for (const [satellite, batch] of Object.entries(bySatellite)) emit("samples", { satellite, batch });
  renderAges();
}

/** The per-satellite indicator: newest packet's age, stale past the server's stale_after_s. */
export function renderAges() {
  const box = $("satellite-ages");
  const names = [...new Set(state.satellites.map((s) => s.name).concat(Object.keys(state.lastPacketS)))]
    .filter((n) => n && (n === state.satellite || state.lastPacketS[n] !== undefined));
  const now = Date.now() / 1000;
  fill(box, names.map((name) => {
    const t = state.lastPacketS[name];
    const known = t !== undefined && t !== null;
    const stale = !known || now - t > staleAfterS();
    const text = known ? `last packet ${age(now - t)} ago${stale ? " · stale" : ""}` : "no telemetry yet";
    return el("button", {
      type: "button", class: `age ${stale ? "stale" : "fresh"}${name === state.satellite ? " current" : ""}`,
      title: known ? `newest sample ${isoUtc(t, 3)}` : "nothing archived", dataset: { satellite: name },
      onclick: () => emit("choose-satellite", name),
    }, el("b", {}, name), ` ${text}`);
  }));
}
