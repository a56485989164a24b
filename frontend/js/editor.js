// Map editor (issue 19): brush, line wall and polygon tools setting cells free / occupied / unknown,
// with undo/redo, saved as a new version of the map (POST /api/maps/{id}/versions, never activated
// by the save); polygons drawn as keepout or speed zones and click-placed places are stored at once.
// The map image is one pixel per cell, top row = max y (map_server's orientation); the map's origin
// yaw is assumed 0 (map_server maps and navdeck's own).
import { $, api, message } from "./core.js";

const COLORS = { free: "#3fb950", occupied: "#f85149", unknown: "#8b949e", keepout: "#ff3b30", speed: "#ffb000" };

let ed = null; // the open editor: { map, scale, ops, undone, draft, tool, ... }

// ---------------------------------------------------------------- polygon validation (as the API)
function cross(o, a, b) { return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]); }
function segmentsTouch(p1, p2, q1, q2) {
  const d1 = Math.sign(cross(p1, p2, q1)), d2 = Math.sign(cross(p1, p2, q2));
  const d3 = Math.sign(cross(q1, q2, p1)), d4 = Math.sign(cross(q1, q2, p2));
  if (d1 * d2 < 0 && d3 * d4 < 0) return true;
  const on = (a, b, c) => Math.min(a[0], b[0]) <= c[0] && c[0] <= Math.max(a[0], b[0]) && Math.min(a[1], b[1]) <= c[1] && c[1] <= Math.max(a[1], b[1]);
  return (d1 === 0 && on(p1, p2, q1)) || (d2 === 0 && on(p1, p2, q2)) || (d3 === 0 && on(q1, q2, p1)) || (d4 === 0 && on(q1, q2, p2));
}
/** Why a polygon would be refused (null if valid): the server's rules (nav/costmap/filter_layer.py). */
export function polygonProblem(pts) {
  if (pts.length < 3) return `a polygon needs at least 3 vertices, got ${pts.length}`;
  const n = pts.length;
  for (let i = 0; i < n; i++) {
    for (let j = i + 2; j < n; j++) {
      if (i === 0 && j === n - 1) continue; // adjacent through the closing edge
      if (segmentsTouch(pts[i], pts[(i + 1) % n], pts[j], pts[(j + 1) % n])) return `the polygon intersects itself (edges ${i} and ${j})`;
    }
  }
  let area = 0;
  for (let i = 0; i < n; i++) area += cross([0, 0], pts[i], pts[(i + 1) % n]);
  if (Math.abs(area) < 1e-12) return "the polygon has no area";
  return null;
}

// ---------------------------------------------------------------- coordinates
function toMap(ev) {
  const r = ed.canvas.getBoundingClientRect();
  const col = (ev.clientX - r.left) / ed.scale, rowTop = (ev.clientY - r.top) / ed.scale;
  const [ox, oy] = ed.map.origin;
  return [ox + col * ed.map.resolution, oy + (ed.map.height - rowTop) * ed.map.resolution];
}
function toPx([x, y]) {
  const [ox, oy] = ed.map.origin;
  return [((x - ox) / ed.map.resolution) * ed.scale, (ed.map.height - (y - oy) / ed.map.resolution) * ed.scale];
}

// ---------------------------------------------------------------- drawing
function stroke(ctx, pts, color, widthPx, close = false) {
  if (!pts.length) return;
  ctx.strokeStyle = color; ctx.fillStyle = color; ctx.lineWidth = Math.max(widthPx, 1.5); ctx.lineCap = "round"; ctx.lineJoin = "round";
  ctx.beginPath();
  pts.map(toPx).forEach(([px, py], i) => (i ? ctx.lineTo(px, py) : ctx.moveTo(px, py)));
  if (close) ctx.closePath();
  if (pts.length === 1) { const [px, py] = toPx(pts[0]); ctx.arc(px, py, widthPx / 2, 0, 2 * Math.PI); ctx.fill(); } else ctx.stroke();
}
function draw() {
  const ctx = ed.canvas.getContext("2d");
  ctx.clearRect(0, 0, ed.canvas.width, ed.canvas.height);
  ctx.imageSmoothingEnabled = false;
  ctx.drawImage(ed.image, 0, 0, ed.canvas.width, ed.canvas.height);
  const px = (m) => (m / ed.map.resolution) * ed.scale;
  for (const op of ed.ops) {
    if (op.op === "brush") stroke(ctx, op.points, COLORS[op.value], px(2 * op.radius));
    else if (op.op === "line") stroke(ctx, [op.start, op.end], COLORS[op.value], px(op.width));
    else { stroke(ctx, op.polygon, COLORS[op.value], 2, true); ctx.globalAlpha = 0.5; ctx.fill(); ctx.globalAlpha = 1; }
  }
  for (const z of ed.zones) { stroke(ctx, z.polygon, COLORS[z.kind], 2, true); }
  if (ed.draft.length) stroke(ctx, ed.draft, "#58a6ff", 2, ed.tool === "polygon");
  $("#ed-undo").disabled = !ed.ops.length;
  $("#ed-redo").disabled = !ed.undone.length;
  $("#ed-save").disabled = !ed.ops.length;
  $("#ed-count").textContent = `${ed.ops.length} edit${ed.ops.length === 1 ? "" : "s"} not saved`;
}

function push(op) { ed.ops.push(op); ed.undone = []; draw(); }

