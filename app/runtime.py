"""Everything one navdeck process runs, built from Settings and torn down in order."""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from types import ModuleType
from typing import TypeVar

from sqlalchemy.engine import Engine

from app.control import ControlLease
from app.db import make_engine, migrate
from app.drivers import DriverBundle, make_driver
from app.errors import FeatureUnavailable
from app.features import discover
from app.map_store import MapStore
from app.robots import register_robot
from app.session import Session, SessionOptions
from app.settings import Settings
from app.viewer.scene import Viewer
from maps.mapio import load_map_yaml
from maps.stock import available_worlds, stock_world_path
from nav.types import Pose2D
from robot.clock import Clock, RealClock
from robot.profiles import RobotProfile, load_profile

log = logging.getLogger("navdeck")

FeatureT = TypeVar("FeatureT")


@dataclass
class Runtime:
    settings: Settings
    profile: RobotProfile
    engine: Engine
    maps: MapStore
    session: Session
    lease: ControlLease = field(default_factory=ControlLease)
    viewer: Viewer | None = None
    world_name: str | None = None
    robot_id: int | None = None  # this robot's row in the robots table (app/robots.py)
    active_map_id: int | None = None  # the map set by localization or activation (None: the world's)
    features: dict[str, object] = field(default_factory=dict)  # feature module name -> its handle
    # What a click-and-drag in the 3D view does, by kind ("goal", "initial_pose"); set by features.
    pose_input_handlers: dict[str, Callable[[Pose2D], None]] = field(default_factory=dict)

    def find_feature(self, kind: type[FeatureT]) -> FeatureT | None:
        """The running feature of this type, or None when this server did not set it up."""
        return next((handle for handle in self.features.values() if isinstance(handle, kind)), None)

    def feature(self, kind: type[FeatureT]) -> FeatureT:
        """The running feature of this type; ``FeatureUnavailable`` (the API's 503) without it."""
        found = self.find_feature(kind)
        if found is None:
            raise FeatureUnavailable(kind)
        return found

    @classmethod
    def build(cls, settings: Settings, clock: Clock | None = None) -> Runtime:
        profile = load_profile(settings.profile)
        clock = clock or RealClock()
        bundle = make_driver(settings.robot, profile, settings.world, clock, settings.seed)
        try:
            engine = make_engine(settings.db_url)
            migrate(engine)
            robot_id = register_robot(engine, settings.robot_name, profile.name, driver=settings.robot)
            maps = MapStore(engine)
            _register_stock_maps(maps)
        except Exception:
            bundle.driver.close()
            raise
        session = Session(
            bundle.driver,
            clock=clock,
            grid=bundle.grid,
            start_pose=bundle.start_pose,
            options=session_options(settings, bundle),
            robot_name=settings.robot_name,
        )
        return cls(settings, profile, engine, maps, session, world_name=bundle.world_name, robot_id=robot_id)

    def setup_features(self, modules: Iterable[ModuleType]) -> None:
        """Set up each feature module on this runtime, keyed by its module name (``start`` does it for
        every discovered feature; tests for the few they need, without the wall-clock thread)."""
        for module in modules:
            self.features[module.__name__.rsplit(".", 1)[-1]] = module.setup(self)

    def start(self) -> None:
        self.setup_features(discover())
        self.session.start()
        if self.settings.viewer:
            self.viewer = Viewer(
                self.session.bus, footprint=self.profile.footprint_polygon(), on_pose_input=self.on_pose_input
            )
            self.viewer.start()

    def on_pose_input(self, kind: str, pose: Pose2D, tab: str = "") -> str | None:
        """A pose set in the 3D view of browser tab ``tab`` (viser's thread): hand it to the feature that
        handles this kind. A refusal is returned (the view shows it) and recorded as an event that the
        tab's dashboard shows in its messages (telemetry ``notices``)."""
        handler = self.pose_input_handlers.get(kind)
        label = kind.replace("_", " ")
        reason = f"nothing handles a {label} yet" if handler is None else None
        if handler is not None:
            try:
                handler(pose)
            except Exception as exc:  # a refusal (e.g. goal in a wall) is shown, never raised into viser
                reason = str(exc)
        if reason is None:
            if kind == "initial_pose":
                self.session.add_event(
                    "notice",
                    text=f"initial pose set at x {pose.x:.2f} y {pose.y:.2f}: "
                    "a click in the 3D view now sets a goal",
                    tab=tab,
                    click_mode="goal",
                )
            return None
        self.session.add_event("refused", what=kind, reason=reason, via="3d view", tab=tab)
        return reason

    def close(self) -> None:
        for name, handle in reversed(list(self.features.items())):
            if handle is not None and hasattr(handle, "close"):
                try:
                    handle.close()
                except Exception:
                    log.exception("feature %s close failed", name)
        if self.viewer is not None:
            try:
                self.viewer.stop()
            except Exception:
                log.exception("viewer stop failed")
        self.session.close()
        self.engine.dispose()


def _register_stock_maps(maps: MapStore) -> None:
    maps.register_stock({name: stock_world_path(name) for name in available_worlds()}, load_map_yaml)


def session_options(settings: Settings, bundle: DriverBundle) -> SessionOptions:
    """The session's options for this robot: the control rate, and a lidar silence limit no shorter
    than the one the driver was configured with."""
    options = SessionOptions(rate_hz=settings.rate_hz)
    if bundle.lidar_timeout is None:
        return options
    return dataclasses.replace(options, lidar_timeout=max(options.lidar_timeout, bundle.lidar_timeout))
