// Dashboard entry point: fetch the robot, start telemetry, initialise each feature module.
import { $, api, emitTelemetry, message, state, wsURL } from "./core.js";
import * as status from "./status.js";
import * as teleop from "./teleop.js";

// Feature modules: each exports init(); add new ones here.
const FEATURES = [status, teleop];

function connectTelemetry() {
  const ws = new WebSocket(wsURL("/ws/telemetry?hz=10"));
  let down = false;
  ws.onmessage = (ev) => emitTelemetry(JSON.parse(ev.data));
  ws.onopen = () => {
    if (connectTelemetry.lost) $("#viewer").src = "/viz/"; // an iframe only reconnects while focused
    connectTelemetry.lost = false;
  };
  ws.onclose = () => {
    if (!down) message("telemetry disconnected; retrying", "error");
    down = true;
    connectTelemetry.lost = true;
    $("#mode-badge").textContent = "disconnected";
    $("#mode-badge").className = "badge fault";
    setTimeout(connectTelemetry, 1000);
  };
}

async function init() {
  try {
    const robot = await api("GET", "/api/robot");
    state.robot = robot;
    state.limits = robot.profile.limits;
    state.omni = robot.profile.kinematics === "omni";
    $("#robot-name").textContent = `${robot.name} · ${robot.profile.name}`;
  } catch { /* telemetry retries */ }
  for (const f of FEATURES) f.init();
  connectTelemetry();
}

init();
