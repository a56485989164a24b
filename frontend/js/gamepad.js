// Gamepad (W3C Gamepad API, "standard" mapping): hold the deadman button (LB, index 4) and use the left
// stick (up: forward, sideways: turn); the right stick's x strafes on omni robots. Letting go of the
// deadman, or the pad disconnecting, stops at once. Polled at 20 Hz (the API has no change events).
import { $, state } from "./core.js";
import { setSource } from "./teleop.js";

const DEADMAN = 4; // LB
const ESTOP_BUTTON = 1; // B / circle: e-stop
const DEADZONE = 0.12;

const dz = (v) => (Math.abs(v) < DEADZONE ? 0 : (v - Math.sign(v) * DEADZONE) / (1 - DEADZONE));

export function init() {
  const status = $("#gamepad-status");
  let held = false;
  let estopWas = false;
  let name = null;

  window.addEventListener("gamepadconnected", (ev) => { name = ev.gamepad.id; status.textContent = `Gamepad: ${name} (hold LB to drive)`; });
  window.addEventListener("gamepaddisconnected", () => {
    name = null;
    status.textContent = "Gamepad: disconnected";
    if (held) { held = false; setSource("gamepad", null); }
  });

  setInterval(() => {
    const pads = navigator.getGamepads ? [...navigator.getGamepads()].filter(Boolean) : [];
    const gp = pads[0];
    if (!gp) return;
    const pressed = (i) => !!(gp.buttons[i] && gp.buttons[i].pressed);
    const e = pressed(ESTOP_BUTTON);
    if (e && !estopWas) document.getElementById("estop").click();
    estopWas = e;
    if (!pressed(DEADMAN)) {
      if (held) { held = false; setSource("gamepad", null); status.textContent = `Gamepad: ${gp.id} (hold LB to drive)`; }
      return;
    }
    held = true;
    const vx = -dz(gp.axes[1] || 0);
    const wz = -dz(gp.axes[0] || 0);
    const vy = state.omni ? -dz(gp.axes[2] || 0) : 0;
    status.textContent = `Gamepad: driving (LB held) ${vx.toFixed(2)} / ${wz.toFixed(2)}`;
    setSource("gamepad", { vx, vy, wz });
  }, 50);
}
