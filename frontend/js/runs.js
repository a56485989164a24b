// Runs page: list with filters and paging, detail with numbers, trajectory over the map, speed plot,
// event timeline (SVG drawn here, no libraries) and replay controls for the 3D view at /replay/viz/.
import { $, api, fmt, message, upload, wireEstop } from "./core.js";

const PAGE = 25;
const SVG = "http://www.w3.org/2000/svg";
const EVENT_COLORS = {
  mode: "#8a93a0", estop: "#e5484d", fault: "#e5484d", collision: "#ff6b00", goal: "#3d8bfd",
  goal_reached: "#30a46c", goal_failed: "#e5484d", goal_canceled: "#f5a524", plan_failed: "#f5a524",
  recovery: "#b07cff", behavior: "#b07cff",
};
const page = { offset: 0, total: 0, filters: {}, run: null, traj: null, replayTimer: null };

function el(tag, attrs = {}, parent = null) {
  const e = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (parent) parent.appendChild(e);
  return e;
}

function clear(node) { while (node.firstChild) node.removeChild(node.firstChild); }

// whole seconds are rounded before splitting: 239.7 s is "4 min 0 s", not "3 min 60 s"
const dur = (s) => (s === null || s === undefined ? "–" : s >= 59.95 ? `${Math.floor(Math.round(s) / 60)} min ${Math.round(s) % 60} s` : `${fmt(s, 1)} s`);
const when = (iso) => (iso ? new Date(iso).toLocaleString() : "–");

// ------------------------------------------------------------------------------------------ list
async function loadList() {
  const q = new URLSearchParams({ limit: PAGE, offset: page.offset });
  for (const [k, v] of Object.entries(page.filters)) if (v) q.set(k, v);
  let body;
  try { body = await api("GET", `/api/runs?${q}`); } catch { return; }
  page.total = body.total;
  const tbody = $("#runs-body");
  clear(tbody);
  if (!body.items.length) tbody.innerHTML = `<tr><td colspan="7" class="empty">no runs match</td></tr>`;
  for (const r of body.items) {
    const tr = document.createElement("tr");
    tr.className = "run";
    tr.tabIndex = 0;
    tr.dataset.id = r.id;
    const s = r.summary || {};
    const goals = r.kind === "navigation" ? `${s.goals_reached ?? 0} / ${s.goals_failed ?? 0}` : "";
    for (const text of [r.id, when(r.started_at), r.kind, null, dur(r.duration_s), `${fmt(r.distance_m, 1)} m`, goals]) {
      const td = document.createElement("td");
      if (text === null) {
        const b = document.createElement("span");
        b.className = `outcome ${r.outcome}`;
        b.textContent = r.outcome;
        td.appendChild(b);
      } else td.textContent = text;
      tr.appendChild(td);
    }
    tr.onclick = () => openRun(r.id);
    tr.onkeydown = (ev) => { if (ev.key === "Enter") openRun(r.id); };
    if (page.run && page.run.id === r.id) tr.classList.add("sel");
    tbody.appendChild(tr);
  }
  const last = Math.min(page.offset + PAGE, page.total);
  $("#page-info").textContent = page.total ? `${page.offset + 1}–${last} of ${page.total}` : "";
  $("#prev").disabled = page.offset === 0;
  $("#next").disabled = last >= page.total;
}

async function loadMaps() {
  try {
    const maps = (await api("GET", "/api/maps?limit=500")).items;
    const sel = $("#filters select[name=map_id]");
    for (const m of maps) {
      const o = document.createElement("option");
      o.value = m.id;
      o.textContent = `${m.name} (#${m.id})`;
      sel.appendChild(o);
    }
  } catch { /* the filter still works by id */ }
}

