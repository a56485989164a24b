"""Everything stored for one run, loaded once for an exporter (a run still recording is exported as
recorded so far, flagged ``partial``)."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

import numpy as np

from app.runs.store import RunsStore, utc_aware
from nav.types import LaserScan, OccupancyGrid


@dataclass(frozen=True)
class RunData:
    run: dict
    samples: np.ndarray  # SAMPLE_DTYPE
    labels: list[str]  # behaviour names the samples' codes index
    scans: list[tuple[float, LaserScan]]
    plans: list[tuple[float, np.ndarray]]
    grids: list[tuple[float, int, OccupancyGrid]]
    events: list[dict]
    goals: list[dict]

    @property
    def partial(self) -> bool:
        """True while the run is still recording: the export holds what was recorded so far."""
        return self.run["outcome"] == "recording"

    @property
    def start(self) -> datetime:
        return utc_aware(datetime.fromisoformat(self.run["started_at"].replace("Z", "+00:00")))

    def stamp_ns(self, t: float) -> int:
        """Run time (s) -> UNIX nanoseconds (ROS time of the recording)."""
        return round(self.start.timestamp() * 1e9) + round(t * 1e9)

    @property
    def laser_pose(self) -> tuple[float, float, float]:
        lp = self.run.get("summary", {}).get("laser_pose") or [0.0, 0.0, 0.0]
        return float(lp[0]), float(lp[1]), float(lp[2])


def load_run(store: RunsStore, run_id: int) -> RunData:
    """RunNotFound if there is no such run."""
    run = store.run(run_id)
    samples, labels = store.samples(run_id)
    return RunData(
        run=run,
        samples=samples,
        labels=labels,
        scans=store.scans(run_id),
        plans=store.plans(run_id),
        grids=store.grids(run_id),
        events=store.events(run_id),
        goals=store.goals(run_id),
    )
