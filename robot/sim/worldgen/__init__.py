"""Seeded world generators, one module per family (``apartment``, ``office``, ``greenhouse``,
``forest``): ``generate(family, seed)`` returns a ``GeneratedWorld``, the same for the same seed,
with its map, the obstacles only the simulator has, a start/goal sampler whose poses are in free
space with clearance and joined by a route the robot's footprint fits along, and walkers' paths.
The stock worlds (``maps/stock``) stay as they are. See docs/worldgen.md."""

from __future__ import annotations

from collections.abc import Callable

from robot.sim.worldgen import apartment, forest, greenhouse, office
from robot.sim.worldgen.base import GeneratedWorld, WorldgenError, Zone

FAMILIES: dict[str, Callable[[int], GeneratedWorld]] = {
    "apartment": apartment.generate,
    "office": office.generate,
    "greenhouse": greenhouse.generate,
    "forest": forest.generate,
}


def generate(family: str, seed: int) -> GeneratedWorld:
    """The world of ``family`` drawn from ``seed``; ``WorldgenError`` for an unknown family."""
    try:
        build = FAMILIES[family]
    except KeyError:
        raise WorldgenError(f"unknown world family {family!r}; one of {', '.join(FAMILIES)}") from None
    return build(int(seed))


__all__ = ["FAMILIES", "GeneratedWorld", "WorldgenError", "Zone", "generate"]