// ------------------------------------------------------------------------------------------ detail
async function openRun(id) {
  let run, traj;
  try {
    [run, traj] = await Promise.all([api("GET", `/api/runs/${id}`), api("GET", `/api/runs/${id}/trajectory?max_points=3000`)]);
  } catch { return; }
  page.run = run;
  page.traj = traj;
  for (const tr of document.querySelectorAll("tr.run")) tr.classList.toggle("sel", Number(tr.dataset.id) === id);
  $("#detail-empty").hidden = true;
  $("#detail-body").hidden = false;
  $("#detail-h").textContent = `Run #${run.id}`;
  $("#detail-title").innerHTML = "";
  const title = document.createElement("p");
  const robot = run.robot || run.profile_name ? ` · ${run.robot} (${run.profile_name})` : "";  // none for an imported bag
  title.textContent = `${run.kind} · ${when(run.started_at)} → ${when(run.ended_at)}${robot} · map ${run.map_id ?? "–"} · `;
  const b = document.createElement("span");
  b.className = `outcome ${run.outcome}`;
  b.textContent = run.outcome + (run.end_reason ? ` (${run.end_reason})` : "");
  title.appendChild(b);
  $("#detail-title").appendChild(title);
  renderImportNotes(run);
  renderNumbers(run);
  renderDownloads(run);
  renderTrajectory(traj, run);
  renderSpeed(traj, run);
  renderTimeline(run);
  resetReplay(run);
}

// A run imported from a bag says where it came from and what the reader chose (topics, typestore, mount).
function renderImportNotes(run) {
  const info = (run.summary || {}).imported;
  const ul = $("#import-notes");
  clear(ul);
  ul.hidden = !info;
  if (!info) return;
  const head = document.createElement("li");
  const slam = info.nodes === undefined ? "" : `, ${info.nodes} SLAM nodes, ${info.loop_closures} loop closures`;
  head.textContent = `imported from ${info.file}: ${info.scans} scans${slam}`;
  ul.appendChild(head);
  for (const n of info.notes || []) {
    const li = document.createElement("li");
    li.textContent = n;
    ul.appendChild(li);
  }
}

// ------------------------------------------------------------------------------------------ bag import
// Upload with a progress bar (bytes sent), then the server's progress (scans mapped) until the run exists.
const IMPORT_STATES = { queued: "queued", reading: "reading the bag", mapping: "mapping", storing: "storing the run" };

function initBagImport() {
  const form = $("#bag-form");
  const bar = $("#bag-progress");
  const status = $("#bag-status");
  form.addEventListener("submit", async (ev) => {
    ev.preventDefault();
    const file = $("#bag-file").files[0];
    if (!file) return;
    const fd = new FormData();
    fd.append("file", file);
    bar.hidden = false;
    bar.value = 0;
    $("#bag-submit").disabled = true;
    try {
      let job = await upload("/api/runs/import", fd, (f) => { bar.value = f; status.textContent = `uploading ${Math.round(f * 100)}%`; });
      while (job.state !== "done" && job.state !== "failed") {
        await new Promise((r) => setTimeout(r, 500));
        job = await api("GET", `/api/runs/import/${job.id}`);
        const frac = job.scans_total ? job.scans_done / job.scans_total : 0;
        bar.value = frac;
        status.textContent = job.state === "mapping"
          ? `mapping ${job.scans_done} / ${job.scans_total} scans`
          : IMPORT_STATES[job.state] || job.state;
      }
      if (job.state === "failed") {
        status.textContent = "failed";
        message(`import of ${job.file} failed: ${job.error}`, "error");
        return;
      }
      bar.value = 1;
      status.textContent = `run #${job.run_id}`;
      message(`imported ${job.file} as run #${job.run_id}`, "ok");
      form.reset();
      page.offset = 0;
      await loadList();
      await openRun(job.run_id);
    } catch { status.textContent = "failed"; } finally {
      $("#bag-submit").disabled = false;
    }
  });
}

function renderNumbers(run) {
  const s = run.summary || {};
  const items = [
    ["Duration", dur(s.duration_s ?? run.duration_s)], ["Distance", `${fmt(s.distance_m ?? run.distance_m, 2)} m`],
    ["Goals reached", s.goals_reached ?? 0], ["Goals failed", s.goals_failed ?? 0], ["Recoveries", s.recoveries ?? 0],
    ["E-stops", s.estops ?? 0], ["Faults", s.faults ?? 0], ["Collisions", s.collisions ?? 0],
    ["Mean speed", `${fmt(s.mean_speed, 2)} m/s`], ["Max speed", `${fmt(s.max_speed, 2)} m/s`],
    ["Closest obstacle", s.min_clearance_m === null || s.min_clearance_m === undefined ? "–" : `${fmt(s.min_clearance_m, 2)} m`],
    ["Plan failures", s.plan_failures ?? 0], ["Samples", s.samples ?? 0], ["Scans", run.scans ?? 0],
  ];
  const dl = $("#nums");
  clear(dl);
  for (const [k, v] of items) {
    const d = document.createElement("div");
    const dt = document.createElement("dt"); dt.textContent = k;
    const dd = document.createElement("dd"); dd.textContent = v;
    d.append(dt, dd);
    dl.appendChild(d);
  }
}

