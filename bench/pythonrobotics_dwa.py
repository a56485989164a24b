"""The peer of the DWA row of ``navdeck bench peers``: PythonRobotics' Dynamic Window Approach
(Atsushi Sakai, ``PathPlanning/DynamicWindowApproach/dynamic_window_approach.py``), written here
from its published algorithm because PythonRobotics is not a package on PyPI.

Same algorithm, same data layout and the same per-sample Python loops as the original (that is what
a user who picks it runs): the dynamic window from the speed and acceleration limits; for every
(v, yaw rate) pair on its grid (``v_resolution``, ``yaw_rate_resolution``) the unicycle motion is
rolled out every ``dt`` for ``predict_time`` (rows appended one at a time), then scored by
``to_goal_cost_gain`` x |heading error to the goal| + ``speed_cost_gain`` x (max speed - v) +
``obstacle_cost_gain`` / (nearest obstacle distance), infinite when an obstacle point lies within
``robot_radius`` of any pose (circle robot). The world is its demo's: 15 point obstacles, start
(0, 0, pi/8) at rest, goal (10, 10).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# The demo world of dynamic_window_approach.py: obstacle points (x, y), m.
OBSTACLES = np.array(
    [
        [-1.0, -1.0],
        [0.0, 2.0],
        [4.0, 2.0],
        [5.0, 4.0],
        [5.0, 5.0],
        [5.0, 6.0],
        [5.0, 9.0],
        [8.0, 9.0],
        [7.0, 9.0],
        [8.0, 10.0],
        [9.0, 11.0],
        [12.0, 13.0],
        [12.0, 12.0],
        [15.0, 15.0],
        [13.0, 13.0],
    ]
)
GOAL = np.array([10.0, 10.0])
START = np.array([0.0, 0.0, math.pi / 8.0, 0.0, 0.0])  # x, y, yaw, v, yaw rate


@dataclass
class Config:
    """The demo's parameters (SI units, radians)."""

    max_speed: float = 1.0
    min_speed: float = -0.5
    max_yaw_rate: float = math.radians(40.0)
    max_accel: float = 0.2
    max_delta_yaw_rate: float = math.radians(40.0)
    v_resolution: float = 0.01
    yaw_rate_resolution: float = math.radians(0.1)
    dt: float = 0.1
    predict_time: float = 3.0
    to_goal_cost_gain: float = 0.15
    speed_cost_gain: float = 1.0
    obstacle_cost_gain: float = 1.0
    robot_stuck_flag_cons: float = 0.001
    robot_radius: float = 1.0


def motion(x: np.ndarray, v: float, yaw_rate: float, dt: float) -> np.ndarray:
    """One unicycle step of state [x, y, yaw, v, yaw rate] (yaw first, then position), in place."""
    x[2] += yaw_rate * dt
    x[0] += v * math.cos(x[2]) * dt
    x[1] += v * math.sin(x[2]) * dt
    x[3] = v
    x[4] = yaw_rate
    return x


def dynamic_window(x: np.ndarray, c: Config) -> tuple[float, float, float, float]:
    """(v min, v max, yaw rate min, yaw rate max) reachable within ``dt`` and within the limits."""
    return (
        max(c.min_speed, x[3] - c.max_accel * c.dt),
        min(c.max_speed, x[3] + c.max_accel * c.dt),
        max(-c.max_yaw_rate, x[4] - c.max_delta_yaw_rate * c.dt),
        min(c.max_yaw_rate, x[4] + c.max_delta_yaw_rate * c.dt),
    )


def predict_trajectory(x_init: np.ndarray, v: float, yaw_rate: float, c: Config) -> np.ndarray:
    """(T, 5) states from ``x_init`` every ``dt`` while the elapsed time is <= ``predict_time``."""
    x = np.array(x_init)
    traj = np.array(x)
    t = 0.0
    while t <= c.predict_time:
        x = motion(x, v, yaw_rate, c.dt)
        traj = np.vstack((traj, x))
        t += c.dt
    return traj


def obstacle_cost(traj: np.ndarray, ob: np.ndarray, c: Config) -> float:
    """1 / (nearest obstacle distance over the trajectory); inf if one is within the radius."""
    dx = traj[:, 0] - ob[:, 0][:, None]
    dy = traj[:, 1] - ob[:, 1][:, None]
    r = np.hypot(dx, dy)
    if np.any(r <= c.robot_radius):
        return float("inf")
    return 1.0 / float(np.min(r))


def to_goal_cost(traj: np.ndarray, goal: np.ndarray) -> float:
    """|angle between the last pose's heading and the direction to the goal|."""
    err = math.atan2(goal[1] - traj[-1, 1], goal[0] - traj[-1, 0]) - traj[-1, 2]
    return abs(math.atan2(math.sin(err), math.cos(err)))


def dwa_control(x: np.ndarray, c: Config, goal: np.ndarray, ob: np.ndarray) -> tuple[list[float], np.ndarray]:
    """One cycle: the best (v, yaw rate) and its predicted trajectory."""
    dw = dynamic_window(x, c)
    best_cost = float("inf")
    best_u = [0.0, 0.0]
    best_traj = np.array([x])
    for v in np.arange(dw[0], dw[1], c.v_resolution):
        for y in np.arange(dw[2], dw[3], c.yaw_rate_resolution):
            traj = predict_trajectory(x, v, y, c)
            cost = (
                c.to_goal_cost_gain * to_goal_cost(traj, goal)
                + c.speed_cost_gain * (c.max_speed - traj[-1, 3])
                + c.obstacle_cost_gain * obstacle_cost(traj, ob, c)
            )
            if best_cost >= cost:
                best_cost = cost
                best_u = [v, y]
                best_traj = traj
                # the demo's escape from standing still in front of an obstacle: turn in place
                if abs(best_u[0]) < c.robot_stuck_flag_cons and abs(x[3]) < c.robot_stuck_flag_cons:
                    best_u[1] = -c.max_delta_yaw_rate
    return best_u, best_traj
