"""The websocket protocol as models: ``/ws/telemetry`` (server -> client snapshots) and ``/ws/teleop``
(client -> server Twists and control requests; server -> client ``hello``, ``control``, ``error``).

Served as JSON Schema next to ``/openapi.json`` (``GET /api/schemas/ws/{name}.json``, listed at
``/api/schemas/ws``) and validated against real traffic by tests/test_api_ws_schema.py; docs/api.md
explains the protocol.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field, RootModel

from app.api.routes.mapping import MappingOut
from app.api.schemas import ControlState, Health, NavigationOut, OpenOut, Out, Pose, Timestamp, Twist
from app.auth import Role
from app.modes import Mode


class ScanMsg(Out):
    """A downsampled sensor_msgs/LaserScan (every k-th beam)."""

    stamp_monotonic_s: float = Field(description="s on the control loop's clock (see `stamp_monotonic_s`)")
    angle_min: float = Field(description="rad, laser frame")
    angle_increment: float = Field(description="rad between the beams sent")
    range_max: float = Field(description="m")
    ranges: list[float | None] = Field(description="m; null where there is no return")


class LocalizationMsg(Out):
    quality: float = Field(description="0..1, the scan's fit at the estimate")
    covariance: list[list[float]] = Field(description="3x3 of x (m), y (m), theta (rad)")
    particles: int
    localized: bool
    converged: bool
    map_mismatch: bool
    match_score: float
    global_running: bool


class ContactMsg(Out):
    in_contact: bool
    with_: str | None = Field(alias="with", description="`obstacle`, `person:<id>` or null")
    nearest_m: float | None = Field(description="nearest reading to the footprint, m")
    free: list[str] | None = Field(description="elementary motions with room: forward, back, turn left...")


class ZoneRef(Out):
    zone_id: int
    name: str
    kind: Literal["keepout", "speed"]
    speed_limit: float | None = None
    speed_limit_unit: Literal["percent", "m/s"] | None = None


class SpeedLimitMsg(Out):
    linear: float = Field(description="m/s: the largest linear speed allowed now")
    reason: str = Field(description="which zone sets it, for the operator")
    zone_id: int | None


class ZonesMsg(Out):
    """The active map's zones at work (issue 19): the zones the robot is in, the speed limit."""

    map_id: int | None
    count: int = Field(description="zones on the active map")
    inside: list[ZoneRef]
    speed_limit: SpeedLimitMsg | None = Field(description="a speed zone's limit in force (or just ahead)")


class Notice(OpenOut):
    """An operator event (a refusal or a notice) meant for this dashboard tab."""

    type: Literal["refused", "notice"]


class TelemetryMessage(Out):
    """One ``/ws/telemetry`` frame (at ``?hz=`` 1..20; ``?scan=0`` leaves ``scan`` out)."""

    time: Timestamp = Field(description="wall clock when the frame was sent, ISO 8601 UTC")
    stamp_monotonic_s: float = Field(
        description="s on the control loop's clock when the snapshot was taken: monotonic, origin "
        "arbitrary (the process's monotonic clock, or the simulator's virtual clock): use differences"
    )
    seq: int = Field(description="snapshot number, increasing")
    mode: Mode
    allowed_modes: list[Mode]
    pose: Pose = Field(description="map frame")
    odom_pose: Pose = Field(description="odom frame")
    velocity: Twist
    command: Twist
    clamped: list[str]
    estop: bool
    fault: str | None
    behavior: str | None = Field(description="the navigation behaviour running (viewer palette name)")
    profile_name: str = Field(description="the robot profile (`GET /api/robot` has it whole)")
    health: Health
    goal: Pose | None
    navigation: NavigationOut | None = None
    localization: LocalizationMsg | None = None
    mapping: MappingOut | None = None
    exploration: OpenOut | None = Field(
        None, description="frontier exploration, when that feature runs (`GET /api/exploration`'s shape)"
    )
    contact: ContactMsg | None = None
    zones: ZonesMsg | None = None
    scan: ScanMsg | None = None
    control: ControlState
    notices: list[Notice]


# ------------------------------------------------------------------------------ teleop
class Vec(BaseModel):
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


class TwistIn(BaseModel):
    """geometry_msgs/Twist: ``linear.x``/``linear.y`` m/s, ``angular.z`` rad/s; missing parts are 0.
    Send at ~10 Hz while driving: a socket that stops sending, or closes, stops the robot."""

    model_config = {"extra": "forbid"}
    linear: Vec = Field(default_factory=Vec)
    angular: Vec = Field(default_factory=Vec)


class ControlRequest(Out):
    type: Literal["take_control", "release_control"]


class TeleopIn(RootModel[TwistIn | ControlRequest]):
    """What a client sends on ``/ws/teleop`` (JSON text frames of at most 4096 bytes)."""


class Hello(Out):
    type: Literal["hello"]
    client_id: str = Field(description="this socket's client id")
    name: str
    role: Role
    control: ControlState
    driving: bool = Field(description="this socket holds control")


class ControlMsg(Out):
    type: Literal["control"]
    driving: bool
    control: ControlState


class TeleopError(OpenOut):
    """A refused message; the robot is stopped when the command itself was bad."""

    type: Literal["error"]
    error: str
    status: int | None = None
    mode: Mode | None = None
    allowed: list[str] | None = None
    control: ControlState | None = None
    refused: dict[str, Any] | None = Field(None, description="per component: value and bound (sanity)")


class TeleopOut(RootModel[Hello | ControlMsg | TeleopError]):
    """What the server sends on ``/ws/teleop``: ``hello`` first, then ``control`` / ``error``."""


SCHEMAS: dict[str, type[BaseModel]] = {
    "telemetry": TelemetryMessage,
    "teleop-in": TeleopIn,
    "teleop-out": TeleopOut,
}
"""Name -> model of each message kind; ``/api/schemas/ws/{name}.json`` serves its JSON Schema."""


def json_schema(name: str) -> dict[str, Any]:
    """The JSON Schema (2020-12) of one message kind, self-contained (``$defs``)."""
    schema = SCHEMAS[name].model_json_schema(by_alias=True, mode="serialization")
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": f"/api/schemas/ws/{name}.json",
        **schema,
    }
