"""The 3D view (the Rviz2 replacement): session snapshots in, viser scene updates out.

One ``Viewer`` owns one ``viser.ViserServer`` bound to 127.0.0.1 on an ephemeral port (the dashboard
relays it, see ``relay.py``). Two daemon threads subscribe to the ``SnapshotBus``, each through its own
one-slot mailbox so neither can slow the control loop:

* the *scene* thread updates the robot pose (one ``atomic()`` step), scan, trail, plans, goal,
  particles, graph edges and the status line at <= ``rate_hz`` (Rviz redraws at about this rate);
* the *grid* thread re-tiles the occupancy map and the costmap overlay at <= ``map_rate_hz``, because
  PNG encoding is the one expensive step and must not stall pose updates.

Every node has a stable name and is created once; optional layers are hidden, never removed, when the
snapshot has no data for them (viser keeps tombstones for removed nodes, see viser.md §8).
Pointer input follows Rviz2's tools: a click sets a position, Shift+drag on the map sets position and
heading; both end in ``on_pose_input(kind, pose, tab)``, which must only enqueue and returns why it
refused, if it did. Layer checkboxes and the click mode belong to each browser tab (``tabs.py``); an
initial pose is a one-shot tool, as in Rviz2: once one is set, that tab's clicks set goals again.
"""

from __future__ import annotations

import contextlib
import dataclasses
import html
import logging
import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import rich
import viser

from app.bus import Snapshot, SnapshotBus, Subscription
from app.viewer import geometry as geo
from app.viewer import loop_safe, palette
from app.viewer.pose_input import (
    PoseInputError,
    ground_through,
    heading_towards,
    pose_from_press_drag,
    ray_ground,
)
from app.viewer.tabs import (
    DEFAULT_TAB,
    ClientView,
    TabRegistry,
    send_visibility,
    tab_of_connection,
)
from app.viewer.tiles import TiledGridLayer, TileOptions
from nav.types import Costmap, Pose2D, wrap_angle

log = logging.getLogger(__name__)

PoseInputCallback = Callable[[str, Pose2D, str], "str | None"]
"""(kind, pose, tab token) -> the reason it was refused, or None when it was taken."""
POSE_KINDS = {"goal": "goal", "goal in unknown space": "goal_unknown", "initial pose": "initial_pose"}
KIND_LABELS = {kind: label for label, kind in POSE_KINDS.items()}

HIDDEN_BY_DEFAULT = frozenset({"/costmap"})

# Toggleable layers: checkbox label -> scene node it drives.
LAYERS: dict[str, str] = {
    "Map": "/map",
    "Costmap": "/costmap",
    "Scan": "/scan",
    "Trail": "/trail",
    "Global path": "/plan/global",
    "Local trajectories": "/plan/local",
    "Goal & waypoints": "/goal",
    "Particles": "/particles",
    "Loop closures": "/graph/edges",
    "People": "/people",
    "Recoveries": "/recoveries",
    "TEB band": "/plan/teb",
    "Zones": "/zones",
    "Frontiers": "/frontiers",
}

MAX_RECOVERY_LABELS = 24
MAX_ZONE_LABELS = 64
"""Zones beyond this many keep their outline but get no label."""
ZONE_KINDS = {"keepout": palette.KEEPOUT_ZONE, "speed": palette.SPEED_ZONE}
"""Recovery markers beyond this many (in one navigation) keep their marker but get no label."""


@contextlib.contextmanager
def quiet_viser() -> Iterator[None]:
    """Silence viser's console output (rich's shared console, whichever thread prints)."""
    console = rich.get_console()
    was = console.quiet
    console.quiet = True
    try:
        yield
    finally:
        console.quiet = was


def behavior_badge_html(name: str | None) -> str:
    """The panel's behaviour badge: the name on its colour (escaped: names come from config)."""
    text = html.escape(name or "")
    bg = palette.hex_color(palette.behavior_color(name))
    return (
        f'<div style="display:inline-block;padding:2px 10px;border-radius:10px;background:{bg};'
        f'color:#111;font-weight:600" data-behavior="{text}">{text}</div>'
    )


@dataclass(frozen=True)
class ViewerOptions:
    """Display settings (Rviz display defaults where one exists)."""

    rate_hz: float = 15.0
    """Maximum scene update rate for pose, scan, plans (Hz)."""
    map_rate_hz: float = 2.0
    """Maximum map / costmap re-tiling rate (Hz); slam_toolbox publishes its map at 0.2..1 Hz."""
    status_rate_hz: float = 5.0
    """Status line refresh rate (Hz)."""
    map_tiles: TileOptions = field(default_factory=TileOptions)
    """Tiling of the occupancy grid."""
    costmap_tiles: TileOptions = field(default_factory=lambda: TileOptions(upsample=2, z=0.005))
    """Tiling of the costmap overlay (floats 5 mm above the map, no z-fighting)."""
    map_alpha: float = 0.7
    """Rviz Map display alpha (baked against Rviz's background, see palette.map_palette)."""
    costmap_alpha: float = 0.7
    """Rviz costmap colour scheme alpha."""
    scan_point_size: float = 0.04
    """Scan point size in metres (Rviz LaserScan "Size (m)" default 0.01 is too small for a browser)."""
    scan_height: float = 0.02
    """Scan points drawn this high above the ground so they are not hidden by the map."""
    path_thickness_px: float = 3.0
    """Line thickness of plans and trail in screen pixels."""
    particle_arrow_length: float = 0.15
    """AMCL particle arrow length in metres."""
    max_particles: int = 4000
    """Particles beyond this are subsampled for display."""
    max_local_samples: int = 400
    """Local trajectory samples beyond this are subsampled for display."""
    behavior_ring_margin: float = 0.1
    """The behaviour ring's radius beyond the footprint's circumscribed radius (m)."""
    recovery_marker_radius: float = 0.15
    """Half-size of a recovery marker's diamond (m)."""
    teb_arrow_length: float = 0.12
    """Length of a TEB band pose arrow (m)."""


