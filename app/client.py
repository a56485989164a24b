"""A small typed Python client for navdeck's API (issue 22): the mission flow from a script.

    from app.client import NavdeckClient

    nd = NavdeckClient("http://robot:8000")
    m = nd.import_map(Path("flat.yaml"))                 # map_server YAML + its image
    nd.activate_map(m.id)
    nd.set_initial_pose(0.5, 0.5, 0.0)
    mission = nd.start_mission([(3.0, 1.2, -1.57), (1.0, 1.0, 0.0)])
    done = nd.wait_mission(mission.id, timeout_s=300)    # long-poll, no polling loop
    with nd.teleop() as drive:                           # /ws/teleop (the deadman: stop when closed)
        drive.send(0.2, 0.0, 0.0)

Answers are the server's own response models (``app.api``), so a client and the server cannot
disagree on a field; every error is raised as ``ApiError`` carrying the RFC 9457 ``Problem``. Only the
standard library and ``websockets`` (a dependency of navdeck) are used: no HTTP client to install.
Missions run on their own: a script may start one and exit (see the lease rules in docs/api.md).
"""

from __future__ import annotations

import json
import time
import urllib.error
import urllib.parse
import urllib.request
import uuid
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

from pydantic import BaseModel
from websockets.sync.client import ClientConnection, connect

from app.api.problems import Problem
from app.api.routes.control import ControlOut
from app.api.routes.localization import LocalizationOut
from app.api.routes.maps import ActivatedOut, MapOut, MapPage
from app.api.routes.missions import MissionOut, MissionPage
from app.api.routes.robot import RobotOut
from app.api.routes.runs import RunDetail, RunOut
from app.api.schemas import Page
from app.features.missions import TERMINAL, MissionState
from maps.mapio import read_map_metadata

M = TypeVar("M", bound=BaseModel)
PoseLike = tuple[float, float] | tuple[float, float, float]


class ApiError(RuntimeError):
    """A non-2xx answer: ``status`` and the server's problem details (``problem.type``, ``detail``,
    extensions such as ``nearest_free`` or ``allowed`` in ``problem.model_extra``)."""

    def __init__(self, status: int, problem: Problem) -> None:
        super().__init__(f"{status} {problem.title}: {problem.detail}")
        self.status = status
        self.problem = problem

    @property
    def kind(self) -> str:
        """The slug of the problem type (``goal-rejected``, ``map-mismatch``...)."""
        return self.problem.type.rsplit("/", 1)[-1]


class Teleop:
    """An open ``/ws/teleop``: ``hello`` is the server's greeting (``driving`` says whether this
    socket holds control). Closing it stops the robot (the deadman)."""

    def __init__(self, ws: ClientConnection) -> None:
        self.ws = ws
        self.hello: dict[str, Any] = json.loads(ws.recv(timeout=10))

    def send(self, vx: float, vy: float = 0.0, wz: float = 0.0) -> None:
        """A geometry_msgs/Twist: m/s forward and left, rad/s CCW."""
        self.ws.send(
            json.dumps({"linear": {"x": vx, "y": vy, "z": 0.0}, "angular": {"x": 0, "y": 0, "z": wz}})
        )

    def take_control(self) -> dict[str, Any]:
        """Take the lease from whoever holds it; answers the ``control`` message."""
        self.ws.send(json.dumps({"type": "take_control"}))
        return self.receive("control")

    def receive(self, kind: str | None = None, timeout_s: float = 10.0) -> dict[str, Any]:
        """The next message (of type ``kind`` when given; others are skipped)."""
        deadline = time.monotonic() + timeout_s
        while True:
            msg = json.loads(self.ws.recv(timeout=max(0.01, deadline - time.monotonic())))
            if kind is None or msg.get("type") == kind:
                return msg


