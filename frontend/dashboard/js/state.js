// The dashboard's shared state (one satellite at a time) and a tiny event bus between panels.

export const state = {
  satellite: "",
  satellites: [],        // [{name, latest_telemetry_utc}] from the API
  info: {},              // dictionary entry of each archived parameter: units, description, enumeration, limits
  window: null,          // [t0_s, t1_s] plotted (a pass or the telemetry span), Unix seconds
  windowLabel: "",
  following: true,       // the plotted window ends at the newest telemetry: live samples extend it
  constants: {},         // the server's constants (GET /constants)
  role: null,            // role of the token (viewer | operator | admin), null when unknown
  lastPacketS: {},       // satellite -> newest sample time seen (Unix s)
};

const listeners = {};

export function on(event, handler) {
  (listeners[event] ||= []).push(handler);
}

export function emit(event, detail) {
  for (const handler of listeners[event] || []) {
    try {
      handler(detail);
    } catch (err) {
      console.error(event, err);
    }
  }
}

export const satParam = () => encodeURIComponent(state.satellite);
