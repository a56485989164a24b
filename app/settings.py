"""Server settings: command-line flags over environment variables over defaults."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path


def default_data_dir() -> Path:
    return Path(os.environ.get("NAVDECK_DATA_DIR", Path.cwd() / "var"))


def default_db_url(data_dir: Path) -> str:
    return os.environ.get("NAVDECK_DATABASE_URL", f"sqlite:///{data_dir / 'navdeck.db'}")


@dataclass
class Settings:
    robot: str = "sim"  # "sim" or "serial:///dev/ttyUSB0?lidar=/dev/ttyUSB1"
    profile: str = "skid4"  # stock profile name or a path to a TOML file
    world: str = "apartment"  # stock world name or a path to a map YAML (simulator only)
    host: str = "127.0.0.1"
    port: int = 8000
    data_dir: Path = field(default_factory=default_data_dir)
    db_url: str = ""
    rate_hz: float = 20.0
    seed: int = 0
    robot_name: str = field(default_factory=lambda: os.environ.get("NAVDECK_ROBOT_NAME", "navdeck"))
    viewer: bool = True  # start the viser 3D view
    max_upload_bytes: int = 64 * 1024 * 1024
    telemetry_hz: float = 15.0
    # Sign-in (app/auth.py). None: required unless bound to localhost; tests force it either way.
    require_auth: bool | None = None
    session_ttl_s: float = 12 * 3600.0  # a sign-in lasts this long (cookie and database row)
    lease_idle_s: float = 15.0  # a lease held over REST only (no teleop socket) frees after this idle time

    def __post_init__(self) -> None:
        self.data_dir = Path(self.data_dir)
        if not self.db_url:
            self.db_url = default_db_url(self.data_dir)
        if self.require_auth is None:
            self.require_auth = not self.is_local

    @property
    def is_local(self) -> bool:
        return self.host in ("127.0.0.1", "localhost", "::1")
