// Shared helpers for the dashboard's feature modules: API calls, messages, telemetry fan-out.

export const $ = (sel) => document.querySelector(sel);
export const wsURL = (path) => `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}${path}`;

/** Dashboard-wide state every feature module may read. */
export const state = {
  mode: null, allowed: [], omni: false, limits: null, robot: null, driving: false, last: null,
  me: null, // GET /api/auth/me: role, username, can_drive
  tab: null, // this tab's 3D view token: the server keeps its click mode and layers (app/viewer/tabs.py)
};

/** Timings the browser tests and the latency report read (ms since navigation start / epoch ms). */
export const perf = (window.__navdeck = window.__navdeck || { firstFrameMs: null, keyDownAt: [], telemetryAt: null });

/** Sign-in required and missing (401): go to the login page, then come back here. */
export function toLogin() {
  location.assign(`/login.html?next=${encodeURIComponent(location.pathname + location.search)}`);
}

const telemetryListeners = [];
/** Call ``fn(t)`` with every telemetry message (t is /ws/telemetry's JSON). */
export function onTelemetry(fn) { telemetryListeners.push(fn); }
export function emitTelemetry(t) {
  state.last = t;
  for (const fn of telemetryListeners) {
    try { fn(t); } catch (err) { console.error(err); }
  }
}

const TOAST_MS = { error: 15000, ok: 6000, info: 6000 };
let toastTimer = null;

/** The latest message in the top bar, next to the mode badge (the Messages list can be below the fold). */
function toast(text, kind, count) {
  const el = $("#toast");
  if (!el) return;
  if (!el.dataset.wired) {
    el.dataset.wired = "1";
    el.querySelector(".toast-close").addEventListener("click", () => { el.hidden = true; });
  }
  el.className = `toast ${kind}`;
  el.querySelector(".toast-text").textContent = text;
  el.querySelector(".toast-count").textContent = count > 1 ? `x${count}` : "";
  el.title = text;
  el.hidden = false;
  clearTimeout(toastTimer);
  toastTimer = setTimeout(() => { el.hidden = true; }, TOAST_MS[kind] || TOAST_MS.info);
}

/** Show ``text`` in Messages and in the top bar's toast. The same message again (a held key refused
 *  several times a second) does not add a line: the newest line counts it ("x12") and takes its time. */
export function message(text, kind = "info") {
  const list = $("#messages");
  const newest = list && list.firstElementChild;
  let count = 1;
  if (newest && newest.dataset.text === text && newest.classList.contains(kind)) {
    count = Number(newest.dataset.count || 1) + 1;
    newest.dataset.count = String(count);
    newest.querySelector(".msg-time").textContent = new Date().toLocaleTimeString();
    newest.querySelector(".msg-count").textContent = `x${count}`;
  } else if (list) {
    const li = document.createElement("li");
    li.className = kind;
    li.dataset.text = text;
    li.dataset.count = "1";
    const time = document.createElement("span");
    time.className = "msg-time";
    time.textContent = new Date().toLocaleTimeString();
    const body = document.createElement("span");
    body.className = "msg-text";
    body.textContent = text;
    const times = document.createElement("span");
    times.className = "msg-count";
    li.append(time, body, times);
    list.prepend(li);
    while (list.children.length > 30) list.lastChild.remove();
  }
  toast(text, kind, count);
}

/** fetch + JSON; refusals are shown as messages with the server's reason, then thrown. */
export async function api(method, path, body) {
  const opts = { method, headers: {} };
  if (body instanceof FormData) opts.body = body;
  else if (body !== undefined) { opts.headers["Content-Type"] = "application/json"; opts.body = JSON.stringify(body); }
  const res = await fetch(path, opts);
  let data = null;
  try { data = await res.json(); } catch { /* empty body */ }
  if (res.status === 401 && !path.startsWith("/api/auth/")) { toLogin(); throw new Error("sign in required"); }
  if (!res.ok) {
    const why = data && data.detail ? (typeof data.detail === "string" ? data.detail : JSON.stringify(data.detail)) : res.statusText;
    const allowed = data && data.allowed && data.allowed.length ? ` (allowed: ${data.allowed.join(", ")})` : "";
    const nearest = data && data.nearest_free ? ` (nearest free: ${fmt(data.nearest_free.x)}, ${fmt(data.nearest_free.y)})` : "";
    const missing = res.status === 404 && why === "Not Found" ? " (this server does not have that feature yet)" : "";
    message(`${method} ${path} refused (${res.status}): ${why}${allowed}${nearest}${missing}`, "error");
    const err = new Error(why);
    err.status = res.status;
    err.data = data;
    throw err;
  }
  return data;
}

/** The header's E-STOP on the pages without the Live controls (Maps, Runs): latches; reset on Live. */
export function wireEstop() {
  const btn = $("#estop");
  if (!btn) return;
  btn.addEventListener("click", async () => {
    try { await api("POST", "/api/robot/estop"); message("E-STOP latched: reset on the Live page", "error"); } catch { /* shown */ }
  });
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

/** Upload a FormData with progress (XMLHttpRequest: fetch has no upload progress); resolves to JSON. */
export function upload(path, form, onProgress) {
  return new Promise((resolve, reject) => {
    const xhr = new XMLHttpRequest();
    xhr.open("POST", path);
    xhr.responseType = "json";
    xhr.upload.onprogress = (ev) => { if (ev.lengthComputable) onProgress(ev.loaded / ev.total); };
    xhr.onload = () => {
      const data = xhr.response;
      if (xhr.status === 401) { toLogin(); reject(new Error("sign in required")); return; }
      if (xhr.status >= 200 && xhr.status < 300) { onProgress(1); resolve(data); return; }
      const why = data && data.detail ? (typeof data.detail === "string" ? data.detail : JSON.stringify(data.detail)) : xhr.statusText;
      message(`upload refused (${xhr.status}): ${why}`, "error");
      const err = new Error(why);
      err.status = xhr.status;
      reject(err);
    };
    xhr.onerror = () => { message("upload failed: network error", "error"); reject(new Error("network error")); };
    xhr.send(form);
  });
}

/** Who am I (role, sign-in); fills the top bar's user box when sign-in is on. */
export async function loadMe() {
  try { state.me = await api("GET", "/api/auth/me"); } catch { state.me = null; }
  const box = $("#user-box");
  if (box && state.me && state.me.signed_in) {
    box.hidden = false;
    $("#user-name").textContent = `${state.me.username} (${state.me.role})`;
    $("#sign-out").addEventListener("click", async () => {
      try { await api("POST", "/api/auth/logout"); } finally { toLogin(); }
    });
  }
  return state.me;
}
