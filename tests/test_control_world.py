"""Test world for the control tests: hand-made inflated costmaps, a small grid planner and an
exact kinematic integrator (no simulator). Other ``test_control_*`` modules import these helpers;
the tests here check the helpers themselves."""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from nav.planning.errors import GoalOccupied, NoValidPathFound, StartOccupied
from nav.types import (
    INSCRIBED_INFLATED_OBSTACLE,
    LETHAL_OBSTACLE,
    Costmap,
    GridGeometry,
    Path,
    Pose2D,
    Twist2D,
    wrap_angle,
)

RES = 0.05
SKID_FOOTPRINT = ((0.12, 0.10), (-0.12, 0.10), (-0.12, -0.10), (0.12, -0.10))


def inflate(
    occupied: np.ndarray,
    inscribed: float,
    res: float = RES,
    inflation_radius: float = 0.55,
    cost_scaling_factor: float = 3.0,
) -> Costmap:
    """Nav2 inflation layer: 254 on obstacles, 253 within the inscribed radius, then
    252 * exp(-cost_scaling_factor * (d - inscribed)) out to ``inflation_radius``."""
    d = ndimage.distance_transform_edt(~occupied) * res
    decay = (INSCRIBED_INFLATED_OBSTACLE - 1) * np.exp(-cost_scaling_factor * (d - inscribed))
    costs = np.where(d <= inflation_radius, decay, 0.0)
    costs = np.where(d <= inscribed, INSCRIBED_INFLATED_OBSTACLE, costs)
    costs = np.where(occupied, LETHAL_OBSTACLE, costs).astype(np.uint8)
    h, w = occupied.shape
    return Costmap(GridGeometry(res, w, h, Pose2D()), costs)


def room(width: float = 6.0, height: float = 6.0, wall: float = 0.1) -> np.ndarray:
    """Occupancy of an empty walled room (rows = y, cols = x)."""
    h, w = round(height / RES), round(width / RES)
    occ = np.zeros((h, w), dtype=bool)
    k = max(round(wall / RES), 1)
    occ[:k, :] = occ[-k:, :] = occ[:, :k] = occ[:, -k:] = True
    return occ


