"""Database tables (SQLModel). Schema changes go through Alembic migrations in ``alembic/versions``."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from sqlalchemy import JSON, Column, Index, LargeBinary, text
from sqlmodel import Field, SQLModel


def utcnow() -> datetime:
    return datetime.now(UTC)


class Robot(SQLModel, table=True):
    """One robot (one navdeck process); fleets share a database and tag rows with the robot id."""

    __tablename__ = "robots"
    id: int | None = Field(default=None, primary_key=True)
    name: str = Field(index=True, unique=True, max_length=100)
    profile_name: str = Field(max_length=200)
    profile_toml: str = ""
    driver: str = Field(default="sim", max_length=200)
    created_at: datetime = Field(default_factory=utcnow)
    last_seen_at: datetime = Field(default_factory=utcnow)


class MapRecord(SQLModel, table=True):
    """An occupancy grid map: nav_msgs/OccupancyGrid values stored zlib-compressed (int8 row-major)."""

    __tablename__ = "maps"
    # One row per stock world: fleet processes starting at once race to register them (migration 0004).
    __table_args__ = (
        Index(
            "uq_maps_stock_name",
            "name",
            unique=True,
            sqlite_where=text("is_stock"),
            postgresql_where=text("is_stock"),
        ),
    )
    id: int | None = Field(default=None, primary_key=True)
    name: str = Field(index=True, max_length=200)
    resolution: float
    origin_x: float = 0.0
    origin_y: float = 0.0
    origin_yaw: float = 0.0
    width: int
    height: int
    data: bytes = Field(sa_column=Column(LargeBinary, nullable=False))
    thumbnail_png: bytes = Field(default=b"", sa_column=Column(LargeBinary, nullable=False))
    source: str = Field(default="import", max_length=50)  # stock | slam | import
    is_stock: bool = False
    robot_id: int | None = Field(default=None, foreign_key="robots.id", index=True)
    run_id: int | None = Field(default=None, index=True)
    created_at: datetime = Field(default_factory=utcnow)
    updated_at: datetime = Field(default_factory=utcnow)
    # Versions (migration 0007): an edit saves a new row; ``parent_id`` is the version it was made
    # from (None for an original), ``version`` counts from 1 along the chain.
    parent_id: int | None = Field(default=None, index=True)
    version: int = 1


class Run(SQLModel, table=True):
    """A recorded mapping session or mission."""

    __tablename__ = "runs"
    id: int | None = Field(default=None, primary_key=True)
    kind: str = Field(index=True, max_length=50)  # mapping | navigation | teleop
    robot_id: int | None = Field(default=None, foreign_key="robots.id", index=True)
    profile: str = Field(default="", max_length=200)
    map_id: int | None = Field(default=None, index=True)
    started_at: datetime = Field(default_factory=utcnow, index=True)
    ended_at: datetime | None = None
    outcome: str = Field(default="recording", index=True, max_length=50)
    summary: dict[str, Any] = Field(default_factory=dict, sa_column=Column(JSON, nullable=False))
    # Added by migration 0002 (the recorder keeps them current at every flush):
    robot_name: str = Field(default="", max_length=100)
    duration_s: float = 0.0  # last recorded sample time: a crash still leaves a true duration
    distance_m: float = 0.0
    end_reason: str = Field(default="", max_length=200)


class RunEvent(SQLModel, table=True):
    __tablename__ = "run_events"
    __table_args__ = (Index("ix_run_events_run_id_t", "run_id", "t"),)  # migration 0002
    id: int | None = Field(default=None, primary_key=True)
    run_id: int = Field(foreign_key="runs.id", index=True)
    t: float  # seconds since the run started
    type: str = Field(max_length=50)
    payload: dict[str, Any] = Field(default_factory=dict, sa_column=Column(JSON, nullable=False))


# ---------------------------------------------------------------------------------------------- runs
# Per-run bulk data (migration 0002). Samples and scans are stored as compressed binary chunks of about
# one recorder flush (<= 1 s) each, so a one-hour run is a few thousand rows, a seek reads one chunk,
# and a crash loses at most the chunk being built. Codecs: app/runs/codec.py.


class RunSampleChunk(SQLModel, table=True):
    """Trajectory samples (>= 10 Hz) t0..t1 (s since run start): zlib of a packed numpy record array."""

    __tablename__ = "run_sample_chunks"
    __table_args__ = (Index("ix_run_sample_chunks_run_id_t0", "run_id", "t0"),)
    id: int | None = Field(default=None, primary_key=True)
    run_id: int = Field(foreign_key="runs.id", index=True)
    t0: float
    t1: float
    n: int
    labels: list[str] = Field(default_factory=list, sa_column=Column(JSON, nullable=False))  # behaviours
    data: bytes = Field(sa_column=Column(LargeBinary, nullable=False))


class RunScanChunk(SQLModel, table=True):
    """Laser scans (downsampled, >= 2 Hz) t0..t1: per-scan headers plus ranges in uint16 millimetres."""

    __tablename__ = "run_scan_chunks"
    __table_args__ = (Index("ix_run_scan_chunks_run_id_t0", "run_id", "t0"),)
    id: int | None = Field(default=None, primary_key=True)
    run_id: int = Field(foreign_key="runs.id", index=True)
    t0: float
    t1: float
    n: int
    data: bytes = Field(sa_column=Column(LargeBinary, nullable=False))


class RunPlan(SQLModel, table=True):
    """A global plan (nav_msgs/Path, map frame) as it was from ``t`` until the next one."""

    __tablename__ = "run_plans"
    __table_args__ = (Index("ix_run_plans_run_id_t", "run_id", "t"),)
    id: int | None = Field(default=None, primary_key=True)
    run_id: int = Field(foreign_key="runs.id", index=True)
    t: float
    n: int
    length_m: float = 0.0
    data: bytes = Field(sa_column=Column(LargeBinary, nullable=False))  # float32 (n, 3) x, y, theta


class RunGoal(SQLModel, table=True):
    """A navigation goal and what became of it (pending | succeeded | failed | canceled)."""

    __tablename__ = "run_goals"
    __table_args__ = (Index("ix_run_goals_run_id_t", "run_id", "t"),)
    id: int | None = Field(default=None, primary_key=True)
    run_id: int = Field(foreign_key="runs.id", index=True)
    t: float
    t_end: float | None = None
    x: float
    y: float
    theta: float
    outcome: str = Field(default="pending", max_length=50)
    reason: str = ""


class RunGrid(SQLModel, table=True):
    """The map as the run saw it from ``t`` (mapping runs store its growth, rate-limited)."""

    __tablename__ = "run_grids"
    __table_args__ = (Index("ix_run_grids_run_id_t", "run_id", "t"),)
    id: int | None = Field(default=None, primary_key=True)
    run_id: int = Field(foreign_key="runs.id", index=True)
    t: float
    version: int = 0
    resolution: float
    origin_x: float = 0.0
    origin_y: float = 0.0
    origin_yaw: float = 0.0
    width: int
    height: int
    data: bytes = Field(sa_column=Column(LargeBinary, nullable=False))  # zlib int8 row-major


# ---------------------------------------------------------------------------------------------- users
# Sign-in (migration 0003, app/auth.py). Passwords and session tokens are stored only as hashes.


class User(SQLModel, table=True):
    """A person who may sign in: ``operator`` drives and edits, ``viewer`` only watches (and e-stops)."""

    __tablename__ = "users"
    id: int | None = Field(default=None, primary_key=True)
    username: str = Field(index=True, unique=True, max_length=64)
    password_hash: str = Field(max_length=400)  # "scrypt$n$r$p$salt_hex$hash_hex"
    role: str = Field(default="viewer", max_length=20)
    created_at: datetime = Field(default_factory=utcnow)


class UserSession(SQLModel, table=True):
    """A signed-in browser: the cookie carries a random token, the table only its SHA-256."""

    __tablename__ = "user_sessions"
    id: int | None = Field(default=None, primary_key=True)
    token_hash: str = Field(index=True, unique=True, max_length=64)
    user_id: int = Field(foreign_key="users.id", index=True)
    created_at: datetime = Field(default_factory=utcnow)
    expires_at: datetime = Field(index=True)


# ---------------------------------------------------------------------------------------------- zones
# Keepout and speed zones of a map (migration 0005, app/zone_store.py): polygons in the map frame.


class ZoneRecord(SQLModel, table=True):
    """A keepout or speed-limit polygon drawn on one map (version); deleted with its map."""

    __tablename__ = "zones"
    id: int | None = Field(default=None, primary_key=True)
    map_id: int = Field(foreign_key="maps.id", index=True, ondelete="CASCADE")
    name: str = Field(max_length=100)
    kind: str = Field(max_length=20)  # keepout | speed
    polygon: list[list[float]] = Field(sa_column=Column(JSON, nullable=False))  # [[x, y], ...] metres
    speed_limit: float | None = None  # speed zones: percent of the profile's max, or m/s
    speed_limit_unit: str = Field(default="percent", max_length=10)  # percent | m/s
    created_at: datetime = Field(default_factory=utcnow)
    updated_at: datetime = Field(default_factory=utcnow)


class PlaceRecord(SQLModel, table=True):
    """A named pose on one map ("dock", "bed 3"): a goal by name (migration 0006)."""

    __tablename__ = "places"
    __table_args__ = (Index("uq_places_map_name", "map_id", "name", unique=True),)
    id: int | None = Field(default=None, primary_key=True)
    map_id: int = Field(foreign_key="maps.id", index=True, ondelete="CASCADE")
    name: str = Field(max_length=100)
    x: float
    y: float
    theta: float = 0.0
    created_at: datetime = Field(default_factory=utcnow)
