// Goals and waypoints: the navigator's queue (from telemetry) and a draft list sent as waypoints.
import { $, api, fmt, message, onTelemetry, state } from "./core.js";

const draft = []; // poses {x, y, theta}, or places {place, x, y, theta}
let places = [];
const pose = (g) => `x ${fmt(g.x)}  y ${fmt(g.y)}  θ ${fmt((g.theta * 180) / Math.PI, 0)}°`;

function renderDraft() {
  const list = $("#draft-list");
  list.replaceChildren(...draft.map((g, i) => {
    const li = document.createElement("li");
    li.textContent = g.place ? `${g.place} (${pose(g)})` : pose(g);
    const rm = document.createElement("button");
    rm.className = "btn small";
    rm.textContent = "✕";
    rm.setAttribute("aria-label", `remove waypoint ${i + 1}`);
    rm.addEventListener("click", () => { draft.splice(i, 1); renderDraft(); });
    li.appendChild(rm);
    return li;
  }));
  $("#goals-send").disabled = draft.length === 0 || !!(state.me && !state.me.can_drive);
}

let lastKey = "";
function renderQueue(t) {
  const nav = t.navigation;
  const goals = nav && nav.active ? nav.goals || [] : [];
  const idx = nav ? nav.goal_index || 0 : 0;
  const key = JSON.stringify([goals, idx]);
  if (key === lastKey) return;
  lastKey = key;
  refreshMission(); // a leg ended or the mission did: its outcomes changed
  $("#goal-list").replaceChildren(...goals.map((g, i) => {
    const li = document.createElement("li");
    li.textContent = pose(g);
    li.className = i < idx ? "done" : i === idx ? "current" : "";
    return li;
  }));
}

// The newest mission's legs, each with its outcome (reached / failed / cancelled and why), the last
// LEGS_SHOWN of a long patrol (the list keeps their numbers). Fetched when the navigator's goal list
// or progress changes.
const LEGS_SHOWN = 30;
let missionBusy = false;
async function refreshMission() {
  if (missionBusy) return;
  missionBusy = true;
  try {
    renderLegs((await api("GET", "/api/missions?limit=1")).items[0]);
  } catch { /* no navigation on this server: the panel stays empty */ } finally { missionBusy = false; }
}

function renderLegs(m) {
  const head = $("#mission-head");
  if (!m) { head.textContent = ""; $("#mission-legs").replaceChildren(); return; }
  const p = m.progress;
  head.textContent = `mission ${m.id.slice(0, 6)}: ${m.state}, ${p.goals_reached} of ${p.goal_count} legs reached`;
  const first = Math.max(0, m.goals.length - LEGS_SHOWN);
  $("#mission-legs").replaceChildren(...m.goals.slice(first).map((g, k) => {
    const li = document.createElement("li");
    li.value = first + k + 1;
    li.className = `leg-${g.state}`;
    li.textContent = `${pose(g.pose)}: ${g.state}${g.reason ? ` (${g.reason})` : ""}`;
    return li;
  }));
}

const deg = (rad) => fmt((Math.abs(rad) * 180) / Math.PI, 0);
const within = (n) => `within ${fmt(n.xy_goal_tolerance)} m and ${deg(n.yaw_goal_tolerance)}°`;

// What "reached" means (the goal checker's tolerances) and how close the robot got.
function renderResult(t) {
  const nav = t.navigation;
  const el = $("#goal-result");
  let text = "";
  if (nav && nav.xy_goal_tolerance !== undefined) {
    const o = nav.outcome;
    if (nav.active) {
      text = `counts as reached ${within(nav)} of the goal; now ${fmt(nav.distance_to_goal)} m away`;
    } else if (o && o.distance_to_goal !== undefined && o.distance_to_goal !== null) {
      const off = `${fmt(o.distance_to_goal)} m and ${deg(o.yaw_to_goal)}° from the goal`;
      text = o.kind === "succeeded" ? `reached ${within(o)}: stopped ${off}` : `${o.kind}: stopped ${off}`;
    }
  }
  if (el.textContent !== text) el.textContent = text;
}

export function init() {
  onTelemetry(renderQueue);
  onTelemetry(renderResult);
  $("#goal-form").addEventListener("submit", (ev) => {
    ev.preventDefault();
    const f = ev.target;
    const g = { x: Number(f.x.value), y: Number(f.y.value), theta: (Number(f.theta.value || 0) * Math.PI) / 180 };
    if (![g.x, g.y, g.theta].every(Number.isFinite)) { message("a waypoint needs numbers for x, y and θ", "error"); return; }
    draft.push(g);
    renderDraft();
  });
  $("#goals-clear").addEventListener("click", () => { draft.length = 0; renderDraft(); });
  $("#goals-send").addEventListener("click", async () => {
    if (!draft.length) return;
    const repeat = Math.max(1, Math.round(Number($("#route-repeat").value) || 1));
    const patrol = $("#route-patrol").checked;
    try {
      if (repeat > 1 || patrol || draft.some((g) => g.place)) {
        // a route: places by name and poses, run `repeat` times (or as a patrol until cancelled)
        // as one mission (a goal per leg)
        const stops = draft.map((g) => (g.place ? g.place : { x: g.x, y: g.y, theta: g.theta }));
        await api("POST", "/api/routes/run", patrol ? { stops, patrol } : { stops, repeat });
      } else {
        // Nav2's allow_unknown goal: the server refuses a waypoint in unknown space unless asked
        const goals = $("#goals-unknown").checked ? draft.map((g) => ({ ...g, allow_unknown: true })) : draft;
        await api("POST", "/api/navigation/goals", goals.length === 1 ? goals[0] : goals);
      }
      const times = patrol ? " as a patrol" : repeat > 1 ? ` × ${repeat}` : "";
      message(`navigating through ${draft.length} waypoint${draft.length > 1 ? "s" : ""}${times}`, "ok");
      draft.length = 0;
      renderDraft();
    } catch { /* the refusal (409/422 with its reason) is in Messages */ }
  });
  $("#place-select").addEventListener("focus", loadPlaces);
  $("#place-go").addEventListener("click", async () => {
    const name = $("#place-select").value;
    if (!name) { message("choose a place first", "error"); return; }
    try {
      await api("POST", "/api/navigation/goals", { place: name });
      message(`navigating to "${name}"`, "ok");
    } catch { /* refusal shown in Messages */ }
  });
  $("#place-add").addEventListener("click", () => {
    const p = places.find((q) => q.name === $("#place-select").value);
    if (!p) { message("choose a place first", "error"); return; }
    draft.push({ place: p.name, ...p.pose });
    renderDraft();
  });
  renderDraft();
  loadPlaces();
  refreshMission();
}

// The active map's places (named poses, drawn on the Maps page's editor)
async function loadPlaces() {
  try {
    const maps = await api("GET", "/api/maps?limit=1");
    if (maps.active_map_id == null) return;
    places = (await api("GET", `/api/maps/${maps.active_map_id}/places?limit=500`)).items;
  } catch { return; }
  const sel = $("#place-select");
  const keep = sel.value;
  const opts = places.map((p) => { const o = document.createElement("option"); o.value = p.name; o.textContent = p.name; return o; });
  const head = document.createElement("option");
  head.value = "";
  head.textContent = places.length ? "places…" : "no places on this map";
  sel.replaceChildren(head, ...opts);
  sel.value = places.some((p) => p.name === keep) ? keep : "";
}
