"""Zones <-> Nav2 costmap filter masks (issue 19: the interchange), pure conversion.

A filter mask is a map_server map (PGM + YAML) over the same cells as the map it filters, plus the
``CostmapFilterInfo`` values Nav2's ``costmap_filter_info_server`` publishes with it (``type``,
``base``, ``multiplier``), as the Nav2 costmap-filter tutorials define them:

- keepout (type 0): cells whose mask value is 100 (occupied) are keepout;
- speed (type 1: percent of the maximum speed, type 2: absolute m/s): a mask value ``v`` in 1..100
  means ``speed_limit = base + multiplier * v``; 0 (and unknown) means no limit.

Export rasterizes the zones by cell centre (``nav.costmap.filter_layer``, as the costmaps do) and
writes ``mode: scale`` (tutorial default) or ``mode: raw``. In scale mode the speed mask uses
``free_thresh: 0``, ``occupied_thresh: 1`` so grey levels map linearly onto 0..100 (2.55 grey levels
per value, so every value survives the 8-bit round trip); the keepout mask is black/white with the
map_server thresholds 0.65 / 0.196 (it reads the same in trinary mode).

Import groups equal mask values into 4-connected regions (``scipy.ndimage.label``) and turns each
into a polygon along the cell boundaries (rectilinear outline, collinear vertices dropped). A region
whose outline is not one simple polygon (a hole, or two corners meeting at a point), or that has
more vertices than a zone may, is cut in two along a row boundary through the hole (the touching
corners, or halfway) and each piece is treated again, so every cell is kept (zones have no holes)
and export -> import -> export is bit-exact.
"""

from __future__ import annotations

import io
import math
import zipfile
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from scipy import ndimage

from app.zone_store import SpeedUnit, Zone, ZoneKind, ZoneSpec
from maps.mapio import (
    YAML_FREE_THRESH,
    YAML_OCCUPIED_THRESH,
    MapFormatError,
    _yaml_float,
    parse_map_yaml,
    read_map_bytes,
)
from nav.costmap.filter_layer import MAX_VERTICES, rasterize_polygons
from nav.types import GridGeometry, OccupancyGrid

MASK_MODES = ("scale", "raw")
NO_LIMIT = 0
"""Nav2 SpeedFilter: a mask value of 0 (or unknown, -1) means no speed limit."""
KEEPOUT_VALUE = 100


class FilterType(IntEnum):
    """CostmapFilterInfo ``type`` (nav2_costmap_2d/costmap_filters/filter_values.hpp)."""

    KEEPOUT = 0
    SPEED_PERCENT = 1
    SPEED_ABSOLUTE = 2


class MaskError(ValueError):
    """A mask cannot be written or read; the message says what is wrong."""


@dataclass(frozen=True)
class FilterInfo:
    type: FilterType
    base: float
    multiplier: float

    def limit(self, value: np.ndarray | int) -> np.ndarray | float:
        return self.base + self.multiplier * np.asarray(value, dtype=float)


DEFAULT_INFO = {
    # the Nav2 tutorials' values: keepout base 0 / multiplier 1; speed in percent base 100 /
    # multiplier -1 (value v = 100 - percent, so 0 = 100 % = no limit); m/s in 0.01 m/s steps
    FilterType.KEEPOUT: FilterInfo(FilterType.KEEPOUT, 0.0, 1.0),
    FilterType.SPEED_PERCENT: FilterInfo(FilterType.SPEED_PERCENT, 100.0, -1.0),
    FilterType.SPEED_ABSOLUTE: FilterInfo(FilterType.SPEED_ABSOLUTE, 0.0, 0.01),
}


def filter_type(kind: ZoneKind, unit: SpeedUnit = SpeedUnit.PERCENT) -> FilterType:
    if kind == ZoneKind.KEEPOUT:
        return FilterType.KEEPOUT
    return FilterType.SPEED_PERCENT if unit == SpeedUnit.PERCENT else FilterType.SPEED_ABSOLUTE


# --------------------------------------------------------------------------------------- export


def mask_values(zones: list[Zone], geometry: GridGeometry, info: FilterInfo) -> np.ndarray:
    """(H, W) uint8 mask values (grid row order) of the zones that ``info`` covers. Overlapping speed
    zones: the lowest limit wins (as the zones feature applies it)."""
    out = np.zeros((geometry.height, geometry.width), dtype=np.uint8)
    if info.type == FilterType.KEEPOUT:
        polys = [z.vertices() for z in zones if z.kind == ZoneKind.KEEPOUT]
        out[rasterize_polygons(polys, geometry)] = KEEPOUT_VALUE
        return out
    unit = SpeedUnit.PERCENT if info.type == FilterType.SPEED_PERCENT else SpeedUnit.MPS
    speed = [z for z in zones if z.kind == ZoneKind.SPEED and z.speed_limit and z.speed_limit_unit == unit]
    for z in sorted(speed, key=lambda z: -float(z.speed_limit or 0.0)):  # lowest limit painted last
        out[rasterize_polygons([z.vertices()], geometry)] = speed_value(
            float(z.speed_limit or 0.0), info, z.name
        )
    return out