function renderDownloads(run) {
  const p = $("#downloads");
  clear(p);
  if (run.outcome === "recording") {
    // exported as recorded so far (the response says X-Run-Partial: true); again when it has ended
    const note = document.createElement("span");
    note.textContent = "Still recording: a download holds the run so far (partial). ";
    p.appendChild(note);
  }
  for (const [fmtName, label] of [["mcap", "MCAP (Foxglove)"], ["json", "JSON"], ["csv", "CSV"]]) {
    const a = document.createElement("a");
    a.href = `/api/runs/${run.id}/export.${fmtName}`;
    a.textContent = `⬇ ${label}`;
    a.setAttribute("download", "");
    p.appendChild(a);
  }
}

/** World (x, y) -> SVG pixel (map image: top row first, REP-103 y up). */
function mapTransform(map, samples) {
  if (map) {
    const [ox, oy] = map.origin;
    return { w: map.width, h: map.height, f: (x, y) => [(x - ox) / map.resolution, map.height - (y - oy) / map.resolution] };
  }
  const xs = samples.x, ys = samples.y;
  const minx = Math.min(...xs) - 1, maxx = Math.max(...xs) + 1, miny = Math.min(...ys) - 1, maxy = Math.max(...ys) + 1;
  const k = 400 / Math.max(maxx - minx, maxy - miny, 1e-3);
  return { w: (maxx - minx) * k, h: (maxy - miny) * k, f: (x, y) => [(x - minx) * k, (maxy - y) * k] };
}

function renderTrajectory(traj, run) {
  const svg = $("#traj");
  clear(svg);
  const s = traj.samples;
  if (!s.t.length) { el("text", { x: 10, y: 20, fill: "#8a93a0" }, svg).textContent = "no samples"; return; }
  const tf = mapTransform(traj.map, s);
  svg.setAttribute("viewBox", `0 0 ${tf.w} ${tf.h}`);
  svg.style.aspectRatio = `${tf.w} / ${tf.h}`;
  if (traj.map) el("image", { href: traj.map.image_url, x: 0, y: 0, width: tf.w, height: tf.h, style: "image-rendering:pixelated" }, svg);
  const scale = traj.map ? Math.max(tf.w, tf.h) / 400 : 1;
  const pts = s.x.map((x, i) => tf.f(x, s.y[i]).map((v) => v.toFixed(1)).join(",")).join(" ");
  el("polyline", { points: pts, fill: "none", stroke: "#3d8bfd", "stroke-width": 2 * scale, "stroke-linejoin": "round" }, svg);
  const [sx, sy] = tf.f(s.x[0], s.y[0]);
  const [ex, ey] = tf.f(s.x[s.x.length - 1], s.y[s.y.length - 1]);
  el("circle", { cx: sx, cy: sy, r: 4 * scale, fill: "#30a46c" }, svg).appendChild(document.createElementNS(SVG, "title")).textContent = "start";
  el("circle", { cx: ex, cy: ey, r: 4 * scale, fill: "#e5484d" }, svg).appendChild(document.createElementNS(SVG, "title")).textContent = "end";
  for (const g of run.goals || []) {
    const [gx, gy] = tf.f(g.x, g.y);
    const color = g.outcome === "succeeded" ? "#30a46c" : g.outcome === "failed" ? "#e5484d" : "#f5a524";
    el("path", { d: `M${gx - 5 * scale},${gy - 5 * scale}L${gx + 5 * scale},${gy + 5 * scale}M${gx + 5 * scale},${gy - 5 * scale}L${gx - 5 * scale},${gy + 5 * scale}`, stroke: color, "stroke-width": 2.5 * scale }, svg)
      .appendChild(document.createElementNS(SVG, "title")).textContent = `goal at ${fmt(g.t, 1)} s: ${g.outcome}`;
  }
  page.robotMark = el("circle", { r: 5 * scale, fill: "none", stroke: "#ffd60a", "stroke-width": 2 * scale, visibility: "hidden" }, svg);
  page.tf = tf;
}

