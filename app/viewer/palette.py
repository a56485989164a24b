"""Colour look-up tables that make the 3D view read like Rviz2.

Both grid palettes are (256, 4) uint8 RGBA tables indexed by the *byte* value of a cell, so a whole
grid is coloured with one fancy-indexing step (``lut[data.view(np.uint8)]``) and no per-cell Python.

* ``map_palette`` is rviz_default_plugins' ``makeMapPalette`` (map_display.cpp): occupancy 0..100 as
  grey from 255 down to 0, the legal unknown value -1 (byte 255) as the "tasteful blueish greenish
  grayish" (0x70, 0x89, 0x86), illegal positive values green and illegal negative values red-to-yellow.
* ``costmap_palette`` is ``makeCostmapPalette`` applied *after* Nav2's ``cost_translation_table``
  (costmap_2d_publisher.cpp), which maps a uint8 cost to the 0..100 / -1 value published on the
  ``costmap`` topic: 0 free -> transparent, 1..252 -> blue..red, 253 inscribed -> cyan,
  254 lethal -> purple, 255 unknown -> transparent here (Rviz would paint it grey-blue and hide the map).
"""

from __future__ import annotations

import numpy as np

from nav.types import INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE, NO_INFORMATION


def _rviz_palette_tail(lut: np.ndarray) -> None:
    """Entries 101..255 shared by Rviz's map and costmap schemes."""
    lut[101:128] = (0, 255, 0, 255)  # illegal positive values: green
    i = np.arange(128, 255)
    lut[128:255, 0] = 255  # illegal negative values: red to yellow
    lut[128:255, 1] = (255 * (i - 128)) // (254 - 128)
    lut[128:255, 2] = 0
    lut[128:255, 3] = 255
    lut[255] = (0x70, 0x89, 0x86, 255)  # -1: unknown


def map_palette(alpha: float = 0.7, background: tuple[int, int, int] = (48, 48, 48)) -> np.ndarray:
    """Rviz's "map" colour scheme as a (256, 4) RGBA table indexed by the int8 value's byte.

    Rviz draws the map with alpha 0.7 over its dark grey (48, 48, 48) background, which is what makes
    free space *light grey* on screen. That blend is baked in here and the result kept opaque, so the
    map tiles need no transparency sorting against the costmap overlay above them."""
    lut = np.zeros((256, 4), dtype=np.uint8)
    i = np.arange(101)
    v = 255 - (255 * i) // 100
    lut[:101, 0] = lut[:101, 1] = lut[:101, 2] = v
    lut[:101, 3] = 255
    _rviz_palette_tail(lut)
    a = float(np.clip(alpha, 0.0, 1.0))
    blended = a * lut[:, :3].astype(float) + (1.0 - a) * np.asarray(background, dtype=float)
    lut[:, :3] = np.round(blended).astype(np.uint8)
    return lut


def cost_translation_table() -> np.ndarray:
    """Nav2 ``Costmap2DPublisher`` table: uint8 cost -> published occupancy value (int8 as uint8 byte)."""
    table = np.empty(256, dtype=np.int16)
    table[0] = 0
    c = np.arange(1, 253)
    table[1:253] = 1 + (97 * (c - 1)) // 251
    table[INSCRIBED_INFLATED_OBSTACLE] = 99
    table[LETHAL_OBSTACLE] = 100
    table[NO_INFORMATION] = -1
    return table.astype(np.int8).view(np.uint8)


def costmap_palette(alpha: float = 0.7, unknown_visible: bool = False) -> np.ndarray:
    """Rviz's "costmap" scheme over raw uint8 Nav2 costs, with overall ``alpha`` (Rviz default 0.7)."""
    rviz = np.zeros((256, 4), dtype=np.uint8)
    i = np.arange(1, 99)
    v = (255 * i) // 100
    rviz[1:99, 0] = v
    rviz[1:99, 2] = 255 - v
    rviz[1:99, 3] = 255
    rviz[99] = (0, 255, 255, 255)  # inscribed: cyan
    rviz[100] = (255, 0, 255, 255)  # lethal: purple
    _rviz_palette_tail(rviz)
    lut = rviz[cost_translation_table()].copy()
    lut[:, 3] = np.round(lut[:, 3].astype(float) * float(np.clip(alpha, 0.0, 1.0))).astype(np.uint8)
    lut[0, 3] = 0  # free space is see-through, as in Rviz
    if not unknown_visible:
        lut[NO_INFORMATION, 3] = 0
    return lut