def speed_value(limit: float, info: FilterInfo, name: str = "") -> int:
    """The mask value 1..100 that encodes ``limit`` (nearest one: the mask has 100 levels)."""
    q = (limit - info.base) / info.multiplier if info.multiplier else -1.0
    v = round(q) if math.isfinite(q) else -1
    if not 1 <= v <= 100:
        raise MaskError(
            f"speed zone {name!r}: limit {limit:g} cannot be encoded with base {info.base:g} and "
            f"multiplier {info.multiplier:g} (value {v}, must be 1..100)"
        )
    return v


def encode_mask_pgm(values: np.ndarray, info: FilterInfo, mode: str) -> bytes:
    """P5 PGM of mask ``values`` (grid row order, flipped so image row 0 is the top)."""
    v = values.astype(np.float64)
    if mode == "raw":
        pix = v
    elif info.type == FilterType.KEEPOUT:
        pix = np.where(v >= KEEPOUT_VALUE, 0.0, 254.0)  # black keepout on map_saver's free grey
    else:
        pix = np.rint(255.0 * (1.0 - v / 100.0))  # scale with free 0 / occupied 1: occ = v / 100
    h, w = values.shape
    header = f"P5\n# CREATOR: navdeck zone_masks\n{w} {h}\n255\n".encode("ascii")
    return header + np.flipud(pix.astype(np.uint8)).tobytes()


def encode_mask_yaml(geometry: GridGeometry, info: FilterInfo, mode: str, image: str) -> bytes:
    linear = mode == "scale" and info.type != FilterType.KEEPOUT
    occ, free = (1.0, 0.0) if linear else (YAML_OCCUPIED_THRESH, YAML_FREE_THRESH)
    o = geometry.origin
    lines = [
        f"image: {image}",
        f"mode: {mode}",
        f"resolution: {_yaml_float(geometry.resolution)}",
        f"origin: [{_yaml_float(o.x)}, {_yaml_float(o.y)}, {_yaml_float(o.theta)}]",
        "negate: 0",
        f"occupied_thresh: {_yaml_float(occ)}",
        f"free_thresh: {_yaml_float(free)}",
    ]
    return ("\n".join(lines) + "\n").encode("utf-8")


def encode_filter_info(info: FilterInfo, mask_topic: str) -> bytes:
    """The ``costmap_filter_info_server`` parameters file of the Nav2 tutorials."""
    lines = [
        "costmap_filter_info_server:",
        "  ros__parameters:",
        "    use_sim_time: false",
        f"    type: {int(info.type)}",
        '    filter_info_topic: "/costmap_filter_info"',
        f'    mask_topic: "{mask_topic}"',
        f"    base: {float(info.base)!r}",
        f"    multiplier: {float(info.multiplier)!r}",
    ]
    return ("\n".join(lines) + "\n").encode("utf-8")


def export_zip(zones: list[Zone], geometry: GridGeometry, info: FilterInfo, mode: str = "scale") -> bytes:
    """A zip of ``<stem>_mask.pgm``, ``<stem>_mask.yaml`` and ``<stem>_filter_info.yaml``."""
    if mode not in MASK_MODES:
        raise MaskError(f"mask mode {mode!r} is not one of {', '.join(MASK_MODES)}")
    stem = "keepout" if info.type == FilterType.KEEPOUT else "speed"
    values = mask_values(zones, geometry, info)
    buf = io.BytesIO()
    files = {
        f"{stem}_mask.pgm": encode_mask_pgm(values, info, mode),
        f"{stem}_mask.yaml": encode_mask_yaml(geometry, info, mode, f"{stem}_mask.pgm"),
        f"{stem}_filter_info.yaml": encode_filter_info(info, f"/{stem}_filter_mask"),
    }
    with zipfile.ZipFile(buf, "w") as z:
        for name, data in files.items():
            # a fixed timestamp so the same zones always give the same bytes
            z.writestr(zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0)), data, zipfile.ZIP_DEFLATED)
    return buf.getvalue()


# --------------------------------------------------------------------------------------- import


