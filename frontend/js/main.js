// Live page entry point: who am I, the robot, telemetry, the 3D view's first frame, feature modules.
import { $, api, emitTelemetry, loadMe, message, perf, state, wsURL } from "./core.js";
import * as control from "./control.js";
import * as gamepad from "./gamepad.js";
import * as goals from "./goals.js";
import * as joystick from "./joystick.js";
import * as modes from "./modes.js";
import * as status from "./status.js";
import * as teleop from "./teleop.js";

// Feature modules: each exports init(); add new ones here.
const FEATURES = [status, teleop, joystick, gamepad, modes, goals, control];

function connectTelemetry() {
  const ws = new WebSocket(wsURL("/ws/telemetry?hz=10"));
  let down = false;
  ws.onmessage = (ev) => {
    if (perf.telemetryAt === null) perf.telemetryAt = performance.now();
    emitTelemetry(JSON.parse(ev.data));
  };
  ws.onopen = () => { down = false; };
  ws.onclose = (ev) => {
    if (ev.code === 1008) { message(`telemetry closed: ${ev.reason || "sign in again"}`, "error"); return; }
    if (!down) message("telemetry disconnected; retrying", "error");
    down = true;
    $("#mode-badge").textContent = "disconnected";
    $("#mode-badge").className = "badge mode-fault";
    setTimeout(connectTelemetry, 1000);
  };
}

/** Time from navigation start to the 3D view's first rendered frame: three.js's first draw call into the
 *  view's WebGL context, plus one animation frame (the frame holding that draw has been handed to the
 *  compositor when the next one starts). The draw calls of the view's window are wrapped as soon as its
 *  document exists (before its bundle runs) and unwrapped at the first one. Milestones on the way go to
 *  ``perf.view`` (ms since this page's navigation start) for bench/dashboard.py's breakdown. */
function watchFirstFrame() {
  const frame = $("#viewer");
  const marks = (perf.view = {});
  const done = (how) => {
    if (perf.firstFrameMs !== null) return;
    perf.firstFrameMs = performance.now();
    perf.firstFrameHow = how;
    document.body.dataset.viewReady = "1";
  };
  const wrapDraws = (win) => {
    const restore = [];
    const first = () => {
      if (marks.firstDraw !== undefined) return;
      marks.firstDraw = performance.now();
      for (const undo of restore) undo();
      win.requestAnimationFrame(() => done("draw"));
    };
    for (const proto of [win.WebGL2RenderingContext?.prototype, win.WebGLRenderingContext?.prototype]) {
      if (!proto) continue;
      for (const fn of ["drawElements", "drawArrays", "drawElementsInstanced", "drawArraysInstanced"]) {
        const orig = proto[fn];
        if (typeof orig !== "function") continue;
        proto[fn] = function (...args) { first(); return orig.apply(this, args); };
        restore.push(() => { proto[fn] = orig; });
      }
    }
    return restore.length > 0;
  };
  let wrapped = false;
  const poll = () => {
    let win = null, doc = null;
    try { win = frame.contentWindow; doc = frame.contentDocument; } catch { return; } // cross-origin: no figure
    if (!wrapped && win && doc && win.location.pathname.startsWith("/viz")) {
      marks.viewCommitted = performance.now();
      wrapped = wrapDraws(win);
      if (!wrapped) marks.noWrap = true;
    }
    const canvas = doc && [...doc.querySelectorAll("canvas")].find((c) => c.width > 0 && c.height > 0);
    if (canvas && marks.canvas === undefined) marks.canvas = performance.now();
    if (canvas && !wrapped) { // could not watch the draws: fall back to "canvas + two frames"
      win.requestAnimationFrame(() => win.requestAnimationFrame(() => done("canvas")));
      return;
    }
    if (marks.firstDraw === undefined) setTimeout(poll, 20);
  };
  poll();
}

async function init() {
  watchFirstFrame();
  await loadMe();
  try {
    const robot = await api("GET", "/api/robot");
    state.robot = robot;
    state.limits = robot.profile.limits;
    state.omni = robot.profile.kinematics === "omni";
    $("#robot-name").textContent = `${robot.name} · ${robot.profile.name}`;
  } catch { /* telemetry retries */ }
  for (const f of FEATURES) f.init();
  status.applyRole();
  connectTelemetry();
}

init();
