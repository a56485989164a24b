"""Stock simulation worlds shipped with navdeck (map_server PGM + YAML, made by ``generate.py``)."""

from __future__ import annotations

from pathlib import Path

STOCK_DIR = Path(__file__).parent


class UnknownWorldError(KeyError):
    """No stock world has this name."""

    def __str__(self) -> str:
        return str(self.args[0])


def available_worlds() -> list[str]:
    """Names of the stock worlds (YAML files in this folder)."""
    return sorted(p.stem for p in STOCK_DIR.glob("*.yaml"))


def stock_world_path(name: str) -> Path:
    """Path of a stock world's YAML; raises ``UnknownWorldError`` naming the choices."""
    path = STOCK_DIR / f"{name}.yaml"
    if not name or "/" in name or not path.is_file():
        raise UnknownWorldError(f"unknown world {name!r}: choose one of {', '.join(available_worlds())}")
    return path
