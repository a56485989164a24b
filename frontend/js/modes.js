// Mapping (start / stop / save with a name), localization (global, initial pose from the 3D view),
// navigation cancel, and what a click in the 3D view sets. Refusals show the server's reason.
import { $, api, message } from "./core.js";

async function call(method, path, body, ok) {
  try {
    const res = await api(method, path, body);
    if (ok) message(typeof ok === "function" ? ok(res) : ok, "ok");
    return res;
  } catch { return null; /* the refusal is already in Messages */ }
}

async function setClickMode(kind) {
  const res = await call("POST", "/api/viewer/click_mode", { kind });
  for (const r of document.querySelectorAll('input[name="click-mode"]')) r.checked = r.value === (res ? res.kind : "goal");
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
    if (await setClickMode("initial_pose")) message("click (or shift+drag for the heading) in the 3D view where the robot is", "ok");
  });
  $("#nav-cancel").addEventListener("click", () => call("POST", "/api/navigation/cancel", undefined, "navigation cancelled"));
  for (const r of document.querySelectorAll('input[name="click-mode"]')) {
    r.addEventListener("change", () => { if (r.checked) setClickMode(r.value); });
  }
  fetch("/api/viewer/click_mode").then((r) => (r.ok ? r.json() : null)).then((res) => {
    if (res) for (const r of document.querySelectorAll('input[name="click-mode"]')) r.checked = r.value === res.kind;
  }).catch(() => {});
}
