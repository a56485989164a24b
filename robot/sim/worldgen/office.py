"""Offices: 18-28 x 12-18 m, one corridor 1.6-2.4 m wide along the floor, rooms 3.5-6 m wide on both
sides, each with a 0.9 m door to the corridor (some also to the next room), a desk with a
four-legged chair and a cabinet; a few pillars stand against the corridor walls."""

from __future__ import annotations

import itertools

import numpy as np

from maps.stock.generate import WALL, Canvas
from robot.sim.worldgen.base import GeneratedWorld, place_chair

PROFILE = "skid4"
DOOR = 0.9


def _room_xs(width: float, rng: np.random.Generator) -> list[float]:
    """Inner wall positions along x splitting the floor into rooms 3.5-6 m wide."""
    xs, x = [], 0.0
    while True:
        x += float(rng.uniform(3.5, 6.0))
        if width - x < 3.5:
            return xs
        xs.append(round(x, 2))


def generate(seed: int) -> GeneratedWorld:
    rng = np.random.default_rng(seed)
    c = Canvas(float(rng.uniform(18.0, 28.0)), float(rng.uniform(12.0, 18.0)))
    width, height = c.w * 0.05, c.h * 0.05
    c.outline()
    corridor = float(rng.uniform(1.6, 2.4))
    y_lo = round(float(height * rng.uniform(0.4, 0.55)), 2)
    y_hi = round(y_lo + corridor, 2)
    c.hwall(y_lo, 0.0, width)
    c.hwall(y_hi, 0.0, width)
    legs: list[tuple[float, float]] = []
    doors: list[tuple[float, float]] = []
    rooms = 0
    for lower in (True, False):
        xs = _room_xs(width, rng)
        bounds = [0.0, *xs, width]
        y0, y1 = (WALL, y_lo - WALL / 2) if lower else (y_hi + WALL / 2, height - WALL)
        for x in xs:
            c.vwall(x, y0, y1)
            if rng.random() < 0.3:  # a door to the next room too
                yd = float(rng.uniform(y0 + 0.8, y1 - 0.8))
                c.vdoor(x, yd, DOOR)
                doors.append((x, yd))
        for a, b in itertools.pairwise(bounds):
            rooms += 1
            xd = float(rng.uniform(a + 0.7, b - 0.7))
            c.hdoor(y_lo if lower else y_hi, xd, DOOR)
            doors.append((xd, y_lo if lower else y_hi))
            # a desk against the back wall on the side away from the door, its chair in front,
            # and a cabinet in the back corner on the door's side
            dw = float(rng.uniform(1.2, 1.8))
            left = xd - a > b - xd
            lo, hi = (
                (a + 0.2, max(a + 0.2, xd - 0.8 - dw))
                if left
                else (min(xd + 0.8, b - 0.2 - dw), b - 0.2 - dw)
            )
            dx0 = float(rng.uniform(lo, hi))
            desk = (y0, y0 + 0.8) if lower else (y1 - 0.8, y1)
            c.box(dx0, desk[0], dx0 + dw, desk[1])
            cx, cy = dx0 + dw / 2, desk[1] + 0.45 if lower else desk[0] - 0.45
            place_chair(c, cx, cy, legs)
            cab = (b - 1.2, b - 0.1) if left else (a + 0.1, a + 1.2)
            c.box(cab[0], y0 if lower else y1 - 0.45, cab[1], y0 + 0.45 if lower else y1)
    pillars = []
    for _ in range(int(rng.integers(0, 3))):
        px = float(rng.uniform(2.0, width - 2.0))
        if all(abs(px - dx) > 1.5 for dx, _ in doors):
            c.box(px - 0.15, y_lo + WALL / 2, px + 0.15, y_lo + WALL / 2 + 0.3)  # leaves >= 1.2 m
            pillars.append((px, y_lo + 0.2))
    return GeneratedWorld(
        family="office",
        seed=seed,
        grid=c.grid(),
        profile=PROFILE,
        params={
            "width_m": width,
            "height_m": height,
            "corridor_width_m": corridor,
            "rooms": rooms,
            "doors": len(doors),
            "pillars": len(pillars),
        },
        items={"leg": legs, "door": doors, "pillar": pillars},
    )