def box(occ: np.ndarray, x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    """Mark the axis-aligned box [x0, x1] x [y0, y1] (m) occupied, in place."""
    occ[round(y0 / RES) : round(y1 / RES), round(x0 / RES) : round(x1 / RES)] = True
    return occ


def l_corridor() -> np.ndarray:
    """An L-shaped corridor 0.8 m wide: east along y in [0.6, 1.4] from x = 0.2 to 4.4, then north
    along x in [3.6, 4.4] up to y = 4.4."""
    occ = np.ones((round(5.0 / RES), round(5.0 / RES)), dtype=bool)
    occ[round(0.6 / RES) : round(1.4 / RES), round(0.2 / RES) : round(4.4 / RES)] = False
    occ[round(0.6 / RES) : round(4.4 / RES), round(3.6 / RES) : round(4.4 / RES)] = False
    return occ


class GridPlanner:
    """8-connected Dijkstra over cells cheaper than 253 (edge = length * (1 + 3 cost/252)), with
    scipy's C implementation; raises the planning area's typed errors."""

    def plan(self, costmap: Costmap, start: Pose2D, goal: Pose2D) -> Path:
        g = costmap.geometry
        costs = costmap.costs
        free = costs < INSCRIBED_INFLATED_OBSTACLE
        (sr,), (sc,) = g.world_to_cell(np.array([[start.x, start.y]]))
        (gr,), (gc,) = g.world_to_cell(np.array([[goal.x, goal.y]]))
        if not free[sr, sc]:
            raise StartOccupied(f"start cell cost {costs[sr, sc]}")
        if not free[gr, gc]:
            raise GoalOccupied(f"goal cell cost {costs[gr, gc]}")
        h, w = costs.shape
        idx = np.arange(h * w).reshape(h, w)
        weight = 1.0 + 3.0 * costs.astype(float) / 252.0
        rows, cols, vals = [], [], []
        for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
            a = (slice(0, h - dr), slice(max(0, -dc), w - max(0, dc)))
            b = (slice(dr, h), slice(max(0, dc), w - max(0, -dc)))
            ok = free[a] & free[b]
            length = math.hypot(dr, dc)
            rows.append(idx[a][ok])
            cols.append(idx[b][ok])
            vals.append(length * 0.5 * (weight[a][ok] + weight[b][ok]))
        r, c, v = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
        graph = coo_matrix((v, (r, c)), shape=(h * w, h * w)).tocsr()
        dist, pred = dijkstra(graph, directed=False, indices=int(idx[sr, sc]), return_predecessors=True)
        node = int(idx[gr, gc])
        if not np.isfinite(dist[node]):
            raise NoValidPathFound("goal unreachable")
        cells = [node]
        while cells[-1] != idx[sr, sc]:
            cells.append(int(pred[cells[-1]]))
        cells = np.array(cells[::-1])
        xy = g.cell_to_world(cells // w, cells % w)
        xy[0], xy[-1] = (start.x, start.y), (goal.x, goal.y)
        d = np.diff(xy, axis=0)
        theta = np.append(np.arctan2(d[:, 1], d[:, 0]), goal.theta) if len(xy) > 1 else np.array([goal.theta])
        return Path(np.column_stack((xy, theta)))


def integrate(pose: Pose2D, cmd: Twist2D, dt: float, substeps: int = 20) -> Pose2D:
    """Move ``pose`` by the body twist ``cmd`` for ``dt`` s (midpoint-rule sub-steps, independent
    of the controller's closed-form arcs)."""
    x, y, th = pose.x, pose.y, pose.theta
    h = dt / substeps
    for _ in range(substeps):
        mid = th + 0.5 * cmd.wz * h
        c, s = math.cos(mid), math.sin(mid)
        x += (cmd.vx * c - cmd.vy * s) * h
        y += (cmd.vx * s + cmd.vy * c) * h
        th += cmd.wz * h
    return Pose2D(x, y, float(wrap_angle(th)))


def footprint_hits_lethal(costmap: Costmap, pose: Pose2D, polygon: np.ndarray) -> bool:
    """Brute force: does any lethal cell centre lie inside the footprint polygon at ``pose``?"""
    rows, cols = np.nonzero(costmap.costs == LETHAL_OBSTACLE)
    if rows.size == 0:
        return False
    pts = pose.inverse().transform_points(costmap.geometry.cell_to_world(rows, cols))
    inside = np.zeros(pts.shape[0], dtype=bool)
    for (x0, y0), (x1, y1) in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
        crosses = (y0 > pts[:, 1]) != (y1 > pts[:, 1])
        with np.errstate(divide="ignore", invalid="ignore"):
            x_at = x0 + (pts[:, 1] - y0) * (x1 - x0) / (y1 - y0)
        inside ^= crosses & (pts[:, 0] < x_at)
    return bool(inside.any())


# --- tests of the helpers ------------------------------------------------------------------------


def test_inflation_profile_matches_nav2_formula() -> None:
    occ = box(np.zeros((40, 40), dtype=bool), 1.0, 0.0, 1.05, 2.0)  # a one-cell wall at x = 1.0
    cm = inflate(occ, inscribed=0.15)
    row = cm.costs[20]
    assert row[20] == LETHAL_OBSTACLE
    assert row[22] == INSCRIBED_INFLATED_OBSTACLE  # 0.10 m away
    assert row[24] == int(252 * math.exp(-3.0 * (0.20 - 0.15)))
    assert row[35] == 0  # 0.75 m away, beyond the inflation radius


def test_grid_planner_follows_the_l_corridor() -> None:
    cm = inflate(l_corridor(), inscribed=0.16)
    path = GridPlanner().plan(cm, Pose2D(0.5, 1.0, 0.0), Pose2D(4.0, 4.0, math.pi / 2))
    assert path.poses[-1, 2] == math.pi / 2
    assert np.all(cm.cost_at(path.poses[:, :2]) < INSCRIBED_INFLATED_OBSTACLE)
    assert 6.0 < path.length < 8.0  # 3.5 m east + 3 m north, plus grid zig-zag


def test_integrate_is_an_arc() -> None:
    p = integrate(Pose2D(), Twist2D(1.0, 0.0, math.pi / 2), 1.0, substeps=2000)
    r = 1.0 / (math.pi / 2)
    assert abs(p.x - r) < 1e-3 and abs(p.y - r) < 1e-3 and abs(p.theta - math.pi / 2) < 1e-9


def test_world_to_cell_puts_non_finite_and_absurd_points_off_the_grid() -> None:
    # Casting NaN/inf to int is undefined (x86: INT64_MIN; ARM, the Jetson: NaN -> 0, a real cell);
    # a goal at 1e308 on a rotated map overflows to NaN in the transform.
    import warnings

    for theta in (0.0, 0.3):
        geo = GridGeometry(0.05, 40, 30, Pose2D(-1.0, -1.0, theta))
        bad = [[np.nan, 0.0], [0.0, np.inf], [-np.inf, 0.0], [1e308, 1e308], [1e30, 0.0]]
        pts = np.array([*bad, [0.0, 0.0]])
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            rows, cols = geo.world_to_cell(pts)
        inside = geo.in_bounds(rows, cols)
        assert inside.tolist() == [False] * 5 + [True], (rows, cols)
