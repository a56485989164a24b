"""Loop-closure detection: match a node's scan against older, finished submaps nearby.

Hess et al. 2016 sec. V: a constraint is searched for a node in every finished submap whose pose is
within a search radius, with a wide (x, y, theta) window; a match is accepted only when its score
is above a threshold. The search itself is :func:`nav.slam.matcher.correlative_search` with
max-pooled levels (branch-and-bound style bounds) then least-squares refinement.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nav.slam.matcher import (
    RefineOptions,
    SearchWindow,
    correlative_search,
    correlative_search_runner_up,
    refine_pose,
)
from nav.slam.metric import relative_poses
from nav.slam.submap import Submap
from nav.types import Pose2D


@dataclass(frozen=True)
class LoopCandidate:
    """An accepted loop closure: ``node`` seen from submap ``submap``'s frame is ``relative``."""

    node: int
    submap: int
    relative: Pose2D
    score: float


def find_loop_closure(
    submap: Submap,
    node: int,
    points: np.ndarray,
    guess_in_submap: Pose2D,
    window: SearchWindow,
    min_score: float,
    refine: RefineOptions,
    match_unobserved_points: bool = True,
    ambiguity: tuple[float, float] | None = None,
) -> LoopCandidate | None:
    """Search ``points`` (robot frame) in ``submap`` around ``guess_in_submap``; ``None`` if the best
    match scores below ``min_score`` (both after the coarse search and after refinement).
    ``ambiguity = (separation, margin)``: also ``None`` when a candidate more than ``separation`` m
    from the best scores within ``margin`` of it (the scan fits two places of the submap)."""
    field = submap.field(window.levels)
    if ambiguity is None:
        coarse, score = correlative_search(field, points, guess_in_submap, window)
    else:
        coarse, score, runner_up = correlative_search_runner_up(
            field, points, guess_in_submap, window, ambiguity[0]
        )
        if runner_up > score - ambiguity[1]:
            return None
    if score < min_score:
        return None
    if not match_unobserved_points:
        # as in the front end: points in cells the submap never observed have no counterpart in
        # it and would pull the match towards the part of it that was seen; chosen at the match
        # found, then searched again without them
        keep = submap.observed(coarse.transform_points(points))
        if 3 <= np.count_nonzero(keep) < len(keep):
            points = points[keep]
            coarse, score = correlative_search(field, points, guess_in_submap, window)
            if score < min_score:
                return None
    pose, fine = refine_pose(field, points, coarse, coarse, refine)
    if fine < min_score:
        return None
    return LoopCandidate(node, submap.index, pose, fine)


@dataclass(frozen=True)
class GlobalProposal:
    """A loop closure found by the global search, waiting for a second one that agrees with it.

    ``implied`` is the node's map pose the closure implies (submap map pose composed with the
    match), ``estimate`` the node's map pose before it; their difference is the correction the
    closure asks for."""

    candidate: LoopCandidate
    implied: np.ndarray
    estimate: np.ndarray


def proposals_agree(a: GlobalProposal, b: GlobalProposal, translation: float, rotation: float) -> bool:
    """Whether two global closures of different nodes tell the same story: the pose of ``b`` seen
    from ``a`` that the closures imply equals the one the trajectory between them gives (which is
    locally accurate even when its drift from the old map is metres), within ``translation`` (m)
    and ``rotation`` (rad). A wrong match is a chance alignment and the next one lands elsewhere;
    two agreeing ones are a real revisit (Olson 2009's pairwise consistency, for two)."""
    implied = relative_poses(a.implied[None], b.implied[None])
    chain = relative_poses(a.estimate[None], b.estimate[None])
    e = relative_poses(chain, implied)[0]
    return bool(math.hypot(e[0], e[1]) <= translation and abs(e[2]) <= rotation)


def global_search_region(
    node_xy: np.ndarray, guess: Pose2D, uncertainty: float
) -> tuple[Pose2D, float] | None:
    """Where a global search of a node in a submap looks: anywhere within ``uncertainty`` (m) of
    ``guess`` (the node in the submap's frame) that is also within 1 m of the submap's own
    trajectory (``node_xy``, (K, 2) in its frame: a scan sees a submap's walls as they were seen
    only from near where they were seen). Returns the region's centre (with the guess's heading)
    and its half-width (m), or ``None`` when the region is empty."""
    lo = np.maximum(node_xy.min(axis=0) - 1.0, [guess.x - uncertainty, guess.y - uncertainty])
    hi = np.minimum(node_xy.max(axis=0) + 1.0, [guess.x + uncertainty, guess.y + uncertainty])
    if np.any(hi < lo):
        return None
    centre = (lo + hi) / 2
    return Pose2D(float(centre[0]), float(centre[1]), guess.theta), float(np.max(hi - lo)) / 2


def observed_fraction(submap: Submap, points: np.ndarray, pose: Pose2D) -> float:
    """Fraction of the (N, 2) points that land, at ``pose``, on cells the submap has observed: a
    global match must explain the scan with the submap, not just the part of it that fits."""
    return float(submap.observed(pose.transform_points(points)).mean()) if len(points) else 0.0
