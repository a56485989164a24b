"""Zones feature: the active map's keepout and speed zones at work (Nav2 KeepoutFilter, SpeedFilter).

- Keepout: the zones' polygons are rasterized (``nav.costmap.filter_layer``) into a mask over the map
  and handed to navigation, whose global and local costmaps make those cells lethal: planners never
  route through, the controller never enters, a goal inside is refused.
- Speed: each tick the robot's position is tested against the speed zones; the lowest limit of the
  zones it is in becomes ``session.speed_limit``, which every command obeys (navigator, teleop,
  behaviours: ``app.limits.apply_speed_limit``). Telemetry says the limit and which zone sets it.
- Entering or leaving any zone is a ``zone`` event of the run.

The set of zones follows the active map (localization's map listener) and any change made through
the API (``reload``).
"""

from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from app.features.localization import Localization
from app.features.navigation import Navigation
from app.limits import SpeedLimit
from app.zone_store import Zone, ZoneKind, ZoneStore
from nav.costmap.filter_layer import points_in_polygon, rasterize_polygons
from nav.types import OccupancyGrid

if TYPE_CHECKING:
    from app.runtime import Runtime
    from app.session import Session
    from robot.base import SensorFrame

log = logging.getLogger("navdeck")

LOOKAHEAD_PERIODS = 3
"""Control periods of travel added to the braking distance when looking for a speed zone ahead: the
command reaching the base and the pose estimate both lag the true position by about a period."""

ORDER = 150  # after navigation (its map listener runs first, so a new map's mask follows its costmaps)


@dataclass(frozen=True)
class ActiveZones:
    """The zones of the active map, with their vertices as arrays (built once per change)."""

    map_id: int | None
    zones: tuple[Zone, ...] = ()
    vertices: tuple[np.ndarray, ...] = ()

    def layer(self) -> tuple[tuple[str, str, np.ndarray], ...]:
        """(kind, label, vertices) per zone: what the 3D view's Zones layer draws."""
        return tuple((z.kind.value, _label(z), v) for z, v in zip(self.zones, self.vertices, strict=True))


