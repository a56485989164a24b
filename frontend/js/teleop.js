// Keyboard and on-screen teleop over /ws/teleop (geometry_msgs/Twist-shaped JSON).
import { $, message, state, wsURL } from "./core.js";
import { estop } from "./status.js";

const KEYMAP = {
  w: [1, 0, 0], arrowup: [1, 0, 0], s: [-1, 0, 0], arrowdown: [-1, 0, 0],
  a: [0, 0, 1], arrowleft: [0, 0, 1], d: [0, 0, -1], arrowright: [0, 0, -1],
  q: [0, 1, 0], e: [0, -1, 0],
};
const keys = new Set();
state.keys = keys;
let socket = null;
let slowHeld = false;
let lastSentZero = true;

function connect() {
  socket = new WebSocket(wsURL("/ws/teleop?name=dashboard"));
  socket.onmessage = (ev) => {
    const m = JSON.parse(ev.data);
    if (m.type === "hello" || m.type === "control") state.driving = !!m.driving;
    if (m.type === "error") message(`teleop: ${m.error}`, "error");
  };
  socket.onclose = () => { socket = null; setTimeout(connect, 1000); };
}

function currentTwist() {
  let vx = 0, vy = 0, wz = 0;
  for (const k of keys) {
    const m = KEYMAP[k];
    if (m) { vx += m[0]; vy += m[1]; wz += m[2]; }
  }
  const lim = state.limits || { max_vel_x: 0.26, max_vel_y: 0, max_vel_theta: 1.0 };
  const scale = Number($("#speed-scale").value) * (slowHeld ? 0.3 : 1);
  return {
    linear: { x: Math.sign(vx) * lim.max_vel_x * scale, y: Math.sign(vy) * (lim.max_vel_y || 0) * scale, z: 0 },
    angular: { x: 0, y: 0, z: Math.sign(wz) * lim.max_vel_theta * scale },
  };
}

export function sendTwist(twist) {
  if (!socket || socket.readyState !== WebSocket.OPEN) return;
  socket.send(JSON.stringify(twist));
}

function sendKeys() {
  const twist = currentTwist();
  const zero = twist.linear.x === 0 && twist.linear.y === 0 && twist.angular.z === 0;
  if (zero && lastSentZero) return; // nothing held: the server's deadman stops the robot
  sendTwist(twist);
  lastSentZero = zero;
}

function stop() {
  keys.clear();
  sendTwist({ linear: { x: 0, y: 0, z: 0 }, angular: { x: 0, y: 0, z: 0 } });
  lastSentZero = true;
}

const keyName = (ev) => ev.key.toLowerCase();

function onKeyDown(ev) {
  if (ev.target && (ev.target.tagName === "INPUT" || ev.target.tagName === "TEXTAREA")) return;
  const k = keyName(ev);
  slowHeld = ev.shiftKey;
  if (k === "escape") { estop(); ev.preventDefault(); return; }
  if (k === " ") { stop(); ev.preventDefault(); return; }
  if (KEYMAP[k]) { keys.add(k); sendKeys(); ev.preventDefault(); }
}

function onKeyUp(ev) {
  slowHeld = ev.shiftKey;
  keys.delete(keyName(ev));
  sendKeys();
}

export function attachKeys(target) {
  target.addEventListener("keydown", onKeyDown);
  target.addEventListener("keyup", onKeyUp);
  target.addEventListener("blur", stop);
}

export function init() {
  for (const b of document.querySelectorAll(".teleop-pad .key")) {
    const k = b.dataset.key;
    const down = (ev) => { ev.preventDefault(); if (k === " ") stop(); else { keys.add(k); sendKeys(); } };
    const up = () => { keys.delete(k); sendKeys(); };
    b.addEventListener("pointerdown", down);
    b.addEventListener("pointerup", up);
    b.addEventListener("pointerleave", up);
    b.addEventListener("pointercancel", up);
  }
  $("#speed-scale").addEventListener("input", (ev) => { $("#speed-out").textContent = `${Math.round(ev.target.value * 100)}%`; });
  attachKeys(window);
  const frame = $("#viewer");
  // The 3D view is same-origin: listen to its keys too, so driving works after clicking into it.
  frame.addEventListener("load", () => { try { attachKeys(frame.contentWindow); } catch { /* cross-origin */ } });
  setInterval(() => { if (keys.size) sendKeys(); }, 100); // keep the deadman fed while keys are held
  connect();
}
