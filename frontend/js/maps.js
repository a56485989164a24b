// Maps page: gallery with thumbnails; open in the 3D view (activate), rename, delete, set active;
// import a map_server YAML + image with upload progress; export as map.yaml + map.pgm; edit (editor.js).
import { $, api, loadMe, message, upload, wireEstop } from "./core.js";
import { initEditor, openEditor } from "./editor.js";

let activeId = null;

function button(label, aria, fn, cls = "btn small") {
  const b = document.createElement("button");
  b.className = cls;
  b.textContent = label;
  b.setAttribute("aria-label", aria);
  b.addEventListener("click", fn);
  return b;
}

function link(label, href, aria) {
  const a = document.createElement("a");
  a.textContent = label;
  a.href = href;
  a.setAttribute("download", "");
  a.setAttribute("aria-label", aria);
  return a;
}

async function activate(m, open) {
  try {
    await api("POST", `/api/maps/${m.id}/activate`);
    message(`"${m.name}" is the active map`, "ok");
    if (open) location.assign("/");
    else await refresh();
  } catch { /* shown */ }
}

function card(m) {
  const li = document.createElement("li");
  li.className = `card${m.id === activeId || m.active ? " active" : ""}`;
  li.dataset.mapId = m.id;
  const img = document.createElement("img");
  img.src = m.thumbnail_url || `/api/maps/${m.id}/thumbnail.png`;
  img.alt = `thumbnail of map ${m.name}`;
  img.loading = "lazy";
  const h = document.createElement("h3");
  h.textContent = m.name;
  if (m.id === activeId || m.active) { const t = document.createElement("span"); t.className = "tag on"; t.textContent = "active"; h.append(" ", t); }
  if (m.version > 1) { const t = document.createElement("span"); t.className = "tag"; t.textContent = `v${m.version}`; h.append(" ", t); }
  if (m.is_stock) { const t = document.createElement("span"); t.className = "tag"; t.textContent = "stock"; h.append(" ", t); }
  const meta = document.createElement("div");
  meta.className = "meta";
  const size = m.size_m ? `${m.size_m[0]} × ${m.size_m[1]} m` : "";
  meta.textContent = `${size} · ${m.resolution} m/cell · ${m.source}${m.created_at ? " · " + m.created_at.slice(0, 16).replace("T", " ") : ""}`;
  const actions = document.createElement("div");
  actions.className = "actions";
  actions.append(
    button("Open in 3D", `open ${m.name} in the 3D view`, () => activate(m, true)),
    button("Set active", `make ${m.name} the active map`, () => activate(m, false)),
    button("Edit", `edit ${m.name}: walls, erasing, zones, places`, () => openEditor(m, refresh)),
  );
  if (!m.is_stock) {
    actions.append(
      button("Rename", `rename ${m.name}`, async () => {
        const name = window.prompt("New name", m.name);
        if (name === null || !name.trim() || name.trim() === m.name) return;
        try { await api("PATCH", `/api/maps/${m.id}`, { name: name.trim() }); message(`renamed to "${name.trim()}"`, "ok"); await refresh(); } catch { /* shown */ }
      }),
      button("Delete", `delete ${m.name}`, async () => {
        if (!window.confirm(`Delete map "${m.name}"? This cannot be undone.`)) return;
        try { await api("DELETE", `/api/maps/${m.id}`); message(`deleted "${m.name}"`, "ok"); await refresh(); } catch { /* shown */ }
      }, "btn small danger"),
    );
  }
  actions.append(
    link("map.yaml", `/api/maps/${m.id}/map.yaml`, `download ${m.name} map.yaml`),
    link("map.pgm", `/api/maps/${m.id}/map.pgm`, `download ${m.name} map.pgm`),
  );
  li.append(img, h, meta, actions);
  return li;
}

async function refresh() {
  let maps = [];
  try {
    const page = await api("GET", "/api/maps?limit=500"); // {total, limit, offset, items, active_map_id}
    maps = page.items;
    activeId = page.active_map_id;
  } catch { return; }
  $("#gallery").replaceChildren(...maps.map(card));
  if (!maps.length) $("#gallery").textContent = "No maps yet: start mapping on the Live page, or import one.";
}

function initImport() {
  const form = $("#import-form");
  const bar = $("#import-progress");
  const pct = $("#import-pct");
  form.addEventListener("submit", async (ev) => {
    ev.preventDefault();
    const fd = new FormData();
    fd.append("yaml", $("#import-yaml").files[0]);
    fd.append("image", $("#import-image").files[0]);
    if ($("#import-name").value.trim()) fd.append("name", $("#import-name").value.trim());
    bar.hidden = false;
    bar.value = 0;
    $("#import-submit").disabled = true;
    try {
      const res = await upload("/api/maps/import", fd, (f) => { bar.value = f; pct.textContent = `${Math.round(f * 100)}%`; });
      message(`imported "${(res && res.name) || "map"}"`, "ok");
      form.reset();
      await refresh();
    } catch { pct.textContent = "failed"; } finally {
      $("#import-submit").disabled = false;
    }
  });
}

async function init() {
  await loadMe();
  wireEstop();
  initImport();
  initEditor()(refresh);
  await refresh();
}

init();
