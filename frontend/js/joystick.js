// On-screen joystick over the 3D view (pointer events: mouse, pen and touch alike).
// Up/down is forward/back, left/right turns (strafing on omni robots: Q/E or the gamepad's right
// stick). Releasing recentres the stick and stops.
import { $ } from "./core.js";
import { setSource } from "./teleop.js";

const DEAD = 0.08; // normalised radius treated as centre

export function init() {
  const pad = $("#joystick");
  const stick = $("#stick");
  if (!pad) return;
  let active = null;

  function place(ev) {
    const r = pad.getBoundingClientRect();
    const R = r.width / 2;
    let dx = (ev.clientX - (r.left + R)) / R;
    let dy = (ev.clientY - (r.top + R)) / R;
    const n = Math.hypot(dx, dy);
    if (n > 1) { dx /= n; dy /= n; }
    stick.style.transform = `translate(${dx * R * 0.6}px, ${dy * R * 0.6}px)`;
    const dz = (v) => (Math.abs(v) < DEAD ? 0 : v);
    setSource("joystick", { vx: dz(-dy), vy: 0, wz: dz(-dx) });
  }

  function release() {
    active = null;
    pad.classList.remove("active");
    stick.style.transform = "";
    setSource("joystick", null);
  }

  pad.addEventListener("pointerdown", (ev) => {
    ev.preventDefault();
    active = ev.pointerId;
    pad.setPointerCapture(ev.pointerId);
    pad.classList.add("active");
    place(ev);
  });
  pad.addEventListener("pointermove", (ev) => { if (ev.pointerId === active) place(ev); });
  pad.addEventListener("pointerup", release);
  pad.addEventListener("pointercancel", release);
  pad.addEventListener("lostpointercapture", () => { if (active !== null) release(); });
}
