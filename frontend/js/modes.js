// Mapping (start / stop / save with a name), localization (global, initial pose from the 3D view),
// navigation cancel, and what a click in the 3D view sets. Refusals show the server's reason.
import { $, api, message, state } from "./core.js";

async function call(method, path, body, ok) {
  try {
    const res = await api(method, path, body);
    if (ok) message(typeof ok === "function" ? ok(res) : ok, "ok");
    return res;
  } catch { return null; /* the refusal is already in Messages */ }
}

function showClickMode(kind) {
  for (const r of document.querySelectorAll('input[name="click-mode"]')) r.checked = r.value === kind;
}

/** What a click in THIS tab's 3D view sets (other tabs keep theirs). */
async function setClickMode(kind) {
  if (!state.tab) { message("the 3D view has not loaded yet: try again in a moment", "error"); showClickMode("goal"); return null; }
  const res = await call("POST", "/api/viewer/click_mode", { kind, tab: state.tab });
  showClickMode(res ? res.kind : "goal");
  return res;
}

export function init() {
  $("#map-start").addEventListener("click", () => call("POST", "/api/mapping/start", undefined,
    "mapping started: drive around (keys, joystick or gamepad); the map grows in the 3D view"));
  $("#map-stop").addEventListener("click", () => call("POST", "/api/mapping/stop", undefined, "mapping stopped"));
  $("#map-save").addEventListener("click", async () => {
    const name = window.prompt("Name for the map", `map ${new Date().toISOString().slice(0, 16).replace("T", " ")}`);
    if (name === null) return;
    if (!name.trim()) { message("a map needs a name", "error"); return; }
    await call("POST", "/api/mapping/save", { name: name.trim() },
      (res) => `map "${name.trim()}" saved${res && (res.id ?? res.map_id) !== undefined ? ` (id ${res.id ?? res.map_id})` : ""}: see Maps`);
  });
  $("#loc-global").addEventListener("click", () => call("POST", "/api/localization/global", undefined,
    "global localization: the robot turns in place until it knows where it is"));
  $("#loc-initial").addEventListener("click", async () => {
    if (await setClickMode("initial_pose")) {
      message("click (or shift+drag for the heading) in the 3D view where the robot is: one click sets it", "ok");
    }
  });
  $("#nav-cancel").addEventListener("click", () => call("POST", "/api/navigation/cancel", undefined, "navigation cancelled"));
  for (const r of document.querySelectorAll('input[name="click-mode"]')) {
    r.addEventListener("change", () => { if (r.checked) setClickMode(r.value); });
  }
  // an initial pose is one-shot: the server says when this tab's clicks set goals again
  document.addEventListener("navdeck:click-mode", (ev) => showClickMode(ev.detail));
  document.addEventListener("navdeck:view-tab", (ev) => {
    if (!ev.detail) return;
    fetch(`/api/viewer/click_mode?tab=${encodeURIComponent(ev.detail)}`).then((r) => (r.ok ? r.json() : null))
      .then((res) => { if (res) showClickMode(res.kind); }).catch(() => {});
  });
}
