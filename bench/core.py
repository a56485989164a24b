"""Benchmark registry: every ``bench/*.py`` module may define ``BENCHMARKS``, a list of
``Benchmark``; ``navdeck bench`` runs them, prints a table and optionally writes JSON."""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class Figure:
    name: str
    value: float
    unit: str
    target: str = ""  # human-readable target, e.g. "< 2 ms"
    ok: bool | None = None  # whether the target is met (None: no target)


@dataclass(frozen=True)
class Benchmark:
    name: str  # dotted, e.g. "sim.raycast"
    run: Callable[[], list[Figure]]
    group: str = "default"  # "default" runs with plain ``navdeck bench``; others only by name


def discover() -> list[Benchmark]:
    import bench

    found: list[Benchmark] = []
    for info in sorted(pkgutil.iter_modules(bench.__path__), key=lambda m: m.name):
        if info.name in ("core", "__main__"):
            continue
        module = importlib.import_module(f"bench.{info.name}")
        found.extend(getattr(module, "BENCHMARKS", []))
    return found


def figure_dict(bench_name: str, fig: Figure) -> dict:
    """JSON-ready row: numpy scalars (a benchmark's ``value`` or ``ok`` computed with numpy) become
    plain float / bool, which ``json`` can write."""
    row = {"benchmark": bench_name, **asdict(fig)}
    row["value"] = float(fig.value)
    row["ok"] = None if fig.ok is None else bool(fig.ok)
    return row
