"""Apartments: a rectangle of 8-12 x 6-9 m split into four rooms by one wall across and one wall
down each half, every inner wall with a 0.8-0.95 m door (so every room is reachable), and furniture:
tables on four 4 cm legs with four-legged chairs round them (source A's smallest object) and solid
pieces (sofa, bed, cabinet) against the walls."""

from __future__ import annotations

import numpy as np

from maps.stock.generate import WALL, Canvas
from robot.sim.worldgen.base import GeneratedWorld, place_chair

PROFILE = "skid4"
CHAIR_OFFSET = 0.45
"""Metres from a table's edge to the centre of a chair beside it."""


def _fits(rect: tuple[float, float, float, float], taken: list[tuple[float, float, float, float]]) -> bool:
    x0, y0, x1, y1 = rect
    return all(x1 <= a0 or x0 >= a1 or y1 <= b0 or y0 >= b1 for a0, b0, a1, b1 in taken)


def _furnish(
    c: Canvas,
    room: tuple[float, float, float, float],
    taken: list[tuple[float, float, float, float]],
    rng: np.random.Generator,
    legs: list[tuple[float, float]],
) -> tuple[int, int]:
    """One table with chairs (if it fits) and one solid piece against a wall; returns (tables, chairs)."""
    rx0, ry0, rx1, ry1 = room
    tables = chairs = 0
    gap = 0.35  # free space kept round every piece (with its chairs) so the room stays drivable
    for _ in range(30):
        w, d = float(rng.uniform(0.8, 1.4)), float(rng.uniform(0.6, 0.9))
        reach = CHAIR_OFFSET + 0.22  # chairs stick out this far from the table's long sides
        if rx1 - gap - w <= rx0 + gap or ry1 - gap - reach - d <= ry0 + gap + reach:
            continue  # too big for this room: draw a smaller one
        x0 = float(rng.uniform(rx0 + gap, rx1 - gap - w))
        y0 = float(rng.uniform(ry0 + gap + reach, ry1 - gap - reach - d))
        rect = (x0 - gap, y0 - reach - gap, x0 + w + gap, y0 + d + reach + gap)
        if not _fits(rect, taken):
            continue
        taken.append(rect)
        for x, y in ((x0, y0), (x0 + w, y0), (x0, y0 + d), (x0 + w, y0 + d)):
            inset = 0.05
            lx, ly = x + (inset if x == x0 else -inset), y + (inset if y == y0 else -inset)
            c.leg(lx, ly)
            legs.append((lx, ly))
        tables += 1
        for k in range(int(rng.integers(2, 5))):
            cx = x0 + w * (0.3 if k % 2 == 0 else 0.7)
            cy = y0 - CHAIR_OFFSET if k < 2 else y0 + d + CHAIR_OFFSET
            place_chair(c, cx, cy, legs)
            chairs += 1
        break
    for _ in range(30):
        w, d = float(rng.uniform(0.6, 2.0)), float(rng.uniform(0.4, 0.9))
        side = int(rng.integers(4))
        if side < 2:  # against the bottom or top wall
            if rx1 - w <= rx0:
                continue
            x0 = float(rng.uniform(rx0, rx1 - w))
            y0 = ry0 if side == 0 else ry1 - d
            rect = (x0, y0, x0 + w, y0 + d)
        else:
            if ry1 - w <= ry0:
                continue
            y0 = float(rng.uniform(ry0, ry1 - w))
            x0 = rx0 if side == 2 else rx1 - d
            rect = (x0, y0, x0 + d, y0 + w)
        padded = (rect[0] - gap, rect[1] - gap, rect[2] + gap, rect[3] + gap)
        if not _fits(padded, taken):
            continue
        taken.append(padded)
        c.box(*rect)
        break
    return tables, chairs


def generate(seed: int) -> GeneratedWorld:
    rng = np.random.default_rng(seed)
    width, height = float(rng.uniform(8.0, 12.0)), float(rng.uniform(6.0, 9.0))
    c = Canvas(width, height)
    width, height = c.w * 0.05, c.h * 0.05
    c.outline()
    ys = round(float(height * rng.uniform(0.45, 0.6)), 2)
    xb, xt = (round(float(width * rng.uniform(0.35, 0.65)), 2) for _ in range(2))
    c.hwall(ys, 0.0, width)
    c.vwall(xb, 0.0, ys)
    c.vwall(xt, ys, height)
    doors: list[tuple[float, float]] = []
    door_w = float(rng.uniform(0.8, 0.95))
    yb = float(rng.uniform(0.7, ys - 0.7))
    c.vdoor(xb, yb, door_w)
    doors.append((xb, yb))
    yt = float(rng.uniform(ys + 0.7, height - 0.7))
    c.vdoor(xt, yt, door_w)
    doors.append((xt, yt))
    spans = [(0.7, min(xb, xt) - 0.7), (max(xb, xt) + 0.7, width - 0.7)]
    spans = [s for s in spans if s[1] > s[0]]
    for lo, hi in spans[: 1 + int(rng.integers(len(spans)))]:  # one or two doors across
        xd = float(rng.uniform(lo, hi))
        c.hdoor(ys, xd, door_w)
        doors.append((xd, ys))
    # doorways are kept clear: nothing within 0.9 m of a door's centre
    taken = [(x - 0.9, y - 0.9, x + 0.9, y + 0.9) for x, y in doors]
    rooms = [
        (WALL, WALL, xb - WALL / 2, ys - WALL / 2),
        (xb + WALL / 2, WALL, width - WALL, ys - WALL / 2),
        (WALL, ys + WALL / 2, xt - WALL / 2, height - WALL),
        (xt + WALL / 2, ys + WALL / 2, width - WALL, height - WALL),
    ]
    legs: list[tuple[float, float]] = []
    tables = chairs = 0
    for room in rooms:
        t, ch = _furnish(c, room, taken, rng, legs)
        tables, chairs = tables + t, chairs + ch
    return GeneratedWorld(
        family="apartment",
        seed=seed,
        grid=c.grid(),
        profile=PROFILE,
        params={
            "width_m": width,
            "height_m": height,
            "rooms": 4,
            "doors": len(doors),
            "door_width_m": door_w,
            "tables": tables,
            "chairs": chairs,
        },
        items={"leg": legs, "door": doors},
    )
