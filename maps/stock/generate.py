"""Generate the stock worlds (PGM + YAML, 0.05 m/pixel) into this folder.

Run ``python -m maps.stock.generate``. Output is deterministic; the committed files are its output.
Each YAML carries ``navdeck_start: [x, y, theta]``, a free start pose (map_server ignores the key).

- ``apartment`` (10 x 8 m): living room, kitchen, bedroom, bathroom, 0.8 m doors, furniture and
  4 x 4 cm chair legs (source A's smallest object).
- ``office`` (30 x 20 m): a central corridor with rooms on both sides behind 0.9 m doors, desks.
- ``greenhouse`` (20 x 12 m): parallel plant rows with 1.2 m aisles and headlands (source C).

People, soil mounds and puddles are not drawn here: they are absent from the maps on purpose (the
robot must meet them with its sensors) and live in the hand-written sidecars
``<name>.scenario.toml`` (``robot.sim.scenario``), loaded with ``World.stock(name, scenario=True)``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from maps.mapio import save_map
from nav.types import GridGeometry, OccupancyGrid, Pose2D

RESOLUTION = 0.05
WALL = 0.10
OUT_DIR = Path(__file__).parent


class Canvas:
    """A free grid to draw axis-aligned obstacles on, in metres (origin at the lower-left)."""

    def __init__(self, width: float, height: float) -> None:
        self.w, self.h = round(width / RESOLUTION), round(height / RESOLUTION)
        self.data = np.zeros((self.h, self.w), dtype=np.int8)

    def _span(self, a: float, b: float, n: int) -> slice:
        lo, hi = sorted((a, b))
        return slice(
            max(0, round(lo / RESOLUTION)), min(n, max(round(hi / RESOLUTION), round(lo / RESOLUTION) + 1))
        )

    def box(self, x0: float, y0: float, x1: float, y1: float, value: int = 100) -> None:
        """Fill the rectangle [x0, x1] x [y0, y1] (at least one cell)."""
        self.data[self._span(y0, y1, self.h), self._span(x0, x1, self.w)] = value

    def clear(self, x0: float, y0: float, x1: float, y1: float) -> None:
        self.box(x0, y0, x1, y1, 0)

    def hwall(self, y: float, x0: float, x1: float) -> None:
        self.box(x0, y - WALL / 2, x1, y + WALL / 2)

    def vwall(self, x: float, y0: float, y1: float) -> None:
        self.box(x - WALL / 2, y0, x + WALL / 2, y1)

    def hdoor(self, y: float, x: float, width: float) -> None:
        """Open a doorway of ``width`` centred at x in a horizontal wall at y."""
        self.clear(x - width / 2, y - WALL, x + width / 2, y + WALL)

    def vdoor(self, x: float, y: float, width: float) -> None:
        self.clear(x - WALL, y - width / 2, x + WALL, y + width / 2)

    def outline(self) -> None:
        W, H = self.w * RESOLUTION, self.h * RESOLUTION
        self.box(0, 0, W, WALL)
        self.box(0, H - WALL, W, H)
        self.box(0, 0, WALL, H)
        self.box(W - WALL, 0, W, H)

    def leg(self, x: float, y: float, size: float = 0.04) -> None:
        """A small square post (chair or table leg)."""
        self.box(x - size / 2, y - size / 2, x + size / 2, y + size / 2)

    def chair(self, x: float, y: float) -> None:
        for dx in (-0.2, 0.2):
            for dy in (-0.2, 0.2):
                self.leg(x + dx, y + dy)

    def grid(self) -> OccupancyGrid:
        return OccupancyGrid(GridGeometry(RESOLUTION, self.w, self.h), self.data.copy())


def apartment() -> tuple[OccupancyGrid, Pose2D]:
    c = Canvas(10.0, 8.0)
    c.outline()
    # living room (0-6, 0-5), kitchen (6-10, 0-5), bedroom (0-5.5, 5-8), bathroom (5.5-10, 5-8)
    c.hwall(5.0, 0, 10)
    c.vwall(6.0, 0, 5.0)
    c.vwall(5.5, 5.0, 8)
    c.hdoor(5.0, 2.5, 0.8)  # living -> bedroom
    c.hdoor(5.0, 8.0, 0.8)  # kitchen -> bathroom
    c.vdoor(6.0, 2.5, 0.8)  # living -> kitchen
    # living room: sofa, coffee table on legs, dining table with chairs
    c.box(0.3, 0.3, 2.3, 1.1)  # sofa
    for x, y in ((1.0, 1.8), (1.8, 1.8), (1.0, 2.4), (1.8, 2.4)):
        c.leg(x, y)  # coffee table legs
    c.box(3.6, 2.2, 4.8, 2.9)  # dining table top (solid at lidar height)
    for x in (3.8, 4.6):
        c.chair(x, 1.7)
        c.chair(x, 3.4)
    # kitchen: counters along walls
    c.box(9.3, 0.1, 9.9, 4.9)
    c.box(6.1, 0.1, 9.3, 0.7)
    # bedroom: bed and wardrobe
    c.box(0.1, 6.0, 2.1, 7.9)
    c.box(4.3, 7.3, 5.4, 7.9)
    # bathroom: tub
    c.box(8.2, 6.9, 9.9, 7.9)
    return c.grid(), Pose2D(3.0, 3.5, 0.0)


def office() -> tuple[OccupancyGrid, Pose2D]:
    c = Canvas(30.0, 20.0)
    c.outline()
    # corridor y in [9, 11] along the whole floor, rooms 5 m wide above and below
    c.hwall(9.0, 0, 30)
    c.hwall(11.0, 0, 30)
    for x in np.arange(5.0, 30.0, 5.0):
        c.vwall(float(x), 0, 9.0)
        c.vwall(float(x), 11.0, 20.0)
    rng = np.random.default_rng(7)
    for i in range(6):
        x0 = i * 5.0
        width = 0.8 if i % 2 else 0.9
        c.hdoor(9.0, x0 + 2.5, width)
        c.hdoor(11.0, x0 + 2.5 + (0.8 if i % 2 else -0.8), width)
        # desks (solid) and chairs (legs) in each room
        for y0 in (2.0, 14.5):
            dx = float(rng.uniform(-0.3, 0.3))
            c.box(x0 + 1.0 + dx, y0, x0 + 2.6 + dx, y0 + 0.8)
            c.chair(x0 + 1.8 + dx, y0 + 1.4)
        c.box(x0 + 3.6, 0.1, x0 + 4.9, 0.6)  # cabinet
        c.box(x0 + 3.6, 19.4, x0 + 4.9, 19.9)
    # a pillar and a plant pot in the corridor
    c.box(14.8, 9.1, 15.2, 9.4)
    c.box(22.0, 10.6, 22.3, 10.9)
    return c.grid(), Pose2D(2.0, 10.0, 0.0)


def greenhouse() -> tuple[OccupancyGrid, Pose2D]:
    c = Canvas(20.0, 12.0)
    c.outline()
    # plant rows along x, 0.6 m wide, 1.2 m aisles, 2.5 m headlands at both ends
    y = 1.4
    while y + 0.6 < 11.0:
        c.box(2.5, y, 17.5, y + 0.6)
        y += 1.8
    # soil mounds and a puddle edge post (small obstacles in aisles)
    c.box(8.0, 2.3, 8.3, 2.5)
    c.box(12.0, 5.9, 12.2, 6.2)
    for x in np.arange(0.6, 19.5, 3.0):  # structural posts
        c.leg(float(x), 0.3, 0.1)
        c.leg(float(x), 11.7, 0.1)
    return c.grid(), Pose2D(1.2, 6.0, 0.0)


WORLDS = {"apartment": apartment, "office": office, "greenhouse": greenhouse}


def generate(out_dir: Path = OUT_DIR) -> list[Path]:
    written = []
    for name, build in WORLDS.items():
        grid, start = build()
        written.append(
            save_map(grid, out_dir, name, extra={"navdeck_start": [start.x, start.y, start.theta]})
        )
    return written


if __name__ == "__main__":
    for path in generate():
        print(path)
