"""A run's numbers, computed from its stored samples, events and goals (one code path for finished,
live and interrupted runs, so a crash still yields a true summary of what was recorded).

Event vocabulary (types the session and the navigation stages emit, see docs/runs.md): ``mode``,
``estop``, ``fault``, ``collision``, ``goal`` / ``goal_reached`` / ``goal_failed`` / ``goal_canceled``,
``plan_failed``, ``recovery`` (payload ``behavior``). Synonyms used by Nav2's action results
(``succeeded``, ``aborted``, ``canceled``) are accepted too.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

import numpy as np

from app.runs.codec import MODES

GOAL_SET = frozenset({"goal", "goal_set", "goal_received"})
GOAL_REACHED = frozenset({"goal_reached", "goal_succeeded", "goal_success", "navigation_succeeded"})
GOAL_FAILED = frozenset({"goal_failed", "goal_aborted", "navigation_failed", "navigation_aborted"})
GOAL_CANCELED = frozenset({"goal_canceled", "goal_cancelled", "navigation_canceled"})
PLAN_FAILED = frozenset({"plan_failed", "planner_failed", "planning_failed", "no_path"})
RECOVERY = frozenset({"recovery", "recovery_started", "behavior_started"})


def goal_outcome(event_type: str) -> str | None:
    """The goal outcome an event type reports (succeeded | failed | canceled), or None."""
    if event_type in GOAL_REACHED:
        return "succeeded"
    if event_type in GOAL_FAILED:
        return "failed"
    if event_type in GOAL_CANCELED:
        return "canceled"
    return None


def _r(v: float, nd: int = 3) -> float | None:
    return None if v is None or not np.isfinite(v) else round(float(v), nd)


def summarize(samples: np.ndarray, events: Sequence[dict], goals: Sequence[dict] = ()) -> dict:
    """Summary metrics. ``samples`` is a SAMPLE_DTYPE array, ``events`` dicts with ``t`` and ``type``,
    ``goals`` dicts with ``outcome``.

    Distance integrates the *odom* pose (continuous by REP-105; the map pose jumps when localization
    corrects it). Speeds are |(vx, vy)| of the measured body velocity.
    """
    n = int(samples.shape[0])
    kinds = Counter(str(e.get("type", "")) for e in events)
    t_last_event = max((float(e.get("t", 0.0)) for e in events), default=0.0)
    out: dict = {"samples": n}
    if n:
        t = samples["t"].astype(np.float64)
        step = np.hypot(np.diff(samples["ox"].astype(np.float64)), np.diff(samples["oy"].astype(np.float64)))
        speed = np.hypot(samples["vx"], samples["vy"]).astype(np.float64)
        clear = samples["clearance"].astype(np.float64)
        dt = np.diff(t, append=t[-1])
        mode_time = np.bincount(samples["mode"], weights=dt, minlength=len(MODES))
        out.update(
            duration_s=_r(max(float(t[-1]), t_last_event)),
            distance_m=_r(float(step.sum())),
            mean_speed=_r(float(speed.mean())),
            max_speed=_r(float(speed.max())),
            max_angular_speed=_r(float(np.abs(samples["wz"]).max())),
            min_clearance_m=_r(float(np.nanmin(clear))) if np.isfinite(clear).any() else None,
            mode_time_s={MODES[i]: _r(v, 2) for i, v in enumerate(mode_time) if v > 0 and i < len(MODES)},
        )
    else:
        out.update(duration_s=_r(t_last_event), distance_m=0.0, mean_speed=None, max_speed=None)
        out.update(max_angular_speed=None, min_clearance_m=None, mode_time_s={})
    outcomes = Counter(str(g.get("outcome")) for g in goals)
    if goals:
        reached, failed, canceled = outcomes["succeeded"], outcomes["failed"], outcomes["canceled"]
    else:
        reached = sum(kinds[k] for k in GOAL_REACHED)
        failed = sum(kinds[k] for k in GOAL_FAILED)
        canceled = sum(kinds[k] for k in GOAL_CANCELED)
    behaviors = Counter(
        str(e.get("behavior") or e.get("name") or "unknown") for e in events if e.get("type") in RECOVERY
    )
    out.update(
        goals=len(goals) if goals else sum(kinds[k] for k in GOAL_SET),
        goals_reached=reached,
        goals_failed=failed,
        goals_canceled=canceled,
        plan_failures=sum(kinds[k] for k in PLAN_FAILED),
        recoveries=sum(behaviors.values()),
        recovery_behaviors=dict(behaviors),
        estops=kinds["estop"],
        faults=kinds["fault"],
        collisions=kinds["collision"],
        mode_changes=kinds["mode"],
    )
    return out


def outcome_for(kind: str, summary: dict, aborted: bool) -> str:
    """A finished run's outcome: ``aborted`` when it ended in e-stop or fault; for navigation
    ``succeeded`` (goals reached, none failed), ``failed`` (a goal failed) or ``completed`` (no goal
    reached or failed); mapping and teleop runs ``completed``."""
    if aborted:
        return "aborted"
    if kind == "navigation":
        if summary.get("goals_failed", 0) > 0:
            return "failed"
        if summary.get("goals_reached", 0) > 0:
            return "succeeded"
    return "completed"