def parse_filter_info(text: str) -> FilterInfo:
    """``type``, ``base``, ``multiplier`` from a costmap_filter_info_server parameters file (nested
    under ``costmap_filter_info_server: ros__parameters:`` or flat)."""
    try:
        data = parse_map_yaml(text)
    except MapFormatError as exc:
        raise MaskError(f"filter info: {exc}") from None
    if "type" not in data:
        raise MaskError("filter info YAML has no 'type' (0 keepout, 1 speed %, 2 speed m/s)")
    t = data["type"]
    if isinstance(t, bool) or t not in (0, 1, 2):
        raise MaskError(f"filter info 'type' must be 0 (keepout), 1 (speed %) or 2 (speed m/s), got {t!r}")
    ftype = FilterType(int(t))  # type: ignore[arg-type]
    default = DEFAULT_INFO[ftype]
    out = []
    for key, fallback in (("base", default.base), ("multiplier", default.multiplier)):
        v = data.get(key, fallback)
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise MaskError(f"filter info {key!r} must be a number, got {v!r}")
        out.append(float(v))
    if ftype != FilterType.KEEPOUT and out[1] == 0:
        raise MaskError("filter info 'multiplier' of a speed mask must not be 0")
    return FilterInfo(ftype, out[0], out[1])


def read_mask(yaml_bytes: bytes, image_bytes: bytes, image_name: str, geometry: GridGeometry) -> np.ndarray:
    """The mask's cell values (int8, grid row order, as map_server loads it), checked to cover
    exactly the map's cells."""
    try:
        grid: OccupancyGrid = read_map_bytes(yaml_bytes, image_bytes, image_name)
    except MapFormatError as exc:
        raise MaskError(str(exc)) from None
    g = grid.geometry
    same_origin = all(
        math.isclose(a, b, abs_tol=1e-6)
        for a, b in zip(
            (g.origin.x, g.origin.y, g.origin.theta),
            (geometry.origin.x, geometry.origin.y, geometry.origin.theta),
            strict=True,
        )
    )
    if (
        (g.width, g.height) != (geometry.width, geometry.height)
        or not math.isclose(g.resolution, geometry.resolution, rel_tol=1e-9)
        or not same_origin
    ):
        raise MaskError(
            f"the mask ({g.width} x {g.height} cells at {g.resolution:g} m, origin "
            f"[{g.origin.x:g}, {g.origin.y:g}, {g.origin.theta:g}]) does not cover the map "
            f"({geometry.width} x {geometry.height} at {geometry.resolution:g} m, origin "
            f"[{geometry.origin.x:g}, {geometry.origin.y:g}, {geometry.origin.theta:g}])"
        )
    return grid.data


def region_polygons(region: np.ndarray) -> list[np.ndarray]:
    """Polygons in cell-corner coordinates (x = column, y = row) covering the True cells of one
    4-connected ``region`` exactly: its outline if it is one simple polygon within the vertex
    limit; else the region is cut in two along a row boundary through its first hole (or where two
    corners touch, or halfway) and each connected piece is treated the same way."""
    outline, cut = _outline(region)
    if outline is not None and len(outline) <= MAX_VERTICES:
        return [outline]
    h = region.shape[0]
    if h < 2:
        return _rectangles(region)
    if outline is None and cut is None:
        holes, _ = ndimage.label(ndimage.binary_fill_holes(region) & ~region)
        rows = np.nonzero(holes == 1)[0]
        cut = (int(rows.min()) + int(rows.max()) + 1) // 2 if rows.size else None
    if cut is None or not 0 < cut < h:
        cut = h // 2
    out: list[np.ndarray] = []
    for part, r0 in ((region[:cut], 0), (region[cut:], cut)):
        labels, _ = ndimage.label(part)
        for k, box in enumerate(ndimage.find_objects(labels), 1):
            offset = np.array([box[1].start, box[0].start + r0], dtype=float)
            out.extend(p + offset for p in region_polygons(labels[box] == k))
    return out


