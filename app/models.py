"""Database tables (SQLModel). Schema changes go through Alembic migrations in ``alembic/versions``."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from sqlalchemy import JSON, Column, LargeBinary
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


class RunEvent(SQLModel, table=True):
    __tablename__ = "run_events"
    id: int | None = Field(default=None, primary_key=True)
    run_id: int = Field(foreign_key="runs.id", index=True)
    t: float  # seconds since the run started
    type: str = Field(max_length=50)
    payload: dict[str, Any] = Field(default_factory=dict, sa_column=Column(JSON, nullable=False))
