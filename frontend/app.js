// navdeck dashboard: telemetry, mode buttons, keyboard/button teleop and the e-stop.
// Plain ES module, no build step.

const $ = (sel) => document.querySelector(sel);
const wsURL = (path) => `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}${path}`;

const state = { mode: null, allowed: [], omni: false, limits: null, keys: new Set(), teleop: null, driving: false };

export function message(text, kind = "info") {
  const li = document.createElement("li");
  li.className = kind;
  li.textContent = `${new Date().toLocaleTimeString()}  ${text}`;
  const list = $("#messages");
  list.prepend(li);
  while (list.children.length > 30) list.lastChild.remove();
}

async function api(method, path, body) {
  const res = await fetch(path, {
    method,
    headers: body ? { "Content-Type": "application/json" } : {},
    body: body ? JSON.stringify(body) : undefined,
  });
  let data = null;
  try { data = await res.json(); } catch { /* empty body */ }
  if (!res.ok) {
    const why = data && data.detail ? (typeof data.detail === "string" ? data.detail : JSON.stringify(data.detail)) : res.statusText;
    const allowed = data && data.allowed ? ` (allowed: ${data.allowed.join(", ") || "none"})` : "";
    message(`${method} ${path} refused: ${why}${allowed}`, "error");
    throw new Error(why);
  }
  return data;
}

// ---------------------------------------------------------------- telemetry
function fmt(v, d = 2) { return v === null || v === undefined ? "–" : Number(v).toFixed(d); }

function render(t) {
  state.mode = t.mode;
  state.allowed = t.allowed_modes || [];
  const badge = $("#mode-badge");
  badge.textContent = t.mode + (t.fault ? `: ${t.fault}` : "");
  badge.className = `badge ${t.mode}`;
  $("#st-mode").textContent = t.mode + (t.behavior ? ` (${t.behavior})` : "");
  $("#st-pose").textContent = `x ${fmt(t.pose.x)}  y ${fmt(t.pose.y)}  θ ${fmt(t.pose.theta * 180 / Math.PI, 0)}°`;
  $("#st-speed").textContent = `${fmt(t.velocity.linear.x)} m/s  ${fmt(t.velocity.angular.z)} rad/s`;
  const cl = t.clamped && t.clamped.length ? ` (clamped: ${t.clamped.join(", ")})` : "";
  $("#st-cmd").textContent = `${fmt(t.command.linear.x)} m/s  ${fmt(t.command.angular.z)} rad/s${cl}`;
  const h = t.health || {};
  const link = $("#st-link");
  link.textContent = `${h.link || "?"}${h.link_reason ? ": " + h.link_reason : ""}  scan age ${fmt(h.scan_age_s, 2)} s`;
  link.className = h.link === "ok" ? "ok-text" : "bad-text";
  $("#st-battery").textContent = h.battery_v ? `${fmt(h.battery_v, 1)} V (${fmt(h.battery_pct, 0)}%)` : "–";
  const loop = h.loop || {};
  $("#st-loop").textContent = loop.lateness_p99_ms !== undefined
    ? `p99 late ${fmt(loop.lateness_p99_ms, 1)} ms, tick ${fmt(loop.tick_p50_ms, 1)} ms` : "–";
  const holder = t.control && t.control.holder;
  $("#st-control").textContent = holder ? `${holder.name}${state.driving ? " (you)" : ""}` : "nobody";
  for (const b of document.querySelectorAll("[data-mode]")) {
    b.classList.toggle("active", b.dataset.mode === t.mode);
    b.disabled = b.dataset.mode !== t.mode && !state.allowed.includes(b.dataset.mode);
  }
}

function connectTelemetry() {
  const ws = new WebSocket(wsURL("/ws/telemetry?hz=10"));
  let wasDown = false;
  ws.onmessage = (ev) => render(JSON.parse(ev.data));
  ws.onopen = () => { if (connectTelemetry.everDown) reloadViewer(); };
  ws.onclose = () => {
    connectTelemetry.everDown = true;
    if (!wasDown) message("telemetry disconnected; retrying", "error");
    wasDown = true;
    $("#mode-badge").textContent = "disconnected";
    $("#mode-badge").className = "badge fault";
    setTimeout(connectTelemetry, 1000);
  };
}

function reloadViewer() {
  // An iframe only reconnects while focused (viser.md); reload it when the server comes back.
  const f = $("#viewer");
  f.src = "/viz/";
}

// ---------------------------------------------------------------- teleop
function connectTeleop() {
  const ws = new WebSocket(wsURL("/ws/teleop?name=dashboard"));
  ws.onmessage = (ev) => {
    const m = JSON.parse(ev.data);
    if (m.type === "hello" || m.type === "control") state.driving = !!m.driving;
    if (m.type === "error") message(`teleop: ${m.error}`, "error");
  };
  ws.onclose = () => { state.teleop = null; setTimeout(connectTeleop, 1000); };
  state.teleop = ws;
}