def _outline(region: np.ndarray) -> tuple[np.ndarray | None, int | None]:
    """The counter-clockwise cell-boundary outline (collinear vertices dropped), or (None, row of a
    vertex where two corners touch) / (None, None for a hole) when the boundary is not a single
    simple loop."""
    p = np.pad(region, 1)
    # vertical edges at x = c between cells (r, c-1) and (r, c); horizontal at y = r between rows
    left_in = p[1:-1, :-1] & ~p[1:-1, 1:]
    right_in = ~p[1:-1, :-1] & p[1:-1, 1:]
    below_in = p[:-1, 1:-1] & ~p[1:, 1:-1]
    above_in = ~p[:-1, 1:-1] & p[1:, 1:-1]
    # interior on the left: up along x = c when the interior is left of it, and so on
    r, c = np.nonzero(left_in)
    starts = [np.column_stack((c, r))]
    ends = [np.column_stack((c, r + 1))]
    r, c = np.nonzero(right_in)
    starts.append(np.column_stack((c, r + 1)))
    ends.append(np.column_stack((c, r)))
    r, c = np.nonzero(below_in)
    starts.append(np.column_stack((c + 1, r)))
    ends.append(np.column_stack((c, r)))
    r, c = np.nonzero(above_in)
    starts.append(np.column_stack((c, r)))
    ends.append(np.column_stack((c + 1, r)))
    s = np.concatenate(starts)
    e = np.concatenate(ends)
    n = len(s)
    width = region.shape[1] + 2
    sk = s[:, 1] * width + s[:, 0]
    keys, counts = np.unique(sk, return_counts=True)
    if keys.size != n:  # a vertex where two corners of the region touch: cut along its row
        return None, int(keys[np.argmax(counts > 1)] // width)
    nxt = dict(zip(sk.tolist(), (e[:, 1] * width + e[:, 0]).tolist(), strict=True))
    first = int(sk[0])
    loop, key = [first], nxt[first]
    while key != first:
        loop.append(key)
        key = nxt[key]
    if len(loop) != n:
        return None, None  # more than one loop: the region has a hole
    pts = np.column_stack((np.array(loop) % width, np.array(loop) // width)).astype(float)
    prev, foll = np.roll(pts, 1, axis=0), np.roll(pts, -1, axis=0)
    cross = (pts[:, 0] - prev[:, 0]) * (foll[:, 1] - pts[:, 1]) - (pts[:, 1] - prev[:, 1]) * (
        foll[:, 0] - pts[:, 0]
    )
    return pts[cross != 0], None


def _rectangles(region: np.ndarray) -> list[np.ndarray]:
    """Rectangles covering ``region``: the runs of each row, a run extended down the following rows
    while they hold the very same run."""
    open_runs: dict[tuple[int, int], int] = {}
    rects: list[tuple[int, int, int, int]] = []
    for row in range(region.shape[0] + 1):
        line = region[row] if row < region.shape[0] else np.zeros(region.shape[1], dtype=bool)
        d = np.diff(np.concatenate(([0], line.astype(np.int8), [0])))
        runs = set(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))
        for run in list(open_runs):
            if run not in runs:
                rects.append((run[0], run[1], open_runs.pop(run), row))
        for run in runs:
            open_runs.setdefault(run, row)
    return [np.array([[c0, r0], [c1, r0], [c1, r1], [c0, r1]], dtype=float) for c0, c1, r0, r1 in rects]


def _to_map(corners: np.ndarray, geometry: GridGeometry) -> list[list[float]]:
    o = geometry.origin
    g = corners * geometry.resolution
    c, s = math.cos(o.theta), math.sin(o.theta)
    x = o.x + c * g[:, 0] - s * g[:, 1]
    y = o.y + s * g[:, 0] + c * g[:, 1]
    return np.column_stack((x, y)).tolist()


def zones_from_mask(
    values: np.ndarray, geometry: GridGeometry, info: FilterInfo, prefix: str
) -> list[ZoneSpec]:
    """Zone specs for a mask's values: one per connected region of equal value (more when a region
    is split), named ``<prefix> <n>``."""
    v = values.astype(np.int16)
    if info.type == FilterType.KEEPOUT:
        levels = [KEEPOUT_VALUE] if (v == KEEPOUT_VALUE).any() else []
    else:
        levels = [int(x) for x in np.unique(v) if 1 <= x <= 100]
        limits = {lv: float(info.limit(lv)) for lv in levels}
        bad = [lv for lv, lim in limits.items() if not _valid_limit(lim, info.type)]
        if bad:
            lv = bad[0]
            raise MaskError(
                f"mask value {lv} means a speed limit of {limits[lv]:g} "
                f"({'%' if info.type == FilterType.SPEED_PERCENT else 'm/s'}) with base {info.base:g} and "
                f"multiplier {info.multiplier:g}: a limit must be > 0 (and <= 100 %)"
            )
    kind = ZoneKind.KEEPOUT if info.type == FilterType.KEEPOUT else ZoneKind.SPEED
    unit = SpeedUnit.MPS if info.type == FilterType.SPEED_ABSOLUTE else SpeedUnit.PERCENT
    specs: list[ZoneSpec] = []
    for level in levels:
        labels, _ = ndimage.label(v == level)
        boxes = ndimage.find_objects(labels)
        for k, box in enumerate(boxes, 1):
            if box is None:
                continue
            region = labels[box] == k
            offset = np.array([box[1].start, box[0].start], dtype=float)
            limit = None if kind == ZoneKind.KEEPOUT else _clean(float(info.limit(level)))
            for poly in region_polygons(region):
                specs.append(
                    ZoneSpec(
                        f"{prefix} {len(specs) + 1}", kind, _to_map(poly + offset, geometry), limit, unit
                    )
                )
    return specs


def _valid_limit(limit: float, ftype: FilterType) -> bool:
    return math.isfinite(limit) and limit > 0 and (ftype != FilterType.SPEED_PERCENT or limit <= 100)


def _clean(x: float) -> float:
    """base + multiplier * v without the float noise (0.01 * 7 = 0.07, not 0.07000000000000001)."""
    return float(f"{x:.12g}")
