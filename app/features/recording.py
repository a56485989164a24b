"""Feature: the always-on run recorder (app/recorder.py) and the replay player for this runtime.

Set up after the pipeline features (high ORDER) so it is closed first: the open run is finished as
``stopped`` while the rest is still running. Runs a crash left open are closed before the loop starts.
"""

from __future__ import annotations

import logging
import threading
from typing import TYPE_CHECKING

from app.recorder import Recorder
from app.runs.replay import ReplayPlayer
from app.runs.store import RunsStore
from app.viewer.scene import Viewer

if TYPE_CHECKING:
    from app.runtime import Runtime

ORDER = 900
log = logging.getLogger("navdeck.runs")


def current_map_id(runtime: Runtime) -> int | None:
    """The map the robot runs on: ``runtime.active_map_id`` when a feature sets one, else the stock
    map of the simulated world."""
    if runtime.active_map_id is not None:
        return runtime.active_map_id
    if runtime.world_name:
        info = runtime.maps.find(runtime.world_name, stock=True)
        return None if info is None else info.id
    return None


class Recording:
    """This runtime's recorder, runs store and (created on first use) replay player."""

    def __init__(self, runtime: Runtime) -> None:
        self.runtime = runtime
        self.store = RunsStore(runtime.engine)
        self.recorder = Recorder(
            runtime.session,
            self.store,
            profile_name=runtime.profile.name,
            map_id=lambda: current_map_id(runtime),
        )
        self._replay: ReplayPlayer | None = None
        self._lock = threading.Lock()

    @property
    def replay(self) -> ReplayPlayer:
        """The replay player; its own 3D view starts with it when the server runs a viewer."""
        with self._lock:
            if self._replay is None:
                player = ReplayPlayer(self.store, footprint=self.runtime.profile.footprint_polygon())
                if self.runtime.settings.viewer:
                    player.viewer = Viewer(player.bus)
                    player.viewer.start()
                self._replay = player
            return self._replay

    @property
    def replay_if_started(self) -> ReplayPlayer | None:
        return self._replay

    def close(self) -> None:
        if self._replay is not None:
            self._replay.close()
        self.recorder.close()


def setup(runtime: Runtime) -> Recording:
    rec = Recording(runtime)
    rec.recorder.start()
    return rec