// ---------------------------------------------------------------- tools
function value() { return $("#ed-value").value; }
function onDown(ev) {
  const p = toMap(ev);
  const tool = $("#ed-tool").value;
  ed.tool = tool;
  if (tool === "brush" || tool === "line") { ed.draft = [p]; ed.drag = true; draw(); }
  else if (tool === "polygon" || tool === "keepout" || tool === "speed") { ed.draft.push(p); draw(); }
  else if (tool === "place") addPlace(p);
}
function onMove(ev) {
  if (!ed.drag) return;
  const p = toMap(ev);
  if (ed.tool === "brush") ed.draft.push(p); else ed.draft = [ed.draft[0], p];
  draw();
}
function onUp() {
  if (!ed.drag) return;
  ed.drag = false;
  const pts = ed.draft;
  ed.draft = [];
  const width = Number($("#ed-width").value);
  if (ed.tool === "brush") push({ op: "brush", points: pts, radius: width / 2, value: value() });
  else if (pts.length === 2) push({ op: "line", start: pts[0], end: pts[1], width, value: value() });
  else draw();
}
async function finishPolygon() {
  // a double click adds its point twice: drop repeated vertices before checking
  const pts = ed.draft.filter((p, i, a) => i === 0 || p[0] !== a[i - 1][0] || p[1] !== a[i - 1][1]);
  const problem = polygonProblem(pts);
  if (problem) { message(`polygon refused: ${problem}`, "err"); return; }
  ed.draft = [];
  if (ed.tool === "polygon") { push({ op: "polygon", polygon: pts, value: value() }); return; }
  const name = window.prompt(`Name of the ${ed.tool} zone`, ed.tool === "keepout" ? "keepout" : "slow");
  if (!name) { draw(); return; }
  const body = { name, kind: ed.tool, polygon: pts };
  if (ed.tool === "speed") body.speed_limit = Number(window.prompt("Speed limit, % of the top speed", "30")) || 30;
  try {
    const z = await api("POST", `/api/maps/${ed.map.id}/zones`, body);
    ed.zones.push(z);
    message(`zone "${z.name}" saved on map ${ed.map.id}`, "ok");
  } catch { /* shown */ }
  draw();
}
async function addPlace(p) {
  const name = window.prompt("Place name", "dock");
  if (!name) return;
  try {
    await api("POST", `/api/maps/${ed.map.id}/places`, { name, x: p[0], y: p[1], theta: 0 });
    message(`place "${name}" saved`, "ok");
  } catch { /* shown */ }
}

async function save(onSaved) {
  try {
    const v = await api("POST", `/api/maps/${ed.map.id}/versions`, { operations: ed.ops });
    message(`saved "${v.name}" (version ${v.version}, ${v.changed_cells} cells changed): activate it when ready`, "ok");
    close();
    onSaved(v);
  } catch { /* shown: nothing was lost, the edits stay */ }
}

function close() {
  $("#editor").hidden = true;
  ed = null;
}

/** Open the editor on map ``m``; ``onSaved(version)`` runs after a save. */
export async function openEditor(m, onSaved) {
  const image = new Image();
  image.src = `/api/maps/${m.id}/image.png`;
  await image.decode();
  let zones = [];
  try { zones = (await api("GET", `/api/maps/${m.id}/zones?limit=500`)).items; } catch { /* shown */ }
  const canvas = $("#ed-canvas");
  const scale = Math.max(1, Math.floor(Math.min(900 / m.width, 600 / m.height) * 4) / 4);
  canvas.width = Math.round(m.width * scale);
  canvas.height = Math.round(m.height * scale);
  ed = { map: m, image, canvas, scale, ops: [], undone: [], draft: [], tool: "brush", drag: false, zones };
  $("#ed-title").textContent = `Editing "${m.name}" (version ${m.version || 1})`;
  $("#editor").hidden = false;
  draw();
}

export function initEditor() {
  const canvas = $("#ed-canvas");
  canvas.addEventListener("mousedown", (ev) => ed && onDown(ev));
  canvas.addEventListener("mousemove", (ev) => ed && onMove(ev));
  window.addEventListener("mouseup", () => ed && onUp());
  canvas.addEventListener("dblclick", (ev) => { ev.preventDefault(); if (ed && ed.draft.length) finishPolygon(); });
  $("#ed-close-poly").addEventListener("click", () => ed && finishPolygon());
  $("#ed-undo").addEventListener("click", () => { if (ed && ed.ops.length) { ed.undone.push(ed.ops.pop()); draw(); } });
  $("#ed-redo").addEventListener("click", () => { if (ed && ed.undone.length) { ed.ops.push(ed.undone.pop()); draw(); } });
  $("#ed-cancel").addEventListener("click", close);
  $("#ed-tool").addEventListener("change", () => { if (ed) { ed.draft = []; ed.tool = $("#ed-tool").value; draw(); } });
  window.addEventListener("keydown", (ev) => {
    if (!ed || !(ev.ctrlKey || ev.metaKey)) return;
    if (ev.key === "z") { ev.preventDefault(); $(ev.shiftKey ? "#ed-redo" : "#ed-undo").click(); }
    if (ev.key === "y") { ev.preventDefault(); $("#ed-redo").click(); }
  });
  return (onSaved) => $("#ed-save").addEventListener("click", () => ed && save(onSaved));
}
