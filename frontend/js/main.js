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

/** Time from navigation start to the 3D view's first painted frame: the viser canvas exists, has a size,
 *  and the iframe's window has run two animation frames since (the second one follows a paint). */
function watchFirstFrame() {
  const frame = $("#viewer");
  const poll = () => {
    let doc = null;
    try { doc = frame.contentDocument; } catch { return; }
    const canvas = doc && [...doc.querySelectorAll("canvas")].find((c) => c.width > 0 && c.height > 0);
    if (!canvas) { setTimeout(poll, 20); return; }
    const win = frame.contentWindow;
    win.requestAnimationFrame(() => win.requestAnimationFrame(() => {
      perf.firstFrameMs = performance.now();
      document.body.dataset.viewReady = "1";
    }));
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
