"""A grid (occupancy map or costmap) shown as a mosaic of PNG image tiles that re-sends only what changed.

viser draws ``add_image`` as a textured plane (image row 0 at local -y, columns along +x: exactly
nav_msgs/OccupancyGrid order, so no flip) and re-encodes the PNG in the thread that assigns it. A
live SLAM map changes a few cells at a time, so the grid is cut into ``tile_cells``-square tiles on a
lattice anchored to the *first* origin seen: when the map grows by whole cells (Cartographer and
slam_toolbox grow by whole cells) existing tiles keep their lattice slot and content, and only the
tiles whose cells differ from the last sent copy are re-encoded. A change of resolution, yaw or a
sub-cell origin shift re-anchors and rebuilds every tile.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import viser

from app.viewer.palette import colorize
from nav.types import GridGeometry, Pose2D

MAX_TEXTURE_PX = 4096  # a safe WebGL texture size on every GPU


@dataclass(frozen=True)
class TileOptions:
    """How a grid is cut and drawn."""

    tile_cells: int = 128
    """Tile side in cells. Smaller tiles re-send less on a local change but add scene nodes."""
    upsample: int = 4
    """Whole-number nearest upsampling so three.js' bilinear filter does not blur cells (capped so a
    tile stays <= 4096 px)."""
    z: float = 0.0
    """Height of the layer in metres (the costmap overlay floats at 0.005 m above the map)."""
    max_total_px: int = 16_000_000
    """Upper bound on the whole layer's texture pixels: large maps get a smaller upsampling factor so
    the first send and browser memory stay bounded (600x400 cells keeps x4, a 2000x2000 map gets x2)."""
    encode_workers: int = 2
    """Threads encoding changed tiles in parallel (PNG deflate releases the GIL); 1 = inline."""


class TiledGridLayer:
    """One grid layer under the scene node ``name`` (a frame at the lattice anchor, tiles as children)."""

    def __init__(
        self,
        server: viser.ViserServer,
        name: str,
        lut: np.ndarray,
        options: TileOptions = TileOptions(),
        on_tile_added: Callable[[viser.ImageHandle], None] | None = None,
    ) -> None:
        if options.tile_cells < 1 or options.upsample < 1:
            raise ValueError("tile_cells and upsample must be >= 1")
        self._server = server
        self._scene = server.scene
        self._name = name.rstrip("/")
        self._lut = lut
        self._opt = options
        self._up_cap = max(1, min(options.upsample, MAX_TEXTURE_PX // options.tile_cells))
        self._up = self._up_cap
        self._on_tile_added = on_tile_added
        self.root = server.scene.add_frame(self._name, show_axes=False)
        self._anchor: Pose2D | None = None
        self._resolution = 0.0
        self._handles: dict[tuple[int, int], viser.ImageHandle] = {}
        self._sent: dict[tuple[int, int], np.ndarray] = {}  # last content sent per lattice slot
        self._centres: dict[tuple[int, int], tuple[float, float]] = {}
        self.encodes = 0  # PNG tile encodes since creation
        self._pool = (
            ThreadPoolExecutor(options.encode_workers, thread_name_prefix="viewer-tiles")
            if options.encode_workers > 1
            else None
        )

    def close(self) -> None:
        """Stop the encoder threads (the scene nodes stay)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    @property
    def tile_names(self) -> list[str]:
        """Scene names of the tiles currently shown."""
        return [self._tile_name(k) for k in sorted(self._sent)]

    def _tile_name(self, key: tuple[int, int]) -> str:
        return f"{self._name}/tile_{key[0]}_{key[1]}"

    def _offset(self, geometry: GridGeometry) -> tuple[int, int] | None:
        """Origin of ``geometry`` in whole cells (rows, cols) on the current lattice, or None if it
        does not sit on it (other resolution or yaw, or a sub-cell shift)."""
        if self._anchor is None or not math.isclose(geometry.resolution, self._resolution, rel_tol=1e-9):
            return None
        rel = geometry.origin.relative_to(self._anchor)
        if abs(rel.theta) > 1e-9:
            return None
        dc, dr = rel.x / geometry.resolution, rel.y / geometry.resolution
        if abs(dc - round(dc)) > 1e-3 or abs(dr - round(dr)) > 1e-3:
            return None
        return round(dr), round(dc)

    def _upsample_for(self, geometry: GridGeometry) -> int:
        fit = math.isqrt(max(1, self._opt.max_total_px // max(1, geometry.width * geometry.height)))
        return max(1, min(self._up_cap, fit))

    def _reanchor(self, geometry: GridGeometry) -> None:
        self._anchor = geometry.origin
        self._resolution = geometry.resolution
        for key in list(self._sent):
            self._handles[key].visible = False
        self._sent.clear()
        o = geometry.origin
        with self._server.atomic():
            self.root.position = (o.x, o.y, self._opt.z)
            self.root.wxyz = (math.cos(o.theta / 2.0), 0.0, 0.0, math.sin(o.theta / 2.0))

    def update(self, geometry: GridGeometry, codes: np.ndarray) -> int:
        """Show ``codes`` ((height, width) int8 or uint8 cells) over ``geometry``; return the number of
        tiles (re-)encoded. Vectorized per tile; the Python loop runs over tiles, never cells."""
        if codes.shape != (geometry.height, geometry.width):
            raise ValueError(f"grid shape {codes.shape} != ({geometry.height}, {geometry.width})")
        up = self._upsample_for(geometry)
        offset = self._offset(geometry)
        if offset is None or up != self._up:
            self._up = up
            self._reanchor(geometry)
            offset = (0, 0)
        r0, c0 = offset
        t = self._opt.tile_cells
        h, w = codes.shape
        res = geometry.resolution
        live: set[tuple[int, int]] = set()
        jobs: list[tuple[tuple[int, int], np.ndarray, tuple[float, float], float, np.ndarray | None]] = []
        for kr in range(r0 // t, (r0 + h - 1) // t + 1):
            gr0, gr1 = max(kr * t, r0), min(kr * t + t, r0 + h)
            for kc in range(c0 // t, (c0 + w - 1) // t + 1):
                gc0, gc1 = max(kc * t, c0), min(kc * t + t, c0 + w)
                key = (kr, kc)
                live.add(key)
                block = codes[gr0 - r0 : gr1 - r0, gc0 - c0 : gc1 - c0]
                last = self._sent.get(key)
                centre = ((gc0 + gc1) * 0.5 * res, (gr0 + gr1) * 0.5 * res)
                if (
                    last is not None
                    and last.shape == block.shape
                    and self._centres.get(key) == centre
                    and np.array_equal(last, block)
                ):
                    continue
                jobs.append((key, block, centre, res, last))
        if len(jobs) > 1 and self._pool is not None:  # zlib releases the GIL: encode tiles in parallel
            list(self._pool.map(lambda job: self._draw(*job), jobs))
        else:
            for job in jobs:
                self._draw(*job)
        for key, block, centre, _res, _last in jobs:
            self._sent[key] = block.copy()
            self._centres[key] = centre
        encoded = len(jobs)
        for key in [k for k in self._sent if k not in live]:
            self._handles[key].visible = False
            del self._sent[key]
        self.encodes += encoded
        return encoded

    def _draw(
        self,
        key: tuple[int, int],
        block: np.ndarray,
        centre: tuple[float, float],
        res: float,
        last: np.ndarray | None,
    ) -> None:
        rgba = colorize(block, self._lut, self._up)
        handle = self._handles.get(key)
        position = (centre[0], centre[1], 0.0)
        if handle is not None and last is not None and last.shape == block.shape:
            handle.image = rgba  # same size: only the texture (and maybe the place, rolling window) changes
            if tuple(handle.position) != position:
                handle.position = position
            return
        handle = self._scene.add_image(
            self._tile_name(key),
            rgba,
            render_width=block.shape[1] * res,
            render_height=block.shape[0] * res,
            format="png",
            position=position,
            cast_shadow=False,
            receive_shadow=False,
        )
        self._handles[key] = handle
        if self._on_tile_added is not None:
            self._on_tile_added(handle)
