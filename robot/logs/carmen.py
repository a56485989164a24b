"""CARMEN text logs (Montemerlo, Roy, Thrun 2003): ``FLASER``, ``ROBOTLASER1`` and ``ODOM`` lines.

Line layouts (CARMEN ``logger`` documentation):
- ``FLASER n r1..rn x y theta odom_x odom_y odom_theta ipc_timestamp hostname logger_timestamp``
  (180 deg front laser, first beam at -90 deg)
- ``ROBOTLASER1 type start_angle fov resolution max_range accuracy remission_mode n r1..rn m
  rem1..remm laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv fwd_safety side_safety
  turn_axis ipc_timestamp hostname logger_timestamp``
- ``ODOM x y theta tv rv accel ipc_timestamp hostname logger_timestamp``
The scan's stamp is ``ipc_timestamp``, kept as text.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from nav.types import LaserScan, Pose2D, wrap_angle
from robot.logs.errors import LogError
from robot.logs.stamp import Stamp

_MAX_RANGE = 80.0  # CARMEN SICK logs saturate at 81.83 m


def _scan(stamp: Stamp, ranges: np.ndarray, angle_min: float, inc: float, rmax: float) -> LaserScan:
    r = ranges.copy()
    r[~(r < rmax)] = np.inf
    return LaserScan(float(stamp), angle_min, inc, r, 0.0, rmax)


def read_carmen(
    path: Path,
) -> tuple[list[Stamp], list[LaserScan], list[float], list[tuple[float, float, float]], Pose2D]:
    stamps: list[Stamp] = []
    scans: list[LaserScan] = []
    t_odom: list[float] = []
    odom: list[tuple[float, float, float]] = []
    laser = Pose2D()
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError as exc:
        raise LogError(f"{path.name}: {exc}") from exc
    for ln in lines:
        tok = ln.split()
        if not tok:
            continue
        try:
            if tok[0] == "FLASER":
                n = int(tok[1])
                r = np.asarray(tok[2 : 2 + n], dtype=float)
                rest = tok[2 + n :]
                st = Stamp(rest[6])
                inc = math.pi / n
                stamps.append(st)
                scans.append(_scan(st, r, -math.pi / 2, inc, _MAX_RANGE))
                t_odom.append(float(st))
                odom.append((float(rest[3]), float(rest[4]), float(rest[5])))
            elif tok[0] == "ROBOTLASER1":
                start, fov, res, rmax = (float(v) for v in tok[2:6])
                n = int(tok[8])
                r = np.asarray(tok[9 : 9 + n], dtype=float)
                k = 9 + n
                m = int(tok[k])
                rest = tok[k + 1 + m :]
                lx, ly, lth, rx, ry, rth = (float(v) for v in rest[:6])
                st = Stamp(rest[11])
                # the laser pose is given in the odometry frame: laser in base_link = robot^-1 * laser
                robot = Pose2D(rx, ry, rth)
                laser = Pose2D(lx, ly, lth).relative_to(robot)
                inc = res if n < 2 else fov / (n - 1) if abs(res * (n - 1) - fov) > 1e-3 else res
                stamps.append(st)
                scans.append(_scan(st, r, start, inc, min(rmax, _MAX_RANGE)))
                t_odom.append(float(st))
                odom.append((rx, ry, float(wrap_angle(rth))))
            elif tok[0] == "ODOM":
                t_odom.append(float(tok[7]))
                odom.append((float(tok[1]), float(tok[2]), float(tok[3])))
        except (IndexError, ValueError) as exc:
            raise LogError(f"{path.name}: malformed {tok[0]} line: {exc}") from exc
    return stamps, scans, t_odom, odom, laser