const KEYMAP = {
  w: [1, 0, 0], arrowup: [1, 0, 0], s: [-1, 0, 0], arrowdown: [-1, 0, 0],
  a: [0, 0, 1], arrowleft: [0, 0, 1], d: [0, 0, -1], arrowright: [0, 0, -1],
  q: [0, 1, 0], e: [0, -1, 0],
};

function currentTwist(slow) {
  let vx = 0, vy = 0, wz = 0;
  for (const k of state.keys) {
    const m = KEYMAP[k];
    if (m) { vx += m[0]; vy += m[1]; wz += m[2]; }
  }
  const lim = state.limits || { max_vel_x: 0.26, max_vel_y: 0, max_vel_theta: 1.0 };
  const scale = Number($("#speed-scale").value) * (slow ? 0.3 : 1);
  return {
    linear: { x: Math.sign(vx) * lim.max_vel_x * scale, y: Math.sign(vy) * (lim.max_vel_y || 0) * scale, z: 0 },
    angular: { x: 0, y: 0, z: Math.sign(wz) * lim.max_vel_theta * scale },
  };
}

let slowHeld = false;
let lastSentZero = true;
function sendTeleop() {
  const ws = state.teleop;
  if (!ws || ws.readyState !== WebSocket.OPEN) return;
  const twist = currentTwist(slowHeld);
  const zero = twist.linear.x === 0 && twist.linear.y === 0 && twist.angular.z === 0;
  if (zero && lastSentZero) return; // nothing held: let the deadman stop the robot, don't spam
  ws.send(JSON.stringify(twist));
  lastSentZero = zero;
}

function keyName(ev) { return ev.key.length === 1 ? ev.key.toLowerCase() : ev.key.toLowerCase(); }

function onKeyDown(ev) {
  if (ev.target && (ev.target.tagName === "INPUT" || ev.target.tagName === "TEXTAREA")) return;
  const k = keyName(ev);
  slowHeld = ev.shiftKey;
  if (k === "escape") { estop(); ev.preventDefault(); return; }
  if (k === " ") { state.keys.clear(); sendStop(); ev.preventDefault(); return; }
  if (KEYMAP[k]) { state.keys.add(k); sendTeleop(); ev.preventDefault(); }
}

function onKeyUp(ev) {
  slowHeld = ev.shiftKey;
  state.keys.delete(keyName(ev));
  sendTeleop();
}

function sendStop() {
  const ws = state.teleop;
  if (ws && ws.readyState === WebSocket.OPEN) {
    ws.send(JSON.stringify({ linear: { x: 0, y: 0, z: 0 }, angular: { x: 0, y: 0, z: 0 } }));
  }
  lastSentZero = true;
}

function attachKeys(target) {
  target.addEventListener("keydown", onKeyDown);
  target.addEventListener("keyup", onKeyUp);
  target.addEventListener("blur", () => { state.keys.clear(); sendStop(); });
}

async function estop() {
  state.keys.clear();
  try { await api("POST", "/api/robot/estop"); message("E-STOP latched: reset to drive again", "error"); } catch { /* shown */ }
}

// ---------------------------------------------------------------- wiring
async function init() {
  try {
    const robot = await api("GET", "/api/robot");
    state.limits = robot.profile.limits;
    state.omni = robot.profile.kinematics === "omni";
    $("#robot-name").textContent = `${robot.name} · ${robot.profile.name}`;
  } catch { /* retried by telemetry */ }
  $("#estop").addEventListener("click", estop);
  $("#reset").addEventListener("click", async () => {
    try { await api("POST", "/api/robot/reset"); message("reset: robot is idle", "ok"); } catch { /* shown */ }
  });
  for (const b of document.querySelectorAll("[data-mode]")) {
    b.addEventListener("click", async () => {
      try { await api("POST", "/api/robot/mode", { mode: b.dataset.mode }); message(`mode → ${b.dataset.mode}`, "ok"); } catch { /* shown */ }
    });
  }
  for (const b of document.querySelectorAll(".teleop-pad .key")) {
    const k = b.dataset.key;
    const down = (ev) => { ev.preventDefault(); if (k === " ") { state.keys.clear(); sendStop(); } else { state.keys.add(k); sendTeleop(); } };
    const up = () => { state.keys.delete(k); sendTeleop(); };
    b.addEventListener("pointerdown", down);
    b.addEventListener("pointerup", up);
    b.addEventListener("pointerleave", up);
    b.addEventListener("pointercancel", up);
  }
  $("#speed-scale").addEventListener("input", (ev) => { $("#speed-out").textContent = `${Math.round(ev.target.value * 100)}%`; });
  attachKeys(window);
  const frame = $("#viewer");
  frame.addEventListener("load", () => { try { attachKeys(frame.contentWindow); } catch { /* cross-origin */ } });
  // Keep the command alive while keys are held (the server's deadman stops after 0.5 s of silence).
  setInterval(() => { if (state.keys.size) sendTeleop(); }, 100);
  connectTelemetry();
  connectTeleop();
}

init();
