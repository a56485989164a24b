"""The last seconds of wheel odometry, to pair a sensor reading with the pose at its own stamp.

A scan is taken before the control tick that reads it (the simulator: up to one tick, 18 ms on
average at 20 Hz and 10 Hz scans; a real lidar: a rotation plus the serial transfer), while the
odometry pose of that tick is already further along. Handing SLAM the tick's pose adds the robot's
travel since the scan to every scan's prediction (issue 18: the maps of offices came out 0.5 %
short along corridors). The session keeps (stamp, pose) of each odometry update here, both stamps
on the driver's clock, and a consumer interpolates at the reading's stamp.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from nav.slam.time_offset import interpolate_poses
from nav.types import Pose2D


class OdometryHistory:
    """Bounded (stamp, odom pose) history: entries older than ``horizon`` s behind the newest drop."""

    def __init__(self, horizon: float = 2.0, capacity: int = 4096) -> None:
        self.horizon = horizon
        self._rows: deque[tuple[float, float, float, float]] = deque(maxlen=capacity)

    def __len__(self) -> int:
        return len(self._rows)

    def clear(self) -> None:
        self._rows.clear()

    def add(self, stamp: float, pose: Pose2D) -> None:
        """Append the pose integrated up to ``stamp``. A stamp behind the newest (the base's clock
        restarted) starts the history over: poses on two time bases must not be interpolated."""
        rows = self._rows
        if rows and stamp < rows[-1][0]:
            rows.clear()
        elif rows and stamp == rows[-1][0]:
            rows.pop()
        rows.append((stamp, pose.x, pose.y, pose.theta))
        while rows[0][0] < stamp - self.horizon:
            rows.popleft()

    def pose_at(self, stamp: float) -> tuple[Pose2D, bool] | None:
        """The odometry pose at ``stamp``, linear between the two updates around it (heading
        unwrapped), held at the newest after it; ``None`` when empty. The flag says the stamp is
        older than the history: the oldest pose is given for it."""
        if not self._rows:
            return None
        a = np.asarray(self._rows, dtype=float)
        x, y, th = interpolate_poses(np.array([stamp]), a[:, 0], a[:, 1:])[0]
        return Pose2D(float(x), float(y), float(th)), stamp < a[0, 0]
