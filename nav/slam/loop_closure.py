"""Loop-closure detection: match a node's scan against older, finished submaps nearby.

Hess et al. 2016 sec. V: a constraint is searched for a node in every finished submap whose pose is
within a search radius, with a wide (x, y, theta) window; a match is accepted only when its score
is above a threshold. The search itself is :func:`nav.slam.matcher.correlative_search` with
max-pooled levels (branch-and-bound style bounds) then least-squares refinement.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nav.slam.matcher import RefineOptions, SearchWindow, correlative_search, refine_pose
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
) -> LoopCandidate | None:
    """Search ``points`` (robot frame) in ``submap`` around ``guess_in_submap``; ``None`` if the best
    match scores below ``min_score`` (both after the coarse search and after refinement)."""
    field = submap.field(window.levels)
    coarse, score = correlative_search(field, points, guess_in_submap, window)
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