class Zones:
    """The zones stage. ``reload`` is thread-safe (API); ``tick`` runs on the control loop."""

    def __init__(
        self,
        session: Session,
        store: ZoneStore,
        localization: Localization | None,
        navigation: Navigation | None,
    ) -> None:
        self.session = session
        self.store = store
        self.localization = localization
        self.navigation = navigation
        self.max_speed = session.profile.limits.max_vel_x
        self.decel = session.profile.limits.decel_lim_x
        self._lock = threading.Lock()
        self._active = ActiveZones(None)
        self._layer: tuple[tuple[str, str, np.ndarray], ...] = ()
        self._grid: OccupancyGrid | None = None
        self._inside: tuple[int, ...] = ()
        self.speed_limit: SpeedLimit | None = None
        self._limit_zone: Zone | None = None
        if localization is not None:
            localization.add_map_listener(self._on_map)
            if localization.grid is not None:
                self._on_map(localization.grid, getattr(localization, "map_id", None))

    @property
    def active(self) -> ActiveZones:
        return self._active

    @property
    def map_id(self) -> int | None:
        return self._active.map_id

    def _on_map(self, grid: OccupancyGrid, map_id: int | None) -> None:
        self._grid = grid
        self._load(map_id)

    def reload(self, map_id: int) -> None:
        """Zones of ``map_id`` changed: re-apply them if it is the active map."""
        if map_id == self._active.map_id:
            self._load(map_id)

    def _load(self, map_id: int | None) -> None:
        with self._lock:  # two API calls at once must not apply an older set last
            zones = tuple(self.store.for_map(map_id)) if map_id is not None else ()
            self._active = ActiveZones(map_id, zones, tuple(z.vertices() for z in zones))
            self._layer = self._active.layer()
            keepout = [z.vertices() for z in zones if z.kind == ZoneKind.KEEPOUT]
            if self.navigation is not None and self._grid is not None:
                geo = self._grid.geometry
                mask = rasterize_polygons(keepout, geo) if keepout else None
                self.navigation.set_keepout(mask, geo)

    # ------------------------------------------------------------------ the stage (loop thread)
    def tick(self, session: Session, frame: SensorFrame, now: float) -> None:
        active = self._active
        ahead = self._ahead(session)
        inside, coming = [], []
        for z, v in zip(active.zones, active.vertices, strict=True):
            hit = points_in_polygon(ahead, v)
            if hit[0]:
                inside.append(z.id)
            if hit.any():
                coming.append(z)
        if tuple(inside) != self._inside:
            by_id = {z.id: z for z in active.zones}
            for zid in self._inside:
                if zid not in inside and zid in by_id:
                    session.add_event("zone", action="leave", **_zone_fields(by_id[zid]))
            for zid in inside:
                if zid not in self._inside:
                    session.add_event("zone", action="enter", **_zone_fields(by_id[zid]))
            self._inside = tuple(inside)
        self._set_limit(session, coming)

    def _ahead(self, session: Session) -> np.ndarray:
        """The robot's position and points ahead of it along its motion, as far as it needs to slow
        from top speed to a stop plus a few control periods: the limit must be met at the zone's edge,
        not after it (the base decelerates at most at ``decel_lim_x``). The distance uses the top
        speed, not the present one, so that slowing down does not bring the robot "out of reach" and
        let it speed up again. Row 0 is the robot's position."""
        p, v = session.pose, session.velocity
        if math.hypot(v.vx, v.vy) < 1e-3:
            return np.array([[p.x, p.y]])
        top = self.max_speed
        decel = abs(self.decel) if self.decel else 1.0
        reach = top * top / (2.0 * decel) + LOOKAHEAD_PERIODS * top * session.period
        heading = p.theta + math.atan2(v.vy, v.vx)
        s = np.linspace(0.0, reach, 6)
        return np.column_stack((p.x + s * math.cos(heading), p.y + s * math.sin(heading)))

    def _set_limit(self, session: Session, zones: list[Zone]) -> None:
        best: tuple[float, Zone] | None = None
        for z in zones:
            limit = z.limit_mps(self.max_speed)
            if limit is not None and (best is None or limit < best[0]):
                best = (limit, z)
        if best is None:
            self.speed_limit = self._limit_zone = None
        elif best[1] is not self._limit_zone:
            limit, z = best
            how = (
                f"{z.speed_limit:g} % of {self.max_speed:.2f} m/s"
                if z.speed_limit_unit == "percent"
                else "absolute"
            )
            self.speed_limit = SpeedLimit(limit, f"speed zone '{z.name}': {limit:.2f} m/s ({how})")
            self._limit_zone = z
        session.speed_limit = self.speed_limit

    def state(self) -> dict[str, Any]:
        """Telemetry ``zones``: the active map's zone count, the zones the robot is in, the limit."""
        active = self._active
        by_id = {z.id: z for z in active.zones}
        limit = self.speed_limit
        return {
            "map_id": active.map_id,
            "count": len(active.zones),
            "inside": [_zone_fields(by_id[i]) for i in self._inside if i in by_id],
            "speed_limit": None
            if limit is None
            else {
                "linear": round(limit.linear, 3),
                "reason": limit.reason,
                "zone_id": getattr(self._limit_zone, "id", None),
            },
        }

    def snapshot_fields(self, session: Session) -> dict[str, Any] | None:
        # a new tuple on every change: the 3D view redraws only then
        return {"extras": {"zones": self.state(), "zone_layer": self._layer}}

    def close(self) -> None:
        self.session.speed_limit = None


def _label(z: Zone) -> str:
    if z.kind == ZoneKind.KEEPOUT:
        return f"{z.name} (keepout)"
    unit = " %" if z.speed_limit_unit.value == "percent" else " m/s"
    return f"{z.name} ({z.speed_limit:g}{unit})"


def _zone_fields(z: Zone) -> dict[str, Any]:
    out: dict[str, Any] = {"zone_id": z.id, "name": z.name, "kind": z.kind.value}
    if z.kind == ZoneKind.SPEED:
        out["speed_limit"] = z.speed_limit
        out["speed_limit_unit"] = z.speed_limit_unit.value
    return out


def setup(runtime: Runtime) -> Zones:
    zones = Zones(
        runtime.session,
        ZoneStore(runtime.engine),
        runtime.find_feature(Localization),
        runtime.find_feature(Navigation),
    )
    runtime.session.add_stage(zones)
    return zones