class NavdeckClient:
    """Blocking client of one navdeck server. ``timeout_s`` bounds every request (a long-poll adds
    its ``wait`` to it)."""

    def __init__(self, base_url: str, *, timeout_s: float = 30.0) -> None:
        self.base_url = base_url.rstrip("/")
        self.timeout_s = timeout_s

    # ------------------------------------------------------------------ transport
    def request(
        self,
        method: str,
        path: str,
        *,
        json_body: Any = None,
        params: dict[str, Any] | None = None,
        data: bytes | None = None,
        content_type: str | None = None,
        timeout_s: float | None = None,
    ) -> tuple[int, dict[str, str], bytes]:
        url = self.base_url + path
        if params:
            url += "?" + urllib.parse.urlencode({k: v for k, v in params.items() if v is not None})
        headers = {"accept": "application/json"}
        if json_body is not None:
            data, content_type = json.dumps(json_body).encode(), "application/json"
        if content_type:
            headers["content-type"] = content_type
        req = urllib.request.Request(url, data=data, method=method, headers=headers)
        try:
            with urllib.request.urlopen(req, timeout=timeout_s or self.timeout_s) as resp:
                return resp.status, dict(resp.headers.items()), resp.read()
        except urllib.error.HTTPError as err:
            body = err.read()
            try:
                problem = Problem.model_validate_json(body)
            except ValueError:
                problem = Problem(
                    title=err.reason or "error", status=err.code, detail=body.decode(errors="replace")
                )
            raise ApiError(err.code, problem) from None

    def _get(self, model: type[M], path: str, **kw: Any) -> M:
        return model.model_validate_json(self.request("GET", path, **kw)[2])

    def _post(self, model: type[M], path: str, **kw: Any) -> M:
        return model.model_validate_json(self.request("POST", path, **kw)[2])

    # ------------------------------------------------------------------ robot
    def robot(self) -> RobotOut:
        return self._get(RobotOut, "/api/robot")

    def set_mode(self, mode: str) -> RobotOut:
        return self._post(RobotOut, "/api/robot/mode", json_body={"mode": mode})

    def estop(self) -> RobotOut:
        return self._post(RobotOut, "/api/robot/estop")

    def reset(self) -> RobotOut:
        return self._post(RobotOut, "/api/robot/reset")

    def acquire_control(self, *, take_over: bool = False) -> ControlOut:
        return self._post(ControlOut, "/api/control/acquire", json_body={"take_over": take_over})

    def release_control(self) -> ControlOut:
        return self._post(ControlOut, "/api/control/release")

    # ------------------------------------------------------------------ maps
    def maps(self, *, limit: int = 50, offset: int = 0) -> MapPage:
        return self._get(MapPage, "/api/maps", params={"limit": limit, "offset": offset})

    def import_map(self, yaml_path: Path, *, name: str | None = None) -> MapOut:
        """Upload a map_server map: the YAML and the image it names (next to it)."""
        image = yaml_path.parent / read_map_metadata(yaml_path).image
        parts = [("yaml", yaml_path.name, yaml_path.read_bytes()), ("image", image.name, image.read_bytes())]
        body, ctype = _multipart(parts, {"name": name} if name else {})
        return self._post(MapOut, "/api/maps/import", data=body, content_type=ctype)

    def activate_map(self, map_id: int) -> ActivatedOut:
        return self._post(ActivatedOut, f"/api/maps/{map_id}/activate")

    def delete_map(self, map_id: int) -> None:
        self.request("DELETE", f"/api/maps/{map_id}")

    def export_map(self, map_id: int) -> tuple[bytes, bytes]:
        """(map.yaml, map.pgm) as map_saver writes them."""
        return (
            self.request("GET", f"/api/maps/{map_id}/map.yaml")[2],
            self.request("GET", f"/api/maps/{map_id}/map.pgm")[2],
        )

    # ------------------------------------------------------------------ localization
    def localization(self) -> LocalizationOut:
        return self._get(LocalizationOut, "/api/localization")

    def set_initial_pose(self, x: float, y: float, theta: float = 0.0) -> LocalizationOut:
        return self._post(
            LocalizationOut, "/api/localization/initial_pose", json_body={"x": x, "y": y, "theta": theta}
        )

    # ------------------------------------------------------------------ missions
    def start_mission(self, goals: Sequence[PoseLike], *, controller: str | None = None) -> MissionOut:
        """Drive through ``goals`` ((x, y) or (x, y, theta), map frame) in order."""
        body: dict[str, Any] = {"goals": [_pose(g) for g in goals]}
        if controller is not None:
            body["controller"] = controller
        return self._post(MissionOut, "/api/missions", json_body=body)

    def mission(self, mission_id: str, *, wait_s: float = 0.0, version: int | None = None) -> MissionOut:
        """The mission; with ``wait_s`` the server answers at its next change (long-poll)."""
        params = {"wait": wait_s, "version": version} if wait_s else None
        return self._get(
            MissionOut, f"/api/missions/{mission_id}", params=params, timeout_s=self.timeout_s + wait_s
        )

    def missions(self, *, limit: int = 50, offset: int = 0) -> MissionPage:
        return self._get(MissionPage, "/api/missions", params={"limit": limit, "offset": offset})

    def wait_mission(
        self, mission_id: str, *, until: frozenset[MissionState] = TERMINAL, timeout_s: float = 600.0
    ) -> MissionOut:
        """Long-poll until the mission's state is one of ``until`` (default: it ended); TimeoutError
        after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        m = self.mission(mission_id)
        while m.state not in until:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"mission {mission_id} still {m.state.value} after {timeout_s:g} s")
            m = self.mission(mission_id, wait_s=min(30.0, left), version=m.version)
        return m

    def cancel_mission(self, mission_id: str) -> MissionOut:
        return self._post(MissionOut, f"/api/missions/{mission_id}/cancel")

    # ------------------------------------------------------------------ runs
    def runs(self, **filters: Any) -> Page[RunOut]:
        return self._get(Page[RunOut], "/api/runs", params=filters)

    def run(self, run_id: int) -> RunDetail:
        return self._get(RunDetail, f"/api/runs/{run_id}")

    def export_run(self, run_id: int, fmt: str = "json") -> bytes:
        """The run as ``json``, ``csv`` or ``mcap`` (a run still recording is exported so far)."""
        return self.request("GET", f"/api/runs/{run_id}/export.{fmt}")[2]

    # ------------------------------------------------------------------ teleop
    @contextmanager
    def teleop(self, name: str = "navdeck.client") -> Iterator[Teleop]:
        """``/ws/teleop``: drive with ``send``; leaving the block closes the socket and stops."""
        ws_url = (
            "ws" + self.base_url.removeprefix("http") + "/ws/teleop?" + urllib.parse.urlencode({"name": name})
        )
        with connect(ws_url, open_timeout=self.timeout_s, max_size=1 << 20) as ws:
            yield Teleop(ws)


def _pose(g: PoseLike) -> dict[str, float]:
    return {"x": float(g[0]), "y": float(g[1]), "theta": float(g[2]) if len(g) > 2 else 0.0}


def _multipart(files: list[tuple[str, str, bytes]], fields: dict[str, str]) -> tuple[bytes, str]:
    """multipart/form-data (RFC 7578) for the map upload."""
    boundary = uuid.uuid4().hex
    out = bytearray()
    for key, value in fields.items():
        out += f'--{boundary}\r\nContent-Disposition: form-data; name="{key}"\r\n\r\n{value}\r\n'.encode()
    for key, filename, content in files:
        out += (
            f'--{boundary}\r\nContent-Disposition: form-data; name="{key}"; filename="{filename}"\r\n'
            "Content-Type: application/octet-stream\r\n\r\n"
        ).encode()
        out += content + b"\r\n"
    out += f"--{boundary}--\r\n".encode()
    return bytes(out), f"multipart/form-data; boundary={boundary}"
