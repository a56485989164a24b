// Mode badge, mode buttons, status panel, e-stop and reset.
import { $, api, fmt, message, onTelemetry, state } from "./core.js";

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

export async function estop() {
  state.keys && state.keys.clear();
  try { await api("POST", "/api/robot/estop"); message("E-STOP latched: reset to drive again", "error"); } catch { /* shown */ }
}

export function init() {
  onTelemetry(render);
  $("#estop").addEventListener("click", estop);
  $("#reset").addEventListener("click", async () => {
    try { await api("POST", "/api/robot/reset"); message("reset: robot is idle", "ok"); } catch { /* shown */ }
  });
  for (const b of document.querySelectorAll("[data-mode]")) {
    b.addEventListener("click", async () => {
      try { await api("POST", "/api/robot/mode", { mode: b.dataset.mode }); message(`mode → ${b.dataset.mode}`, "ok"); } catch { /* shown */ }
    });
  }
}