function renderSpeed(traj, run) {
  const svg = $("#speed");
  clear(svg);
  const s = traj.samples;
  const W = 600, H = 150, L = 40, B = 20;
  svg.setAttribute("viewBox", `0 0 ${W} ${H}`);
  if (!s.t.length) return;
  const T = Math.max(s.t[s.t.length - 1], 1e-3);
  const speed = s.vx.map((v, i) => Math.hypot(v ?? 0, s.vy[i] ?? 0));
  const cmd = s.cmd_vx.map((v, i) => Math.hypot(v ?? 0, s.cmd_vy[i] ?? 0));
  const vmax = Math.max(0.1, ...speed, ...cmd) * 1.1;
  const X = (t) => L + (t / T) * (W - L - 5), Y = (v) => H - B - (v / vmax) * (H - B - 5);
  for (const frac of [0, 0.5, 1]) {
    el("line", { x1: L, x2: W - 5, y1: Y(vmax * frac / 1.1), y2: Y(vmax * frac / 1.1), stroke: "#2a2f38" }, svg);
    el("text", { x: 2, y: Y(vmax * frac / 1.1) + 4, fill: "#8a93a0", "font-size": 10 }, svg).textContent = `${fmt(vmax * frac / 1.1, 2)}`;
  }
  el("text", { x: W - 60, y: H - 4, fill: "#8a93a0", "font-size": 10 }, svg).textContent = `${fmt(T, 0)} s`;
  el("text", { x: L, y: H - 4, fill: "#8a93a0", "font-size": 10 }, svg).textContent = "m/s · blue measured, grey command";
  const line = (vals, color) => el("polyline", { points: vals.map((v, i) => `${X(s.t[i]).toFixed(1)},${Y(v).toFixed(1)}`).join(" "), fill: "none", stroke: color, "stroke-width": 1.5 }, svg);
  line(cmd, "#5b6370");
  line(speed, "#3d8bfd");
  page.speedCursor = el("line", { x1: 0, x2: 0, y1: 0, y2: H - B, stroke: "#ffd60a", visibility: "hidden" }, svg);
  page.speedX = X;
}

function renderTimeline(run) {
  const svg = $("#timeline");
  clear(svg);
  const W = 600, H = 70;
  svg.setAttribute("viewBox", `0 0 ${W} ${H}`);
  const T = Math.max(run.summary?.duration_s || run.duration_s || 1, 1e-3);
  const X = (t) => 10 + (t / T) * (W - 20);
  el("line", { x1: 10, x2: W - 10, y1: 35, y2: 35, stroke: "#3a414d" }, svg);
  const rows = { mode: 15, behavior: 55, recovery: 55 };
  const list = $("#event-list");
  clear(list);
  const seen = new Set();
  for (const ev of run.events) {
    const color = EVENT_COLORS[ev.type] || "#e6e8eb";
    const y = rows[ev.type] ?? 35;
    const mark = el("circle", { cx: X(ev.t), cy: y, r: 5, fill: color }, svg);
    const detail = ev.type === "mode" ? `${ev.from} → ${ev.to}` : Object.entries(ev).filter(([k]) => k !== "t" && k !== "type").map(([k, v]) => `${k}: ${JSON.stringify(v)}`).join(", ");
    mark.appendChild(document.createElementNS(SVG, "title")).textContent = `${fmt(ev.t, 2)} s ${ev.type} ${detail}`;
    seen.add(ev.type);
    const li = document.createElement("li");
    li.textContent = `${fmt(ev.t, 2)} s  ${ev.type}  ${detail}`;
    if (["estop", "fault", "collision", "goal_failed", "plan_failed"].includes(ev.type)) li.className = "error";
    if (ev.type === "goal_reached") li.className = "ok";
    list.appendChild(li);
  }
  const legend = $("#legend");
  clear(legend);
  for (const t of seen) {
    const sp = document.createElement("span");
    sp.innerHTML = `<b style="color:${EVENT_COLORS[t] || "#e6e8eb"}">●</b> `;
    sp.appendChild(document.createTextNode(t));
    legend.appendChild(sp);
  }
}

