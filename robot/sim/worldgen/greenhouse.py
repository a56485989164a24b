"""Greenhouses (source C): 3-7 plant rows 0.3-0.8 m wide and 8-16 m long along x, aisles of one
drawn width in 0.8-1.6 m between them and along the side walls, headlands of 1.0-2.0 m at both
ends, 0.1 m structural posts along the side walls and at the row ends, and soil mounds in the aisles
that are in the simulated world but not on the map (as in the stock greenhouse's scenario). A mound
narrows its aisle but always leaves the robot's width plus margin: each aisle stays drivable."""

from __future__ import annotations

import numpy as np

from maps.stock.generate import WALL, Canvas
from robot.profiles import load_profile
from robot.sim.scenario import ellipse
from robot.sim.worldgen.base import GeneratedWorld

PROFILE = "skid4"
"""The skid robot, as in the issue's greenhouse trials (`sim-nav --people 2`). omni4 (source C's robot)
runs with ``run_trial(..., profile="omni4")``."""
POST = 0.1
MOUND_MARGIN = 0.15
"""Metres of aisle kept free next to a mound beyond the robot's circumscribed diameter (plus a
cell each side)."""


def generate(seed: int) -> GeneratedWorld:
    rng = np.random.default_rng(seed)
    rows = int(rng.integers(3, 8))
    row_w = float(rng.uniform(0.3, 0.8))
    aisle = float(rng.uniform(0.8, 1.6))
    headland = float(rng.uniform(1.0, 2.0))
    length = float(rng.uniform(8.0, 16.0))
    width = length + 2 * headland + 2 * WALL
    height = (rows + 1) * aisle + rows * row_w + 2 * WALL
    c = Canvas(width, height)
    c.outline()
    x0, x1 = WALL + headland, WALL + headland + length
    row_y = [WALL + aisle + k * (aisle + row_w) for k in range(rows)]
    posts: list[tuple[float, float]] = []
    for y in row_y:
        c.box(x0, y, x1, y + row_w)
        for x in (x0 - POST / 2, x1 + POST / 2):  # posts holding the row's wires at both ends
            c.leg(x, y + row_w / 2, POST)
            posts.append((x, y + row_w / 2))
    for x in np.arange(x0, x1 + 1e-6, 3.0):  # structural posts along the side walls
        for y in (WALL + POST / 2, height - WALL - POST / 2):
            c.leg(float(x), y, POST)
            posts.append((float(x), y))
    radius = load_profile(PROFILE).circumscribed_radius
    free_needed = 2 * (radius + 0.05) + MOUND_MARGIN
    room = aisle - free_needed  # how far a mound may reach into its aisle
    mounds: list[np.ndarray] = []
    aisle_lo = [WALL, *(y + row_w for y in row_y)]  # lower edge of every aisle
    for lo in aisle_lo:
        # all of an aisle's mounds grow from one side (a row or the wall) and reach at most ``room``
        # into it and at most a row's width into the row, so no two mounds close an aisle together
        # and none pokes through a row into the next aisle
        below = bool(rng.random() < 0.5)
        for _ in range(int(rng.integers(0, 3))):
            top = min(room, row_w)
            if top <= 0.08:
                continue
            depth = float(rng.uniform(0.08, top))
            along = float(rng.uniform(0.3, 0.8))
            cx = float(rng.uniform(x0 + 1.0, x1 - 1.0))
            mounds.append(ellipse((cx, lo if below else lo + aisle), (along, depth)))
    # walkers go down the aisles between the rows, from headland to headland
    lanes = tuple(
        np.array([[x0 - headland / 2, y - aisle / 2], [x1 + headland / 2, y - aisle / 2]]) for y in row_y[1:]
    )
    return GeneratedWorld(
        family="greenhouse",
        seed=seed,
        grid=c.grid(),
        profile=PROFILE,
        unmapped=tuple(mounds),
        params={
            "rows": rows,
            "row_width_m": row_w,
            "aisle_width_m": aisle,
            "headland_m": headland,
            "row_length_m": length,
            "mounds": len(mounds),
            "posts": len(posts),
        },
        items={"post": posts, "row_y": [(y, y + row_w) for y in row_y]},
        lanes=lanes,
    )