def colorize(codes: np.ndarray, lut: np.ndarray, upsample: int = 1) -> np.ndarray:
    """(H, W) int8/uint8 cells -> (H*k, W*k, 4) RGBA, nearest-upsampled by the integer ``upsample``.

    Upsampling by whole factors keeps cells crisp under three.js' bilinear texture filter."""
    rgba = lut[np.ascontiguousarray(codes).view(np.uint8)]
    if upsample > 1:
        rgba = np.repeat(np.repeat(rgba, upsample, axis=0), upsample, axis=1)
    return rgba


# Scan points coloured by range in a few bands, each band one point cloud with one flat colour (red near,
# yellow, blue far: Rviz's rainbow transformer, coarsened). Not per-point colours: viser's client builds a
# new point material whenever a cloud's colour array changes, and three.js then recompiles its shader
# program (100-500 ms of the page's main thread under software WebGL, on every scan).
SCAN_BANDS: tuple[tuple[float, tuple[int, int, int]], ...] = (
    (0.5, (255, 40, 40)),  # < 0.5 m: inside the safety layer's slow-down zone
    (2.0, (255, 200, 0)),
    (float("inf"), (40, 160, 255)),
)


def scan_band(ranges: np.ndarray) -> np.ndarray:
    """(N,) metres -> (N,) index into ``SCAN_BANDS`` (the first band whose upper edge exceeds it)."""
    edges = np.array([b[0] for b in SCAN_BANDS[:-1]])
    return np.searchsorted(edges, np.asarray(ranges, dtype=float), side="right")


# Flat colours for vector layers (RGB), close to Rviz's defaults for the same displays.
FOOTPRINT = (0, 200, 0)  # Nav2 footprint polygon: green
HEADING = (255, 60, 60)
TRAIL = (255, 170, 0)  # Odometry display: orange-ish
GLOBAL_PLAN = (40, 120, 255)  # Nav2 default rviz config: /plan in blue
LOCAL_SAMPLES = (140, 140, 160)
LOCAL_BEST = (0, 230, 120)
GOAL = (230, 40, 200)
WAYPOINTS = (255, 220, 0)
PARTICLES = (255, 40, 40)  # AMCL particle cloud: red arrows
GRAPH_EDGES = (0, 200, 255)
PREVIEW = (80, 255, 80)

PEOPLE = (255, 140, 0)  # simulated people (orange discs)
TEB_BAND = (255, 105, 180)  # TEB band poses (pink), apart from DWB samples (grey) and best (green)
KEEPOUT_ZONE = (220, 30, 30)  # Nav2 keepout mask: red outlines
SPEED_ZONE = (255, 190, 0)  # Nav2 speed mask: amber outlines
FRONTIERS = (0, 230, 255)  # exploration frontier cells (cyan), over the grey map
FRONTIER_GOAL = (255, 60, 255)  # the frontier being driven to

# Behaviour colours, shared by the 3D view (ring + marker colour) and the dashboard's status panel
# (frontend/js/behaviors.js holds the same table; a test keeps the two equal). Navigation itself is
# calm (blue/green), recoveries are warm and each one distinct, so an operator can tell at a glance
# which recovery is running and which ones already ran (the markers keep their colour).
BEHAVIOR_COLORS: dict[str, tuple[int, int, int]] = {
    "compute_path": (40, 120, 255),  # Nav2 ComputePathToPose: planning, waiting for a path
    "follow_path": (0, 200, 120),  # Nav2 FollowPath: the controller is driving
    "blocked": (230, 50, 50),  # no safe trajectory this cycle: stopped, looking for another way
    "clear_local_costmap": (0, 200, 230),
    "clear_global_costmap": (0, 140, 200),
    "clear_costmaps": (0, 170, 215),
    "spin": (170, 80, 255),
    "spin_until_matched": (230, 60, 200),
    "relocalize": (255, 60, 120),
    "wait": (255, 200, 0),
    "wait_for_walker": (255, 225, 120),  # a wait ended by the walker leaving the path
    "back_up": (255, 120, 0),
    "drive_on_heading": (180, 220, 40),
}
UNKNOWN_BEHAVIOR = (170, 170, 170)


def behavior_color(name: str | None) -> tuple[int, int, int]:
    """RGB of a behaviour name (grey for one not in the table, e.g. a plugin's own behaviour)."""
    return BEHAVIOR_COLORS.get(name or "", UNKNOWN_BEHAVIOR)


def hex_color(rgb: tuple[int, int, int]) -> str:
    """(r, g, b) -> "#rrggbb"."""
    return "#{:02x}{:02x}{:02x}".format(*rgb)