// ------------------------------------------------------------------------------------------ replay
function resetReplay(run) {
  stopPolling();
  $("#replay-view").hidden = true;
  $("#replay-frame").src = "about:blank";
  for (const id of ["#replay-play", "#replay-pause", "#replay-slider"]) $(id).disabled = true;
  const T = run.summary?.duration_s || run.duration_s || 0;
  $("#replay-slider").max = T;
  $("#replay-slider").value = 0;
  $("#replay-t").textContent = `0 / ${fmt(T, 1)} s`;
  if (page.robotMark) page.robotMark.setAttribute("visibility", "hidden");
}

function showReplay(st) {
  $("#replay-slider").max = st.duration;
  if (document.activeElement !== $("#replay-slider")) $("#replay-slider").value = st.t;
  $("#replay-t").textContent = `${fmt(st.t, 1)} / ${fmt(st.duration, 1)} s`;
  const s = page.traj?.samples;
  if (s && s.t.length && page.tf) {
    let i = s.t.findIndex((t) => t > st.t);
    i = i < 0 ? s.t.length - 1 : Math.max(0, i - 1);
    const [x, y] = page.tf.f(s.x[i], s.y[i]);
    page.robotMark.setAttribute("cx", x);
    page.robotMark.setAttribute("cy", y);
    page.robotMark.setAttribute("visibility", "visible");
  }
  if (page.speedCursor) {
    const x = page.speedX(st.t);
    page.speedCursor.setAttribute("x1", x);
    page.speedCursor.setAttribute("x2", x);
    page.speedCursor.setAttribute("visibility", "visible");
  }
  if (!st.playing) stopPolling();
}

function stopPolling() { if (page.replayTimer) clearInterval(page.replayTimer); page.replayTimer = null; }

function startPolling() {
  stopPolling();
  page.replayTimer = setInterval(async () => {
    try { showReplay(await api("GET", "/api/replay")); } catch { stopPolling(); }
  }, 200);
}

async function replay(body) {
  try {
    const st = await api("POST", "/api/replay", body);
    showReplay(st);
    return st;
  } catch { return null; }
}

function initReplay() {
  $("#replay-load").onclick = async () => {
    if (!page.run) return;
    const st = await replay({ action: "load", run_id: page.run.id });
    if (!st) return;
    for (const id of ["#replay-play", "#replay-pause", "#replay-slider"]) $(id).disabled = false;
    if (st.viewer) {
      $("#replay-view").hidden = false;
      $("#replay-frame").src = "/replay/viz/"; // live view is not shown on this page: this client sees the replay
    } else message("the server runs without a 3D view: replay shows on the trajectory plot only");
    await replay({ action: "speed", speed: Number($("#replay-speed").value) });
  };
  $("#replay-play").onclick = async () => { if (await replay({ action: "play" })) startPolling(); };
  $("#replay-pause").onclick = () => replay({ action: "pause" });
  $("#replay-speed").onchange = () => replay({ action: "speed", speed: Number($("#replay-speed").value) });
  $("#replay-slider").oninput = () => replay({ action: "seek", t: Number($("#replay-slider").value) });
}

// ------------------------------------------------------------------------------------------ init
function init() {
  wireEstop();
  $("#filters").onsubmit = (ev) => {
    ev.preventDefault();
    page.filters = Object.fromEntries(new FormData($("#filters")).entries());
    page.offset = 0;
    loadList();
  };
  $("#prev").onclick = () => { page.offset = Math.max(0, page.offset - PAGE); loadList(); };
  $("#next").onclick = () => { page.offset += PAGE; loadList(); };
  $("#delete-run").onclick = async () => {
    if (!page.run || !confirm(`Delete run #${page.run.id} and all its data?`)) return;
    try { await fetch(`/api/runs/${page.run.id}`, { method: "DELETE" }).then((r) => { if (!r.ok) throw new Error(r.statusText); }); } catch (err) { message(`delete failed: ${err.message}`, "error"); return; }
    message(`run #${page.run.id} deleted`, "ok");
    page.run = null;
    $("#detail-body").hidden = true;
    $("#detail-empty").hidden = false;
    loadList();
  };
  initReplay();
  initBagImport();
  loadMaps();
  loadList();
  const wanted = Number(new URLSearchParams(location.search).get("run"));
  if (wanted) openRun(wanted);
}

init();
