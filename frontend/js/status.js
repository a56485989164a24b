// Mode badge, mode buttons, status panel (mode, behaviour, battery, link, localization, goal), e-stop, reset.
import { behaviorColor } from "./behaviors.js";
import { $, api, fmt, message, onTelemetry, state } from "./core.js";

const deg = (rad) => fmt((rad * 180) / Math.PI, 0);

function eta(s) {
  if (s === null || s === undefined) return "–";
  return s >= 90 ? `${Math.floor(s / 60)} min ${Math.round(s % 60)} s` : `${fmt(s, 0)} s`;
}

/** "IN CONTACT with obstacle: free: back, turn left" or "none (nearest 0.31 m)". */
function contactText(c) {
  if (!c) return "–";
  if (!c.in_contact) return c.nearest_m === null ? "none" : `none (nearest ${fmt(c.nearest_m, 2)} m)`;
  const free = Object.entries(c.free || {}).filter(([, ok]) => ok).map(([name]) => name);
  return `IN CONTACT${c.with ? " with " + c.with : ""}: ` + (free.length ? `free: ${free.join(", ")}` : "no free motion");
}

function render(t) {
  state.mode = t.mode;
  state.allowed = t.allowed_modes || [];
  const badge = $("#mode-badge");
  const cleared = t.health && t.health.fault_cleared; // latched, cause gone: not a present fault
  badge.textContent = t.mode + (t.fault ? (cleared ? ": cause gone, press Reset" : `: ${t.fault}`) : "");
  badge.className = `badge mode-${t.mode}`;
  $("#st-mode").textContent = t.mode;
  const nav = t.navigation || null;
  // the behaviour's name on its colour (as in the 3D view), the navigator's own words beside it
  const beh = $("#st-behavior");
  const activity = nav && nav.active ? nav.activity : null;
  if (t.behavior) {
    beh.innerHTML = "";
    const tag = document.createElement("span");
    tag.className = "behavior-tag";
    tag.textContent = t.behavior;
    tag.style.background = behaviorColor(t.behavior);
    beh.append(tag);
    if (activity) beh.append(` ${activity}`);
    beh.dataset.behavior = t.behavior;
  } else {
    beh.textContent = activity || "–";
    delete beh.dataset.behavior;
  }
  $("#st-pose").textContent = `x ${fmt(t.pose.x)}  y ${fmt(t.pose.y)}  θ ${deg(t.pose.theta)}°`;
  const h = t.health || {};
  const lost = h.link === "lost"; // the last speeds are stale, not the robot's: show none
  $("#st-speed").textContent = lost ? "— (base link lost)" : `${fmt(t.velocity.linear.x)} m/s  ${fmt(t.velocity.angular.z)} rad/s`;
  const cl = t.clamped && t.clamped.length ? ` (clamped: ${t.clamped.join(", ")})` : "";
  $("#st-cmd").textContent = `${fmt(t.command.linear.x)} m/s  ${fmt(t.command.angular.z)} rad/s${cl}`;
  // base link, then the lidar: a lidar fault is not an "ok" link, and a base-only robot says so
  const link = $("#st-link");
  const base = `${h.link || "?"}${h.link_reason ? ": " + h.link_reason : ""}`;
  const lidar = h.lidar === false ? "no lidar (base only)"
    : h.lidar_fault ? h.lidar_fault : `scan age ${fmt(h.scan_age_s, 2)} s`;
  link.textContent = `${base}  ${lidar}`;
  link.className = h.link === "ok" && !h.lidar_fault ? "ok-text" : "bad-text";
  const batt = $("#st-battery");
  batt.textContent = h.battery_v ? `${fmt(h.battery_v, 1)} V (${fmt(h.battery_pct, 0)}%)` : "–";
  batt.className = h.battery_pct !== null && h.battery_pct !== undefined && h.battery_pct < 20 ? "bad-text" : "";
  const loc = t.localization || null;
  const locEl = $("#st-loc");
  if (t.mode === "mapping") { // AMCL is off while mapping: SLAM's pose is the estimate
    locEl.textContent = "by SLAM (mapping)";
    locEl.className = "ok-text";
  } else if (loc) {
    const q = loc.quality !== undefined ? `${fmt(loc.quality * 100, 0)}%` : "?";
    locEl.textContent = `${loc.localized ? "localized" : loc.global_running ? "searching…" : "not localized"}, quality ${q}` +
      (loc.particles ? `, ${loc.particles} particles` : "");
    locEl.className = loc.localized && loc.quality >= 0.5 ? "ok-text" : "warn-text";
  } else locEl.textContent = "–";
  const goal = $("#st-goal");
  if (nav && nav.active && nav.goal) {
    goal.textContent = `${fmt(nav.distance_remaining_m)} m to go, ETA ${eta(nav.eta_s)}`;
  } else if (nav && nav.outcome) {
    const o = nav.outcome;
    goal.textContent = typeof o === "string" ? o : `${o.kind || o.outcome || "done"}${o.reason ? ": " + o.reason : ""}`;
  } else goal.textContent = t.goal ? `goal x ${fmt(t.goal.x)} y ${fmt(t.goal.y)}` : "–";
  const loop = h.loop || {};
  $("#st-loop").textContent = loop.lateness_p99_ms !== undefined
    ? `p99 late ${fmt(loop.lateness_p99_ms, 1)} ms, tick ${fmt(loop.tick_p50_ms, 1)} ms` : "–";
  $("#st-contact").textContent = contactText(t.contact);
  $("#st-contact").className = t.contact && t.contact.in_contact ? "bad-text" : "";
  const holder = t.control && t.control.holder;
  $("#st-control").textContent = holder ? `${holder.name}${state.driving ? " (you)" : ""}` : "nobody";
  const viewer = state.me && !state.me.can_drive;
  for (const b of document.querySelectorAll("[data-mode]")) {
    b.classList.toggle("active", b.dataset.mode === t.mode);
    b.disabled = viewer || (b.dataset.mode !== t.mode && !state.allowed.includes(b.dataset.mode));
  }
}

/** Viewers watch: every control that would move the robot is disabled (the server refuses them anyway). */
export function applyRole() {
  if (!state.me || state.me.can_drive) return;
  document.body.classList.add("viewer");
  for (const el of document.querySelectorAll(".panel button, .panel input, #reset, #take-control")) el.disabled = true;
  document.getElementById("joystick")?.setAttribute("aria-disabled", "true");
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
