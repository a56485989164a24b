"""The robots table: each navdeck process registers its robot at start, so a fleet sharing one database
(PostgreSQL, docs/deployment.md) can tell every robot's maps and runs apart by ``robot_id``.

Registration is an upsert by name (``NAVDECK_ROBOT_NAME``): a restart finds its own row again and
refreshes the profile and ``last_seen_at``. Runs carry ``robot_name`` from the recorder; a mapper hook
fills their ``robot_id`` from it, so every writer tags rows without knowing about robot ids.
"""

from __future__ import annotations

from sqlalchemy import event, select
from sqlalchemy.engine import Engine
from sqlalchemy.exc import IntegrityError
from sqlmodel import Session

from app.models import Robot, Run, utcnow


def register_robot(
    engine: Engine, name: str, profile_name: str, profile_toml: str = "", driver: str = "sim"
) -> int:
    """Insert or refresh this robot's row; returns its id. Safe when two processes race on one name
    (the unique index decides; the loser re-reads the winner's row)."""
    for _ in range(2):
        with Session(engine, expire_on_commit=False) as s:
            row = s.scalars(select(Robot).where(Robot.name == name)).first()
            if row is None:
                row = Robot(name=name, profile_name=profile_name, profile_toml=profile_toml, driver=driver)
            else:
                row.profile_name, row.profile_toml, row.driver = profile_name, profile_toml, driver
                row.last_seen_at = utcnow()
            s.add(row)
            try:
                s.commit()
            except IntegrityError:
                s.rollback()
                continue
            assert row.id is not None
            return row.id
    raise RuntimeError(f"could not register robot {name!r}")


@event.listens_for(Run, "before_insert")
def _tag_run_with_robot(_mapper, connection, target: Run) -> None:
    """A run written with only ``robot_name`` gets that robot's id (one indexed look-up per run)."""
    if target.robot_id is None and target.robot_name:
        target.robot_id = connection.execute(
            select(Robot.id).where(Robot.name == target.robot_name)
        ).scalar_one_or_none()
