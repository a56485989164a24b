"""Places (named poses on a map) and routes through them (issue 19).

A place belongs to one map; goals name places of the active map (``POST /api/navigation/goals
{"place": "dock"}``, unknown names 422). A route is an ordered list of places and poses run once or
``repeat`` times as one mission, so each leg has its own outcome in the mission and the run's events.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, Query, Response
from pydantic import Field

from app.api.deps import ActorDep, MapGridDep, MapInfoDep, RuntimeDep, StrictModel
from app.api.problems import ProblemError
from app.api.routes.maps import active_map_id
from app.api.routes.missions import MissionOut, MissionsDep, PoseIn, mission_out, start_mission
from app.api.schemas import ERRORS, DbId, Out, Page, Pose
from app.place_store import Place, PlaceExists, PlaceStore
from nav.types import Pose2D

router = APIRouter(tags=["places"])

MAX_ROUTE_GOALS = 1000


class PlaceIn(StrictModel):
    """A named pose in the map frame (REP-103: metres, radians CCW)."""

    name: str = Field(min_length=1, max_length=100, pattern=r"\S")
    x: float = Field(description="m")
    y: float = Field(description="m")
    theta: float = Field(0.0, description="rad")


class PlaceOut(Out):
    id: int
    map_id: int
    name: str
    pose: Pose


class PlacePage(Page[PlaceOut]):
    """A map's places, by name."""

    map_id: int


class RouteIn(StrictModel):
    """Stops in order: place names (of the active map) or poses; the whole list ``repeat`` times, or
    as a patrol loop until the mission is cancelled (``patrol: true`` or ``repeat: 0``)."""

    stops: list[str | PoseIn] = Field(min_length=1, max_length=200)
    repeat: int = Field(1, ge=0, le=100, description="how many times to run the route; 0: a patrol")
    patrol: bool = Field(False, description="run the route in a loop until the mission is cancelled")
    controller: Literal["dwa", "teb"] | None = None

    @property
    def is_patrol(self) -> bool:
        return self.patrol or self.repeat == 0


def get_places(rt: RuntimeDep) -> PlaceStore:
    return PlaceStore(rt.engine)


PlacesDep = Annotated[PlaceStore, Depends(get_places)]


def place_out(p: Place) -> PlaceOut:
    return PlaceOut(
        id=p.id, map_id=p.map_id, name=p.name, pose=Pose(x=p.pose.x, y=p.pose.y, theta=p.pose.theta)
    )


def resolve_place(rt: Any, name: str) -> Pose2D:
    """The pose of a place of the active map; 422 ``unknown-place`` (with the known names) if none."""
    map_id = active_map_id(rt)
    store = PlaceStore(rt.engine)
    place = store.find(map_id, name) if map_id is not None else None
    if place is None:
        known = [p.name for p in store.for_map(map_id)] if map_id is not None else []
        raise ProblemError(
            422, f"no place named {name!r} on the active map", kind="unknown-place", places=known
        )
    return place.pose


@router.get(
    "/api/maps/{map_id}/places",
    response_model=PlacePage,
    summary="The places of a map, by name",
    responses=ERRORS(s404="no such map"),
)
def list_places(
    map_id: DbId,
    _map: MapInfoDep,
    places: PlacesDep,
    limit: Annotated[int, Query(ge=1, le=500)] = 100,
    offset: Annotated[int, Query(ge=0)] = 0,
) -> PlacePage:
    found = places.for_map(map_id)
    items = [place_out(p) for p in found[offset : offset + limit]]
    return PlacePage(total=len(found), limit=limit, offset=offset, items=items, map_id=map_id)


@router.post(
    "/api/maps/{map_id}/places",
    status_code=201,
    response_model=PlaceOut,
    summary="Name a pose on a map",
    responses=ERRORS(
        s404="no such map", s409="the map already has a place of that name", s422="the pose is off the map"
    ),
)
def create_place(
    map_id: DbId, body: PlaceIn, grid: MapGridDep, places: PlacesDep, response: Response
) -> PlaceOut:
    geo = grid.geometry
    rows, cols = geo.world_to_cell(Pose2D(body.x, body.y).as_array()[None, :2])
    if not geo.in_bounds(rows, cols)[0]:
        raise ProblemError(422, f"({body.x:.3f}, {body.y:.3f}) is off the map", kind="invalid-pose")
    try:
        p = places.add(map_id, body.name.strip(), Pose2D(body.x, body.y, body.theta))
    except PlaceExists as exc:
        raise ProblemError(409, str(exc), kind="place-exists") from None
    response.headers["Location"] = f"/api/places/{p.id}"
    return place_out(p)


@router.delete(
    "/api/places/{place_id}",
    status_code=204,
    summary="Delete a place",
    responses=ERRORS(s404="no such place"),
)
def delete_place(place_id: DbId, places: PlacesDep) -> Response:
    if not places.delete(place_id):
        raise ProblemError(404, f"no place with id {place_id}", kind="not-found")
    return Response(status_code=204)


@router.post(
    "/api/routes/run",
    status_code=201,
    response_model=MissionOut,
    summary="Run a route: places (by name) and poses in order, `repeat` times or as a patrol, as one mission",
    description="Each leg is a goal of the mission with its own state and reason "
    "(`GET /api/missions/{id}`) and a `mission_leg` event of the run; cancel it like any mission. "
    "A patrol (`patrol: true` or `repeat: 0`, two stops or more) runs until cancelled: the next lap "
    "is appended to the mission's goals when the robot starts the last one queued.",
    responses=ERRORS(
        s409="navigation cannot run now (not localized, e-stop, mode)",
        s422="an unknown place name, a stop off the map or in an obstacle",
    ),
)
def run_route(
    body: RouteIn, rt: RuntimeDep, missions: MissionsDep, actor: ActorDep, response: Response
) -> MissionOut:
    legs = [resolve_place(rt, s) if isinstance(s, str) else Pose2D(s.x, s.y, s.theta) for s in body.stops]
    if body.is_patrol and len(legs) < 2:
        raise ProblemError(422, "a patrol needs at least two stops", kind="invalid-request")
    goals = legs if body.is_patrol else legs * body.repeat
    if len(goals) > MAX_ROUTE_GOALS:
        raise ProblemError(422, f"a route runs at most {MAX_ROUTE_GOALS} legs", kind="invalid-request")
    m = start_mission(missions, goals, body.controller, actor, patrol=body.is_patrol)
    response.headers["Location"] = f"/api/missions/{m.id}"
    return mission_out(missions, m)
