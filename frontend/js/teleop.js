// Teleop over /ws/teleop (geometry_msgs/Twist-shaped JSON): keyboard, on-screen pad, joystick, gamepad.
//
// Every input is a "source" giving a normalised command (-1..1 per axis); the first active source in
// priority order drives (keys > pad > joystick > gamepad). A change is sent at once (key-press latency),
// and re-sent every 100 ms while held so the server's deadman (0.5 s) keeps the robot moving; on release
// one zero command is sent and the server's deadman covers a lost one.
import { $, message, perf, state, wsURL } from "./core.js";
import { estop } from "./status.js";

const KEYMAP = {
  w: [1, 0, 0], arrowup: [1, 0, 0], s: [-1, 0, 0], arrowdown: [-1, 0, 0],
  a: [0, 0, 1], arrowleft: [0, 0, 1], d: [0, 0, -1], arrowright: [0, 0, -1],
  q: [0, 1, 0], e: [0, -1, 0],
};
const PRIORITY = ["keys", "pad", "joystick", "gamepad"];
const SLOW = 0.3; // Shift: 30 % of the chosen speed

const keys = new Set(); // keyboard keys held
const padKeys = new Set(); // on-screen buttons held
const sources = new Map(); // name -> {vx, vy, wz} in -1..1, or absent
state.keys = keys;
let socket = null;
let slowHeld = false;
let lastSentZero = true;

function connect() {
  socket = new WebSocket(wsURL("/ws/teleop"));
  socket.onmessage = (ev) => {
    const m = JSON.parse(ev.data);
    if (m.type === "hello" || m.type === "control") {
      state.driving = !!m.driving;
      state.role = m.role || state.role;
      document.dispatchEvent(new CustomEvent("navdeck:control", { detail: m }));
    }
    if (m.type === "error") {
      const allowed = m.allowed && m.allowed.length ? ` (allowed modes: ${m.allowed.join(", ")})` : "";
      const other = m.control && m.control.holder && !state.driving; // refused because someone else drives
      const todo = other ? ` (${m.control.holder.name || "another client"} holds control: press Take control to drive)` : "";
      message(`teleop refused: ${m.error}${allowed}${todo}`, "error");
      if (m.control) document.dispatchEvent(new CustomEvent("navdeck:control", { detail: m }));
    }
  };
  socket.onclose = (ev) => {
    socket = null;
    state.driving = false;
    if (ev.code === 1008) { message(`teleop closed: ${ev.reason || "sign in again"}`, "error"); return; }
    setTimeout(connect, 1000);
  };
}

/** Send a control message on the teleop socket ({type: "take_control"} etc.); false if not connected. */
export function sendControl(msg) {
  if (!socket || socket.readyState !== WebSocket.OPEN) return false;
  socket.send(JSON.stringify(msg));
  return true;
}

function fromKeys(set) {
  let vx = 0, vy = 0, wz = 0;
  for (const k of set) {
    const m = KEYMAP[k];
    if (m) { vx += m[0]; vy += m[1]; wz += m[2]; }
  }
  return { vx: Math.sign(vx), vy: Math.sign(vy), wz: Math.sign(wz) };
}

/** Set (or clear with null) one input source's normalised command and send the result now. */
export function setSource(name, cmd) {
  if (cmd && (cmd.vx || cmd.vy || cmd.wz)) sources.set(name, cmd);
  else sources.delete(name);
  send();
}

function currentTwist() {
  const name = PRIORITY.find((n) => sources.has(n));
  const c = name ? sources.get(name) : { vx: 0, vy: 0, wz: 0 };
  const lim = state.limits || { max_vel_x: 0.26, max_vel_y: 0, max_vel_theta: 1.0 };
  const scale = Number($("#speed-scale").value) * (slowHeld ? SLOW : 1);
  const vy = state.omni ? (lim.max_vel_y || lim.max_vel_x) : 0;
  return {
    linear: { x: c.vx * lim.max_vel_x * scale, y: c.vy * vy * scale, z: 0 },
    angular: { x: 0, y: 0, z: c.wz * lim.max_vel_theta * scale },
  };
}

export function sendTwist(twist) {
  if (!socket || socket.readyState !== WebSocket.OPEN) return;
  socket.send(JSON.stringify(twist));
}

function send() {
  const twist = currentTwist();
  const zero = twist.linear.x === 0 && twist.linear.y === 0 && twist.angular.z === 0;
  if (zero && lastSentZero) return;
  sendTwist(twist);
  lastSentZero = zero;
}

export function stop() {
  keys.clear();
  padKeys.clear();
  sources.clear();
  sendTwist({ linear: { x: 0, y: 0, z: 0 }, angular: { x: 0, y: 0, z: 0 } });
  lastSentZero = true;
}

const keyName = (ev) => ev.key.toLowerCase();
const typing = (ev) => ev.target && ["INPUT", "TEXTAREA", "SELECT"].includes(ev.target.tagName) && ev.target.type !== "range";

function onKeyDown(ev) {
  if (typing(ev)) return;
  const k = keyName(ev);
  if (k === "shift") { slowHeld = true; send(); return; }
  slowHeld = ev.shiftKey;
  if (k === "escape") { stop(); estop(); ev.preventDefault(); return; }
  if (k === " ") { stop(); ev.preventDefault(); return; }
  if (KEYMAP[k]) {
    // when the key went down (the event's own time, epoch ms), not when this handler got to run: a busy
    // main thread (the 3D view compiling shaders) delays handlers, and that delay is part of the latency
    if (!ev.repeat) perf.keyDownAt.push((ev.view || window).performance.timeOrigin + ev.timeStamp);
    keys.add(k);
    setSource("keys", fromKeys(keys));
    ev.preventDefault();
  }
}

function onKeyUp(ev) {
  const k = keyName(ev);
  slowHeld = k === "shift" ? false : ev.shiftKey;
  keys.delete(k);
  setSource("keys", fromKeys(keys));
}

export function attachKeys(target) {
  target.addEventListener("keydown", onKeyDown);
  target.addEventListener("keyup", onKeyUp);
  target.addEventListener("blur", () => { keys.clear(); setSource("keys", null); });
}

export function init() {
  for (const b of document.querySelectorAll(".teleop-pad .key")) {
    const k = b.dataset.key;
    const down = (ev) => {
      ev.preventDefault();
      if (k === " ") { stop(); return; }
      b.setPointerCapture?.(ev.pointerId);
      padKeys.add(k);
      setSource("pad", fromKeys(padKeys));
    };
    const up = () => { padKeys.delete(k); setSource("pad", fromKeys(padKeys)); };
    b.addEventListener("pointerdown", down);
    b.addEventListener("pointerup", up);
    b.addEventListener("pointercancel", up);
    b.addEventListener("lostpointercapture", up);
  }
  $("#speed-scale").addEventListener("input", (ev) => { $("#speed-out").textContent = `${Math.round(ev.target.value * 100)}%`; });
  attachKeys(window);
  const frame = $("#viewer");
  // The 3D view is same-origin: listen to its keys too, so driving works after clicking into it.
  // boot.js starts loading it before this module runs, so it may have loaded already (then no "load"
  // event comes); attaching twice is harmless.
  const attachFrame = () => { try { attachKeys(frame.contentWindow); } catch { /* cross-origin */ } };
  frame.addEventListener("load", attachFrame);
  try { if (frame.contentDocument?.readyState === "complete") attachFrame(); } catch { /* cross-origin */ }
  setInterval(() => { if (sources.size) { lastSentZero = false; send(); } }, 100); // feed the deadman
  connect();
}
