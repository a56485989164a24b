// Explore with one click: start / stop frontier exploration (optional time budget), its state in the
// status panel (explored area, frontiers, time left), and the offer to save the map when it ends.
import { $, api, fmt, message, onTelemetry } from "./core.js";

function minutes(s) {
  if (s === null || s === undefined) return "";
  return s >= 90 ? `${Math.floor(s / 60)} min ${Math.round(s % 60)} s` : `${fmt(s, 0)} s`;
}

function render(t) {
  const ex = t.exploration || null;
  const el = $("#st-explore");
  const offer = $("#explore-offer");
  if (!ex) { el.textContent = "–"; offer.hidden = true; return; }
  const area = ex.explored_area_m2 === null ? "–" : `${fmt(ex.explored_area_m2, 1)} m²`;
  const fr = ex.frontiers === null ? "" : `, ${ex.frontiers} frontier${ex.frontiers === 1 ? "" : "s"}`;
  const left = ex.time_left_s !== null && ex.time_left_s !== undefined ? `, ${minutes(ex.time_left_s)} left` : "";
  el.textContent = ex.active
    ? `exploring: ${area} mapped${fr}${left}`
    : `${ex.state}${ex.reason ? ": " + ex.reason : ""} (${area} mapped)`;
  el.dataset.frontiers = ex.frontiers === null ? "" : String(ex.frontiers);
  el.dataset.state = ex.state;
  el.className = ex.active ? "ok-text" : "";
  offer.hidden = !ex.save_offered;
}

async function save() {
  const name = window.prompt("Name for the explored map", `explored ${new Date().toISOString().slice(0, 16).replace("T", " ")}`);
  if (name === null) return;
  if (!name.trim()) { message("a map needs a name", "error"); return; }
  try {
    const res = await api("POST", "/api/mapping/save", { name: name.trim() });
    message(`map "${name.trim()}" saved (id ${res.id}): see Maps`, "ok");
  } catch { /* the refusal is in Messages */ }
}

export function init() {
  onTelemetry(render);
  $("#explore-start").addEventListener("click", async () => {
    const budget = parseFloat($("#explore-budget").value);
    const body = Number.isFinite(budget) && budget > 0 ? { time_budget_s: budget } : {};
    try {
      await api("POST", "/api/exploration/start", body);
      message("exploring: the robot maps the place, driving to the edge of what it has seen", "ok");
    } catch { /* shown */ }
  });
  $("#explore-stop").addEventListener("click", async () => {
    try { await api("POST", "/api/exploration/stop"); message("exploration stopped: mapping goes on", "ok"); } catch { /* shown */ }
  });
  $("#explore-save").addEventListener("click", save);
}
