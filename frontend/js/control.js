// The control lease in the top bar: who holds it (everyone sees), take control, release.
import { $, api, message, onTelemetry, state } from "./core.js";
import { sendControl } from "./teleop.js";

function show(control) {
  const h = control && control.holder;
  const el = $("#control-holder");
  el.textContent = h ? `control: ${h.name}${state.driving ? " (you)" : ""}` : "control: free";
  el.classList.toggle("you", !!state.driving);
  const canDrive = !state.me || state.me.can_drive;
  $("#take-control").disabled = !canDrive || state.driving;
  $("#release-control").disabled = !state.driving;
  $("#take-control").title = canDrive ? "" : "viewers cannot drive";
}

export function init() {
  onTelemetry((t) => show(t.control));
  document.addEventListener("navdeck:control", (ev) => show(ev.detail.control));
  $("#take-control").addEventListener("click", async () => {
    if (!sendControl({ type: "take_control" })) {
      try { await api("POST", "/api/control/acquire", { take_over: true }); } catch { return; }
    }
    message("you have control", "ok");
  });
  $("#release-control").addEventListener("click", () => {
    if (sendControl({ type: "release_control" })) message("control released: the robot stops", "ok");
  });
}
