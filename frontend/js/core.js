// Shared helpers for the dashboard's feature modules: API calls, messages, telemetry fan-out.

export const $ = (sel) => document.querySelector(sel);
export const wsURL = (path) => `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}${path}`;

/** Dashboard-wide state every feature module may read. */
export const state = { mode: null, allowed: [], omni: false, limits: null, robot: null, driving: false, last: null };

const telemetryListeners = [];
/** Call ``fn(t)`` with every telemetry message (t is /ws/telemetry's JSON). */
export function onTelemetry(fn) { telemetryListeners.push(fn); }
export function emitTelemetry(t) {
  state.last = t;
  for (const fn of telemetryListeners) {
    try { fn(t); } catch (err) { console.error(err); }
  }
}

export function message(text, kind = "info") {
  const li = document.createElement("li");
  li.className = kind;
  li.textContent = `${new Date().toLocaleTimeString()}  ${text}`;
  const list = $("#messages");
  if (!list) return;
  list.prepend(li);
  while (list.children.length > 30) list.lastChild.remove();
}

/** fetch + JSON; refusals are shown as messages with the server's reason, then thrown. */
export async function api(method, path, body) {
  const opts = { method, headers: {} };
  if (body instanceof FormData) opts.body = body;
  else if (body !== undefined) { opts.headers["Content-Type"] = "application/json"; opts.body = JSON.stringify(body); }
  const res = await fetch(path, opts);
  let data = null;
  try { data = await res.json(); } catch { /* empty body */ }
  if (!res.ok) {
    const why = data && data.detail ? (typeof data.detail === "string" ? data.detail : JSON.stringify(data.detail)) : res.statusText;
    const allowed = data && data.allowed ? ` (allowed: ${data.allowed.join(", ") || "none"})` : "";
    message(`${method} ${path} refused: ${why}${allowed}`, "error");
    const err = new Error(why);
    err.status = res.status;
    err.data = data;
    throw err;
  }
  return data;
}

export function fmt(v, d = 2) { return v === null || v === undefined ? "–" : Number(v).toFixed(d); }

/** Add a titled section to the side panel (feature modules call this for their controls). */
export function panelSection(id, title) {
  let sec = document.getElementById(id);
  if (sec) return sec;
  sec = document.createElement("section");
  sec.id = id;
  sec.setAttribute("aria-labelledby", `${id}-h`);
  sec.innerHTML = `<h2 id="${id}-h">${title}</h2>`;
  $("#feature-panels").appendChild(sec);
  return sec;
}