@dataclass
class ViewerStats:
    """Counters a test, benchmark or health page can read."""

    updates: int = 0
    grid_updates: int = 0
    last_update_s: float = 0.0
    errors: int = 0


class Viewer:
    """viser scene fed by a ``SnapshotBus``. ``start()`` binds the server, ``stop()`` frees it."""

    def __init__(
        self,
        bus: SnapshotBus,
        rate_hz: float = 15.0,
        *,
        footprint: np.ndarray | None = None,
        options: ViewerOptions | None = None,
        on_pose_input: PoseInputCallback | None = None,
    ) -> None:
        opts = options or ViewerOptions()
        if rate_hz != opts.rate_hz:
            opts = dataclasses.replace(opts, rate_hz=rate_hz)
        if opts.rate_hz <= 0.0 or opts.map_rate_hz <= 0.0:
            raise ValueError("viewer rates must be positive")
        self.options = opts
        self.bus = bus
        self.on_pose_input: PoseInputCallback | None = on_pose_input
        self.stats = ViewerStats()
        self._footprint = None if footprint is None else np.asarray(footprint, dtype=float).reshape(-1, 2)
        self._server: viser.ViserServer | None = None
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._subs: list[Subscription] = []
        self._h: dict[str, Any] = {}  # scene handles by node name
        self._has_data: dict[str, bool] = {}
        self.tabs = TabRegistry({node: node not in HIDDEN_BY_DEFAULT for node in LAYERS.values()})
        self._last: dict[str, Any] = {}  # identity of the last data drawn per layer
        self._pose = Pose2D()
        self._aimed_at: Any = None  # map geometry the initial camera (and "Reset View") looks at
        self._status_due = 0.0

    # ---------------------------------------------------------------- lifecycle
    @property
    def server(self) -> viser.ViserServer:
        if self._server is None:
            raise RuntimeError("viewer not started")
        return self._server

    @property
    def port(self) -> int:
        return self.server.get_port()

    @property
    def running(self) -> bool:
        return self._server is not None

    def start(self) -> None:
        """Bind viser on 127.0.0.1 (ephemeral port), build the scene and GUI, start both threads."""
        if self._server is not None:
            return
        # viser prints a panel with its own port even when not verbose; users open the dashboard's
        # address (the relay), so that port must not look like one to open
        loop_safe.install()  # viser's buffers must survive pushes from our threads (loop_safe.py)
        with quiet_viser():
            self._server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
        self._last.clear()  # a restarted server has an empty scene: redraw everything
        self._aimed_at = None
        self._build_scene()
        self._build_gui()
        self._stop.clear()
        for target, name in ((self._scene_loop, "viewer-scene"), (self._grid_loop, "viewer-grid")):
            sub = self.bus.subscribe()
            self._subs.append(sub)
            t = threading.Thread(target=target, args=(sub,), name=name, daemon=True)
            self._threads.append(t)
            t.start()

    def stop(self) -> None:
        """Stop the threads, leave the bus and free the port. Safe to call twice."""
        self._stop.set()
        for sub in self._subs:
            sub.close()
        for t in self._threads:
            t.join(timeout=5.0)
        self._threads.clear()
        self._subs.clear()
        if self._server is not None:
            self.map_layer.close()
            self.costmap_layer.close()
            with quiet_viser():  # viser's "Server stopped" line (printed on its own thread)
                self._server.stop()
            self._server = None

    def __enter__(self) -> Viewer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ---------------------------------------------------------------- scene
    def _build_scene(self) -> None:
        s = self.server.scene
        o = self.options
        s.set_up_direction("+z")
        # A top-down navigation view needs neither image-based lighting nor shadows. viser's client
        # defaults to both (an HDRI environment, pre-filtered with PMREM, and cascaded shadow maps), and
        # each adds shader programs and render passes before the first frame: seconds under software
        # WebGL (bench dashboard.browser). The two default directional lights still shade the robot.
        s.configure_environment_map(hdri=None)
        s.configure_default_lights(enabled=True, cast_shadow=False)
        self.server.initial_camera.position = (-4.0, -6.0, 8.0)
        self.server.initial_camera.look_at = (0.0, 0.0, 0.0)
        self.map_layer = TiledGridLayer(
            self.server, "/map", palette.map_palette(o.map_alpha), o.map_tiles, self._bind_tile_drag
        )
        self.costmap_layer = TiledGridLayer(
            self.server, "/costmap", palette.costmap_palette(o.costmap_alpha), o.costmap_tiles
        )
        h = self._h
        h["/robot"] = s.add_frame("/robot", show_axes=False)
        h["/robot/footprint"] = s.add_line_segments(
            "/robot/footprint",
            np.zeros((0, 2, 3), np.float32),
            palette.FOOTPRINT,
            thickness=o.path_thickness_px,
            thickness_units="screen",
        )
        # An arrow drawn with lines, not a mesh: lines share one shader program with every other line
        # layer, a mesh arrow needs a PBR program compiled at page load (seconds under software WebGL).
        h["/robot/heading"] = s.add_line_segments(
            "/robot/heading",
            np.array(
                [
                    [[0.0, 0.0, 0.03], [0.25, 0.0, 0.03]],
                    [[0.25, 0.0, 0.03], [0.18, 0.05, 0.03]],
                    [[0.25, 0.0, 0.03], [0.18, -0.05, 0.03]],
                ],
                np.float32,
            ),
            palette.HEADING,
            thickness=4.0,
            thickness_units="screen",
        )
        # The scan is drawn in the map frame (Rviz's fixed frame), not under /robot: viser's browser
        # applies a node's pose at once but new points through a React re-render, which a busy browser
        # runs seconds late; a late scan under /robot turned with the robot, off the walls it had seen.
        h["/scan"] = s.add_frame("/scan", show_axes=False)
        for i, (_edge, rgb) in enumerate(palette.SCAN_BANDS):
            h[f"/scan/band_{i}"] = s.add_point_cloud(
                f"/scan/band_{i}",
                np.zeros((0, 3), np.float32),
                rgb,  # set once: a changed colour array costs a shader recompile in the browser
                point_size=o.scan_point_size,
                point_shape="circle",
                precision="float32",
            )
        h["/robot/label"] = s.add_label("/robot/label", "", position=(0.0, 0.0, 0.35), visible=False)
        h["/robot/behavior"] = s.add_line_segments(
            "/robot/behavior",
            geo.circle_segments(0.3, 0.015),
            palette.UNKNOWN_BEHAVIOR,
            thickness=4.0,
            thickness_units="screen",
            visible=False,
        )
        h["/trail"] = self._lines("/trail", palette.TRAIL)
        h["/plan"] = s.add_frame("/plan", show_axes=False)
        h["/plan/global"] = self._lines("/plan/global", palette.GLOBAL_PLAN)
        h["/plan/local"] = s.add_frame("/plan/local", show_axes=False)
        h["/plan/local/samples"] = self._lines("/plan/local/samples", palette.LOCAL_SAMPLES, 1.0)
        h["/plan/local/best"] = self._lines("/plan/local/best", palette.LOCAL_BEST)
        h["/goal"] = s.add_frame("/goal", axes_length=0.3, axes_radius=0.015, visible=False)
        h["/goal/waypoints"] = s.add_point_cloud(
            "/goal/waypoints",
            np.zeros((0, 3), np.float32),
            np.array(palette.WAYPOINTS, np.uint8),
            point_size=0.12,
            point_shape="diamond",
            precision="float32",
        )
        h["/particles"] = self._lines("/particles", palette.PARTICLES, 1.5)  # Rviz's flat arrows, as lines
        h["/people"] = self._lines("/people", palette.PEOPLE, 2.5)
        h["/recoveries"] = s.add_frame("/recoveries", show_axes=False, visible=False)
        h["/recoveries/markers"] = self._lines("/recoveries/markers", palette.UNKNOWN_BEHAVIOR, 3.0)
        h["/recoveries/markers"].visible = True  # the parent frame's visibility toggles the layer
        h["/plan/teb"] = s.add_frame("/plan/teb", show_axes=False, visible=False)
        h["/plan/teb/band"] = self._lines("/plan/teb/band", palette.TEB_BAND, 2.0)
        h["/plan/teb/band"].visible = True
        h["/plan/teb/poses"] = self._lines("/plan/teb/poses", palette.TEB_BAND, 2.0)  # arrows as lines
        h["/plan/teb/poses"].visible = True
        h["/zones"] = s.add_frame("/zones", show_axes=False, visible=False)
        for kind, rgb in ZONE_KINDS.items():  # one node per kind: a colour set once, never re-sent
            h[f"/zones/{kind}"] = self._lines(f"/zones/{kind}", rgb, 3.0)
            h[f"/zones/{kind}"].visible = True  # the parent frame's visibility toggles the layer
        h["/frontiers"] = s.add_frame("/frontiers", show_axes=False, visible=False)
        h["/frontiers/cells"] = s.add_point_cloud(
            "/frontiers/cells",
            np.zeros((0, 3), np.float32),
            np.array(palette.FRONTIERS, np.uint8),
            point_size=0.06,
            point_shape="square",
            precision="float32",  # map coordinates: float16 steps 3 cm at 50 m (viser.md)
        )
        h["/frontiers/goal"] = s.add_point_cloud(
            "/frontiers/goal",
            np.zeros((0, 3), np.float32),
            np.array(palette.FRONTIER_GOAL, np.uint8),
            point_size=0.2,
            point_shape="diamond",
            precision="float32",
        )
        h["/graph"] = s.add_frame("/graph", show_axes=False)
        h["/graph/edges"] = self._lines("/graph/edges", palette.GRAPH_EDGES, 2.0)
        h["/input/preview"] = s.add_arrows(
            "/input/preview",
            np.zeros((1, 2, 3), np.float32),
            palette.PREVIEW,
            shaft_radius=0.02,
            head_radius=0.06,
            head_length=0.12,
            visible=False,
        )
        h["/map"] = self.map_layer.root
        h["/costmap"] = self.costmap_layer.root
        self._has_data = {name: False for name in LAYERS.values()}
        self._has_data["/scan"] = True  # shown empty until a scan arrives
        # Like Rviz's default displays: the costmap overlay starts hidden (its checkbox starts off) so
        # the map stays readable. Layer visibility is sent to each client for its tab (tabs.py); the
        # shared nodes start hidden so a page shows nothing it has not been told to.
        for node in LAYERS.values():
            self._h[node].visible = False
        s.on_click()(self._on_scene_click)

    def _lines(self, name: str, color: tuple[int, int, int], px: float | None = None) -> Any:
        return self.server.scene.add_line_segments(
            name,
            np.zeros((0, 2, 3), np.float32),
            color,
            thickness=self.options.path_thickness_px if px is None else px,
            thickness_units="screen",
            visible=False,
        )

    def _build_gui(self) -> None:
        gui = self.server.gui
        gui.configure_theme(
            dark_mode=True,
            show_logo=False,
            show_share_button=False,
            brand_color=(40, 120, 255),
        )
        gui.set_panel_label("navdeck")
        self.status = gui.add_markdown("**waiting for the robot…**")
        self.behavior_badge = gui.add_html(behavior_badge_html(None), visible=False)
        # The folders are shared; what is in them is built for each client (its tab's state).
        self._pose_folder = gui.add_folder("Pose input")
        with self._pose_folder:
            gui.add_markdown("Click: position. **Shift+drag** on the map: position and heading.")
        self._layers_folder = gui.add_folder("Layers")
        self.server.on_client_connect(self._on_client_connect)
        self.server.on_client_disconnect(self._on_client_disconnect)

    # ---------------------------------------------------------------- per-tab view state
    def _on_client_connect(self, client: viser.ClientHandle) -> None:
        """Build this client's click-mode dropdown and layer checkboxes from its tab's state, then
        show it the layers that tab has on."""
        token = tab_of_connection(self.server, client.client_id) or f"client-{client.client_id}"
        tab = self.tabs.tab(token)
        view = ClientView(client, token)
        with self._pose_folder:
            view.click_mode = client.gui.add_dropdown(
                "Click sets", tuple(POSE_KINDS), initial_value=KIND_LABELS.get(tab.kind, "goal")
            )
        view.click_mode.on_update(lambda ev: self._on_click_mode(token, ev))
        with self._layers_folder:
            for label, node in LAYERS.items():
                cb = client.gui.add_checkbox(label, tab.layers[node])
                cb.on_update(lambda ev, node=node: self._on_layer_check(token, node, ev))
                view.checks[node] = cb
        with self.tabs.lock:
            self.tabs.clients[client.client_id] = view
        for node in LAYERS.values():
            self._refresh_client(view, node)

    def _on_client_disconnect(self, client: viser.ClientHandle) -> None:
        with self.tabs.lock:
            self.tabs.clients.pop(client.client_id, None)

    def _on_click_mode(self, token: str, event: Any) -> None:
        if event.client_id is None:  # our own assignment (set_click_kind) echoing back
            return
        self.set_click_kind(token, POSE_KINDS.get(str(event.target.value), "goal"))

    def _on_layer_check(self, token: str, node: str, event: Any) -> None:
        if event.client_id is None:
            return
        self._set_node_enabled(node, bool(event.target.value), token)

    def _refresh_client(self, view: ClientView, node: str) -> None:
        """Show a layer to one client iff its tab has the checkbox on and the latest snapshot had data."""
        with self.tabs.lock:
            want = bool(self._has_data.get(node, False)) and self.tabs.tab(view.tab).layers[node]
            if view.sent.get(node) != want:
                view.sent[node] = want
                send_visibility(view.handle, node, want)

    def _refresh(self, node: str) -> None:
        with self.tabs.lock:
            for view in list(self.tabs.clients.values()):
                self._refresh_client(view, node)

    def _set_data(self, node: str, present: bool) -> None:
        if self._has_data.get(node) != present:
            with self.tabs.lock:
                self._has_data[node] = present
            self._refresh(node)

    def is_shown(self, node: str, tab: str = DEFAULT_TAB) -> bool:
        """Whether a toggleable layer is visible in ``tab``'s view (data present and checkbox on)."""
        with self.tabs.lock:
            return bool(self._has_data.get(node, False)) and self.tabs.tab(tab).layers[node]

    def set_layer_enabled(self, label: str, enabled: bool, tab: str = DEFAULT_TAB) -> None:
        """Tick or untick a layer checkbox of one tab (same effect as its user doing it)."""
        self._set_node_enabled(LAYERS[label], enabled, tab)

    def _set_node_enabled(self, node: str, enabled: bool, tab: str) -> None:
        with self.tabs.lock:
            self.tabs.tab(tab).layers[node] = bool(enabled)
            views = self.tabs.clients_of(tab)
        for view in views:
            cb = view.checks.get(node)
            if cb is not None and bool(cb.value) != bool(enabled):
                cb.value = bool(enabled)
            self._refresh_client(view, node)

    def click_kind(self, tab: str = DEFAULT_TAB) -> str:
        """What a click in ``tab``'s view sets: "goal", "goal_unknown" or "initial_pose"."""
        return self.tabs.tab(tab).kind

    def set_click_kind(self, tab: str, kind: str) -> None:
        """Choose what a click in ``tab``'s view sets (its dropdown follows)."""
        if kind not in KIND_LABELS:
            raise ValueError(f"kind must be one of: {', '.join(KIND_LABELS)}")
        with self.tabs.lock:
            self.tabs.tab(tab).kind = kind
            views = self.tabs.clients_of(tab)
        for view in views:
            if view.click_mode is not None and view.click_mode.value != KIND_LABELS[kind]:
                view.click_mode.value = KIND_LABELS[kind]

    # ---------------------------------------------------------------- snapshot -> scene
    def apply(self, snap: Snapshot) -> None:
        """Apply one snapshot synchronously: scene layers then grids (tests, benchmarks, replays)."""
        self.apply_scene(snap)
        self.apply_grids(snap)

    def apply_scene(self, snap: Snapshot) -> None:
        """Everything except the grids: cheap per-tick updates (~0.1 ms per property, viser.md §10)."""
        t0 = time.perf_counter()
        h, last, o = self._h, self._last, self.options
        pose = snap.pose
        if pose.is_finite():
            self._pose = pose
            with self.server.atomic():
                h["/robot"].position = (pose.x, pose.y, 0.0)
                h["/robot"].wxyz = geo.yaw_wxyz(pose.theta)

        fp = snap.extras.get("footprint", self._footprint)
        if fp is not None and fp is not last.get("footprint"):
            last["footprint"] = fp
            h["/robot/footprint"].points = geo.ring_segments(fp, 0.01)
            r = float(np.max(np.hypot(*np.asarray(fp, dtype=float).reshape(-1, 2).T)))
            h["/robot/behavior"].points = geo.circle_segments(r + o.behavior_ring_margin, 0.015)
            self._draw_body(np.asarray(fp, dtype=float).reshape(-1, 2))

        if snap.scan is not None and (snap.scan is not last.get("scan") or snap.laser_pose != last.get("lp")):
            last["scan"], last["lp"] = snap.scan, snap.laser_pose
            pts, r = geo.scan_points(snap.scan, self._pose.compose(snap.laser_pose), o.scan_height)
            band = palette.scan_band(r)
            with self.server.atomic():
                for i in range(len(palette.SCAN_BANDS)):
                    h[f"/scan/band_{i}"].points = pts[band == i]

        if snap.trail is not last.get("trail"):
            last["trail"] = snap.trail
            present = snap.trail is not None and len(snap.trail) >= 2
            if present:
                h["/trail"].points = geo.polyline_segments(snap.trail, 0.003)
            self._set_data("/trail", present)

        if snap.path is not last.get("path"):
            last["path"] = snap.path
            present = snap.path is not None and len(snap.path) >= 2
            if present:
                h["/plan/global"].points = geo.polyline_segments(snap.path.poses, 0.008)
            self._set_data("/plan/global", present)

        self._apply_local_plan(snap)

        goal_key = (snap.goal, id(snap.extras.get("waypoints")))
        if goal_key != last.get("goal"):
            last["goal"] = goal_key
            wps = snap.extras.get("waypoints")
            goal = snap.goal if snap.goal is not None and snap.goal.is_finite() else Pose2D()
            with self.server.atomic():
                h["/goal"].position = (goal.x, goal.y, 0.0)
                h["/goal"].wxyz = geo.yaw_wxyz(goal.theta)
                h["/goal"].show_axes = snap.goal is not None
            if wps is not None and len(wps):
                w = np.array(
                    [(p.x, p.y) if isinstance(p, Pose2D) else tuple(p)[:2] for p in wps], dtype=float
                )
                local = goal.inverse().transform_points(geo.finite_rows(w))  # children follow /goal's pose
                pts = np.column_stack((local, np.full(len(local), 0.05))).astype(np.float32)
            else:
                pts = np.zeros((0, 3), np.float32)
            h["/goal/waypoints"].points = pts
            self._set_data("/goal", snap.goal is not None or len(pts) > 0)

        if snap.particles is not last.get("particles"):
            last["particles"] = snap.particles
            present = snap.particles is not None and len(snap.particles) > 0
            if present:
                h["/particles"].points = geo.pose_arrow_lines(
                    snap.particles, o.particle_arrow_length, 0.02, max_poses=o.max_particles
                ).reshape(-1, 2, 3)
            self._set_data("/particles", present)

        people = snap.extras.get("people")  # (P, 4): x, y, heading, radius (simulated people)
        if people is not last.get("people"):
            last["people"] = people
            present = people is not None and len(people) > 0
            if present:
                h["/people"].points = geo.disc_segments(np.asarray(people, dtype=float), 0.02)
            self._set_data("/people", present)

        # Loop closures belong to the mapping session: once mapping ends (or navigation starts) they
        # would only hide the path, so the layer is empty outside MAPPING.
        edges = snap.extras.get("graph_edges") if snap.mode == "mapping" else None
        if edges is not last.get("edges"):
            last["edges"] = edges
            present = edges is not None and len(edges) > 0
            if present:
                h["/graph/edges"].points = geo.edge_segments(edges, 0.012)
            self._set_data("/graph/edges", present)

        if snap.behavior != last.get("behavior"):
            last["behavior"] = snap.behavior
            self._draw_behavior(snap.behavior)

        marks = snap.extras.get("recovery_markers")  # ((x, y, theta, behaviour name), ...)
        if marks is not last.get("recoveries"):
            last["recoveries"] = marks
            self._draw_recoveries(marks)

        zones = snap.extras.get("zone_layer")  # ((kind, label, (K, 2) vertices), ...)
        if zones is not last.get("zones"):
            last["zones"] = zones
            self._draw_zones(zones or ())
        self._draw_frontiers(snap.extras.get("frontiers"), snap.extras.get("frontier_goal"))

        band = snap.extras.get("teb_band")  # (N, 3) TEB poses, map frame
        if band is not last.get("teb_band"):
            last["teb_band"] = band
            present = band is not None and len(band) >= 2
            if present:
                poses = np.asarray(band, dtype=float)
                with self.server.atomic():
                    h["/plan/teb/band"].points = geo.polyline_segments(poses, 0.014)
                    h["/plan/teb/poses"].points = geo.pose_arrow_lines(
                        poses, o.teb_arrow_length, 0.016
                    ).reshape(-1, 2, 3)
            self._set_data("/plan/teb", present)

        now = time.monotonic()
        if now >= self._status_due:
            self._status_due = now + 1.0 / self.options.status_rate_hz
            self.status.content = self.status_text(snap)
        self.stats.updates += 1
        self.stats.last_update_s = time.perf_counter() - t0

    def _draw_frontiers(self, cells: Any, goal: Any) -> None:
        """Exploration's frontier cells ((N, 2), map frame) and the chosen frontier's goal (x, y)."""
        last, h = self._last, self._h
        if cells is last.get("frontiers") and goal == last.get("frontier_goal"):
            return
        last["frontiers"], last["frontier_goal"] = cells, goal
        present = cells is not None and len(cells) > 0
        with self.server.atomic():
            if present:
                pts = np.asarray(cells, dtype=np.float32)[:, :2]
                h["/frontiers/cells"].points = np.column_stack((pts, np.full(len(pts), 0.02, np.float32)))
            g = (
                np.array([[goal[0], goal[1], 0.08]], np.float32)
                if goal is not None
                else np.zeros((0, 3), np.float32)
            )
            h["/frontiers/goal"].points = g
        self._set_data("/frontiers", present or goal is not None)

    def _draw_body(self, ring: np.ndarray) -> None:
        """A translucent box over the footprint's bounding box, so the robot is visible from afar
        (Rviz shows the URDF; a 2D footprint is all a profile gives us)."""
        lo, hi = ring.min(axis=0), ring.max(axis=0)
        centre = (lo + hi) / 2.0
        self._h["/robot/body"] = self.server.scene.add_box(
            "/robot/body",
            color=(90, 150, 230),
            dimensions=(float(hi[0] - lo[0]), float(hi[1] - lo[1]), 0.08),
            position=(float(centre[0]), float(centre[1]), 0.04),
            opacity=0.6,
            material="toon3",  # lit without PBR: a much smaller shader to compile in the browser
            cast_shadow=False,
            receive_shadow=False,
        )

    def _draw_behavior(self, name: str | None) -> None:
        """Name and colour the current behaviour: a ring around the robot, a label above it and a
        badge in the panel (the dashboard's status panel uses the same colours)."""
        h = self._h
        rgb = palette.behavior_color(name)
        with self.server.atomic():
            if name:
                h["/robot/label"].text = name
                h["/robot/behavior"].colors = np.array(rgb, np.uint8)
            h["/robot/label"].visible = bool(name)
            h["/robot/behavior"].visible = bool(name)
        self.behavior_badge.content = behavior_badge_html(name)
        self.behavior_badge.visible = bool(name)

    def _draw_recoveries(self, marks: Any) -> None:
        """A diamond in the behaviour's colour where each recovery attempt started, numbered."""
        h, o = self._h, self.options
        rows = [m for m in (marks or ()) if len(m) >= 4 and all(math.isfinite(float(v)) for v in m[:3])]
        if rows:
            xy = np.array([(float(m[0]), float(m[1])) for m in rows])
            colors = np.array([palette.behavior_color(str(m[3])) for m in rows], np.uint8)
            segs = geo.diamond_segments(xy, o.recovery_marker_radius, 0.02)  # (K, 4, 2, 3)
            with self.server.atomic():
                h["/recoveries/markers"].points = segs.reshape(-1, 2, 3)
                h["/recoveries/markers"].colors = np.repeat(colors, 8, axis=0).reshape(-1, 2, 3)
        for i in range(MAX_RECOVERY_LABELS):
            name = f"/recoveries/label_{i}"
            if i < len(rows):
                x, y, _th, what = rows[i][:4]
                text = f"{i + 1}. {what}"
                if name not in h:
                    h[name] = self.server.scene.add_label(
                        name, text, position=(float(x), float(y), 0.25), anchor="bottom-center"
                    )
                else:
                    with self.server.atomic():
                        h[name].text = text
                        h[name].position = (float(x), float(y), 0.25)
                        h[name].visible = True
            elif name in h:
                h[name].visible = False
            else:
                break
        self._set_data("/recoveries", bool(rows))

    def _draw_zones(self, zones: Any) -> None:
        """Keepout (red) and speed (amber) zone outlines just above the map, each labelled."""
        h = self._h
        with self.server.atomic():
            for kind in ZONE_KINDS:
                rings = [np.vstack((v, v[:1])) for k, _label, v in zones if k == kind]
                segs = [geo.polyline_segments(r, 0.03) for r in rings]
                h[f"/zones/{kind}"].points = np.concatenate(segs) if segs else np.zeros((0, 2, 3), np.float32)
        for i in range(MAX_ZONE_LABELS):
            name = f"/zones/label_{i}"
            if i < len(zones):
                _kind, text, v = zones[i]
                x, y = (float(c) for c in np.asarray(v).mean(axis=0))
                if name not in h:
                    h[name] = self.server.scene.add_label(
                        name, text, position=(x, y, 0.1), anchor="center-center"
                    )
                else:
                    with self.server.atomic():
                        h[name].text = text
                        h[name].position = (x, y, 0.1)
                        h[name].visible = True
            elif name in h:
                h[name].visible = False
            else:
                break
        self._set_data("/zones", bool(zones))

    def _apply_local_plan(self, snap: Snapshot) -> None:
        h, last = self._h, self._last
        lp = snap.local_plan
        best_idx = snap.extras.get("local_plan_best")
        if lp is last.get("local") and best_idx == last.get("local_best"):
            return
        last["local"], last["local_best"] = lp, best_idx
        present = lp is not None and lp.size > 0
        if present:
            arr = np.asarray(lp, dtype=float)
            if arr.ndim == 2:  # one trajectory: it is the chosen one
                best, samples = arr, None
            else:  # (K, N, 2) samples, extras["local_plan_best"] picks the chosen one
                k = arr.shape[0]
                best = arr[int(best_idx)] if best_idx is not None and 0 <= int(best_idx) < k else None
                samples = arr
            if samples is not None:
                h["/plan/local/samples"].points = geo.trajectory_segments(
                    samples, 0.01, self.options.max_local_samples
                )
            h["/plan/local/samples"].visible = samples is not None
            if best is not None:
                h["/plan/local/best"].points = geo.polyline_segments(best, 0.012)
            h["/plan/local/best"].visible = best is not None
        self._set_data("/plan/local", present)

    def apply_grids(self, snap: Snapshot) -> int:
        """Re-tile the map and costmap if they changed; return the number of tiles encoded."""
        encoded = 0
        grid = snap.grid
        key = (id(grid), snap.grid_version)
        if key != self._last.get("grid"):
            self._last["grid"] = key
            if grid is not None:
                encoded += self.map_layer.update(grid.geometry, grid.data)
                if grid.geometry != self._aimed_at:
                    # a new active map (another frame) or a growing SLAM map: new pages and "Reset View"
                    # look at it; viser never moves a connected client's camera for this
                    self._aim_camera(grid.geometry)
            self._set_data("/map", grid is not None)
        cm = snap.extras.get("costmap")
        cm_key = (id(cm), snap.extras.get("costmap_version"))
        if cm_key != self._last.get("costmap"):
            self._last["costmap"] = cm_key
            self._last["costmap_ref"] = cm  # hold it: a freed object's id() can be reused by the next one
            present = isinstance(cm, Costmap)
            if present:
                encoded += self.costmap_layer.update(cm.geometry, cm.costs)
            self._set_data("/costmap", present)
        if encoded:
            self.stats.grid_updates += 1
        return encoded

    def _aim_camera(self, geometry: Any) -> None:
        """Initial camera (new pages, "Reset View"): the map centre from about 55 degrees up."""
        w, hgt = geometry.size_m
        c = geometry.origin.transform_points(np.array([[w / 2.0, hgt / 2.0]]))[0]
        span = max(w, hgt, 2.0)
        self.server.initial_camera.look_at = (float(c[0]), float(c[1]), 0.0)
        self.server.initial_camera.position = (float(c[0]), float(c[1] - 0.4 * span), 0.55 * span)
        self._aimed_at = geometry

    @staticmethod
    def status_text(snap: Snapshot) -> str:
        """One markdown line: mode, pose, speed, behaviour, and any stop condition."""
        p, v = snap.pose, snap.velocity
        parts = [
            f"**{snap.mode}**",
            f"x {p.x:.2f} y {p.y:.2f} θ {math.degrees(wrap_angle(p.theta)):.0f}°",
            f"v {v.vx:.2f} m/s ω {v.wz:.2f} rad/s",
        ]
        if snap.behavior:
            parts.append(f"_{snap.behavior}_")
        if snap.estop:
            parts.append("**E-STOP**")
        if snap.fault:
            parts.append(f"fault: {snap.fault}")
        return " · ".join(parts)

    # ---------------------------------------------------------------- threads
    def _scene_loop(self, sub: Subscription) -> None:
        period = 1.0 / self.options.rate_hz
        due = 0.0
        while not self._stop.is_set():
            snap = sub.wait(timeout=0.25)
            if snap is None:
                continue
            wait = due - time.monotonic()
            if wait > 0.0 and self._stop.wait(wait):
                return
            snap = sub.take() or snap  # the newest one after the rate-limit pause
            due = time.monotonic() + period
            try:
                self.apply_scene(snap)
            except Exception:  # a bad snapshot must not kill the view
                self.stats.errors += 1
                log.exception("viewer: scene update failed")

    def _grid_loop(self, sub: Subscription) -> None:
        period = 1.0 / self.options.map_rate_hz
        due = 0.0
        while not self._stop.is_set():
            snap = sub.wait(timeout=0.25)
            if snap is None:
                continue
            wait = due - time.monotonic()
            if wait > 0.0 and self._stop.wait(wait):
                return
            snap = sub.take() or snap
            try:
                if self.apply_grids(snap):
                    due = time.monotonic() + period
            except Exception:
                self.stats.errors += 1
                log.exception("viewer: grid update failed")

    # ---------------------------------------------------------------- pointer input
    def _emit(self, tab: str, kind: str, pose: Pose2D) -> None:
        """Hand a pose to ``on_pose_input`` and tell the tab's view what became of it: a refusal with its
        reason, an initial pose with a confirmation (and the tab's clicks set goals again)."""
        cb = self.on_pose_input
        if cb is None or not pose.is_finite():
            return
        try:
            refused = cb(kind, pose, tab)
        except Exception:  # viser would only print it; keep the view alive
            log.exception("viewer: on_pose_input failed")
            return
        label = KIND_LABELS.get(kind, kind)
        if refused:
            self._notify(tab, f"{label} refused", refused, (220, 60, 60))
            return
        if kind == "initial_pose":
            self.set_click_kind(tab, "goal")
            where = f"x {pose.x:.2f} y {pose.y:.2f} θ {math.degrees(pose.theta):.0f}°"
            self._notify(tab, "initial pose set", f"{where}. A click now sets a goal.", (40, 160, 80))

    def _notify(self, tab: str, title: str, body: str, color: tuple[int, int, int]) -> None:
        """A toast in the views of one tab (viser's per-client notification)."""
        for view in self.tabs.clients_of(tab):
            try:
                view.handle.add_notification(title, body, auto_close_seconds=6.0, color=color)
            except Exception:  # a client that just went away
                log.debug("viewer: notification to client %s failed", view.handle.client_id, exc_info=True)

    def _on_scene_click(self, event: viser.SceneClickEvent) -> None:
        """Plain click: a goal faces the direction of travel, an initial pose keeps the estimate's heading."""
        try:
            xy = ray_ground(event.ray_origin, event.ray_direction)
        except PoseInputError:
            return
        tab = self.tabs.tab_of_client(getattr(event, "client_id", None))
        kind = self.click_kind(tab)
        theta = self._pose.theta if kind == "initial_pose" else heading_towards(self._pose, xy)
        self._emit(tab, kind, Pose2D(float(xy[0]), float(xy[1]), theta))

    def _bind_tile_drag(self, tile: viser.ImageHandle) -> None:
        tile.on_drag("left", modifier="shift")(self._on_map_drag)

    async def _on_map_drag(self, event: viser.SceneNodeDragEvent) -> None:
        """Shift+drag on the map, as Rviz's pose tools: press = position, drag direction = heading.

        ``async`` so viser runs the phases in order on its loop; it only does arithmetic and enqueues."""
        press = np.asarray(event.start_position, dtype=float)
        try:
            release = ground_through(event.client.camera.position, event.end_position)
        except (PoseInputError, AttributeError):
            release = np.asarray(event.end_position, dtype=float)[:2]
        pose = pose_from_press_drag(press, release, self._pose.theta)
        preview = self._h["/input/preview"]
        if event.phase == "end":
            preview.visible = False
            tab = self.tabs.tab_of_client(getattr(event, "client_id", None))
            self._emit(tab, self.click_kind(tab), pose)
            return
        tip = (pose.x + 0.5 * math.cos(pose.theta), pose.y + 0.5 * math.sin(pose.theta))
        preview.points = np.array([[[pose.x, pose.y, 0.05], [tip[0], tip[1], 0.05]]], np.float32)
        preview.visible = True
