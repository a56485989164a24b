// Live page entry point: who am I, the robot, telemetry, the 3D view's first frame, feature modules.
import { $, api, emitTelemetry, loadMe, message, perf, state, wsURL } from "./core.js";
import * as control from "./control.js";
import * as explore from "./explore.js";
import * as gamepad from "./gamepad.js";
import * as goals from "./goals.js";
import * as joystick from "./joystick.js";
import * as modes from "./modes.js";
import * as status from "./status.js";
import * as teleop from "./teleop.js";

// Feature modules: each exports init(); add new ones here.
const FEATURES = [status, teleop, joystick, gamepad, modes, goals, control, explore];

/** Server-side refusals and notices for this tab (a refused click in its 3D view, the new map frame). */
function showNotices(t) {
  for (const n of t.notices || []) {
    if (n.type === "refused") {
      const what = (n.what || "action").replace("_", " ");
      message(`${what} refused${n.via ? ` (${n.via})` : ""}: ${n.reason}`, "error");
    } else if (n.text) message(n.text, "ok");
    if (n.click_mode) document.dispatchEvent(new CustomEvent("navdeck:click-mode", { detail: n.click_mode }));
  }
}

/** The token of this tab's 3D view (chosen by the view's page, see app/viewer/client.py), which the
 *  server uses for this tab's click mode, layers and notices; null when the view has none. */
async function viewTab() {
  const frame = $("#viewer");
  for (let i = 0; i < 600 && frame; i += 1) { // up to 30 s: the view's page loads while this page does
    try {
      const tab = frame.contentWindow && frame.contentWindow.__navdeckTab;
      if (tab) return tab;
    } catch { return null; } // another origin
    await new Promise((r) => setTimeout(r, 50));
  }
  return null;
}

let telemetry = null;
let down = false;

function connectTelemetry() {
  const tab = state.tab ? `&tab=${encodeURIComponent(state.tab)}` : "";
  const ws = (telemetry = new WebSocket(wsURL(`/ws/telemetry?hz=10${tab}`)));
  ws.onmessage = (ev) => {
    if (perf.telemetryAt === null) perf.telemetryAt = performance.now();
    const t = JSON.parse(ev.data);
    showNotices(t);
    emitTelemetry(t);
  };
  ws.onopen = () => { down = false; };
  ws.onclose = (ev) => {
    if (ws.retab) { connectTelemetry(); return; } // reopened for this tab's notices, not lost
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
  state.tab = await viewTab();
  if (state.tab) {
    document.dispatchEvent(new CustomEvent("navdeck:view-tab", { detail: state.tab }));
    if (telemetry && telemetry.readyState <= WebSocket.OPEN) { telemetry.retab = true; telemetry.close(); }
  }
}

init();
