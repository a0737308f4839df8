// The REST API (/api/v1, Bearer token): one fetch wrapper whose errors say what went wrong —
// server unreachable, token refused (expired or revoked), role too low, or the API's own message and field.

export class ApiError extends Error {
  constructor(message, { status = 0, field = null, kind = "api" } = {}) {
    super(message);
    this.status = status;
    this.field = field;
    this.kind = kind;  // "unreachable" | "unauthorized" | "forbidden" | "api"
  }
}

export const session = {
  base: "/api/v1",
  token: sessionStorage.getItem("acs-twin-token") || "",
  onUnauthorized: null,  // called once per refused token (the app shows the login again)
  onUnreachable: null,   // called when the server does not answer (the app shows retry)
};

export function setToken(token) {
  session.token = token;
  if (token) sessionStorage.setItem("acs-twin-token", token);
  else sessionStorage.removeItem("acs-twin-token");
}

/** GET/POST path under the API base; options: {method, json, body, headers, query}. */
export async function api(path, options = {}) {
  const headers = Object.assign({}, options.headers || {});
  if (session.token) headers.Authorization = `Bearer ${session.token}`;
  let body = options.body;
  if (options.json !== undefined) {
    headers["Content-Type"] = "application/json";
    body = JSON.stringify(options.json);
  }
  const url = session.base + path + query(options.query);
  let response;
  try {
    response = await fetch(url, { method: options.method || "GET", headers, body });
  } catch (err) {
    const error = new ApiError(`server unreachable (${location.origin}): ${err.message}`, { kind: "unreachable" });
    if (session.onUnreachable) session.onUnreachable(error);
    throw error;
  }
  const type = response.headers.get("content-type") || "";
  const answer = type.includes("json") ? await response.json() : await response.text();
  if (response.ok) return answer;
  const message = answer && answer.message ? answer.message : `${response.status} ${response.statusText}`;
  const kind = response.status === 401 ? "unauthorized" : response.status === 403 ? "forbidden" : "api";
  const error = new ApiError(message, { status: response.status, field: answer && answer.field, kind });
  if (kind === "unauthorized" && session.onUnauthorized) session.onUnauthorized(error);
  throw error;
}

function query(params) {
  if (!params) return "";
  const q = new URLSearchParams();
  for (const [k, v] of Object.entries(params)) if (v !== undefined && v !== null && v !== "") q.set(k, v);
  const text = q.toString();
  return text ? `?${text}` : "";
}

/** GET that answers `fallback` when the route does not exist on this server (404 without a field). */
export async function optional(path, fallback, options = {}) {
  try {
    return await api(path, options);
  } catch (err) {
    if ((err.status === 404 || err.status === 405) && !err.field) return fallback;
    throw err;
  }
}

/** The WebSocket URL of the live stream (token as a query parameter, the browser cannot set headers). */
export function wsUrl() {
  const scheme = location.protocol === "https:" ? "wss:" : "ws:";
  const token = session.token ? `?token=${encodeURIComponent(session.token)}` : "";
  return `${scheme}//${location.host}${session.base}/ws${token}`;
}

/** Message an operator reads for an error (with the API's field). */
export const errorText = (err) => `${err.message}${err.field ? ` (field: ${err.field})` : ""}`;
