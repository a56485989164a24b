"""Shared value types for the navigation stack.

Conventions follow REP-103 (SI units, x forward, y left, z up, counter-clockwise angles in
radians) and REP-105 (frames ``map``, ``odom``, ``base_link``, ``laser``). Everything here is
plain data: numpy arrays and frozen dataclasses, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

# nav_msgs/OccupancyGrid values.
UNKNOWN = -1
FREE = 0
OCCUPIED = 100

# Nav2 costmap_2d cost values.
FREE_SPACE = 0
INSCRIBED_INFLATED_OBSTACLE = 253
LETHAL_OBSTACLE = 254
NO_INFORMATION = 255


def wrap_angle(a: float | np.ndarray) -> float | np.ndarray:
    """Wrap an angle (or array of angles) to [-pi, pi)."""
    if isinstance(a, np.ndarray):
        return (a + np.pi) % (2.0 * np.pi) - np.pi
    return (float(a) + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True, slots=True)
class Pose2D:
    """A planar pose: position in metres, heading ``theta`` in radians (CCW from +x)."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0

    def compose(self, other: Pose2D) -> Pose2D:
        """``self ⊕ other``: ``other`` is expressed in the frame of ``self``."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        return Pose2D(
            self.x + c * other.x - s * other.y,
            self.y + s * other.x + c * other.y,
            float(wrap_angle(self.theta + other.theta)),
        )

    def inverse(self) -> Pose2D:
        c, s = math.cos(self.theta), math.sin(self.theta)
        return Pose2D(-c * self.x - s * self.y, s * self.x - c * self.y, float(wrap_angle(-self.theta)))

    def relative_to(self, base: Pose2D) -> Pose2D:
        """This pose expressed in the frame of ``base`` (``base⁻¹ ⊕ self``)."""
        return base.inverse().compose(self)

    def transform_points(self, pts: np.ndarray) -> np.ndarray:
        """Map (N, 2) points from this pose's frame into the parent frame."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        rot = np.array([[c, -s], [s, c]])
        return pts @ rot.T + np.array([self.x, self.y])

    def distance_to(self, other: Pose2D) -> float:
        return math.hypot(other.x - self.x, other.y - self.y)

    def as_array(self) -> np.ndarray:
        """(x, y, theta) as float64, whatever number types the pose was built with."""
        return np.array([self.x, self.y, self.theta], dtype=np.float64)

    @staticmethod
    def from_array(a: np.ndarray | list[float] | tuple[float, ...]) -> Pose2D:
        return Pose2D(float(a[0]), float(a[1]), float(a[2]))

    def is_finite(self) -> bool:
        return math.isfinite(self.x) and math.isfinite(self.y) and math.isfinite(self.theta)


@dataclass(frozen=True, slots=True)
class Twist2D:
    """A planar velocity in the body frame, with geometry_msgs/Twist's meaning:
    ``vx`` forward (m/s), ``vy`` left (m/s, omni only), ``wz`` counter-clockwise (rad/s)."""

    vx: float = 0.0
    vy: float = 0.0
    wz: float = 0.0

    def is_zero(self, eps: float = 1e-9) -> bool:
        return abs(self.vx) < eps and abs(self.vy) < eps and abs(self.wz) < eps

    def is_finite(self) -> bool:
        return math.isfinite(self.vx) and math.isfinite(self.vy) and math.isfinite(self.wz)

    def as_array(self) -> np.ndarray:
        return np.array([self.vx, self.vy, self.wz])


ZERO_TWIST = Twist2D()


@dataclass(frozen=True)
class LaserScan:
    """sensor_msgs/LaserScan in the ``laser`` frame (counter-clockwise angles, REP-103).

    ``ranges`` holds metres; ``+inf`` means no return (REP-117), ``nan`` an invalid reading.
    """

    stamp: float
    angle_min: float
    angle_increment: float
    ranges: np.ndarray
    range_min: float
    range_max: float
    frame_id: str = "laser"

    @property
    def angles(self) -> np.ndarray:
        return self.angle_min + self.angle_increment * np.arange(self.ranges.shape[0])

    def valid_mask(self) -> np.ndarray:
        r = self.ranges
        return np.isfinite(r) & (r >= self.range_min) & (r <= self.range_max)

    def points(self) -> np.ndarray:
        """Valid returns as (N, 2) points in the laser frame."""
        m = self.valid_mask()
        a = self.angles[m]
        r = self.ranges[m]
        return np.column_stack((r * np.cos(a), r * np.sin(a)))


def _cell_index(v: np.ndarray) -> np.ndarray:
    """floor(v) as int64, with NaN, infinities and values no grid reaches (|v| >= 2**52) mapped to -1,
    which every ``in_bounds`` refuses. Casting them is undefined in C: x86 gives INT64_MIN, but ARM
    (the Jetson) turns NaN into 0, a real cell (a far-off goal on a rotated map overflows to NaN)."""
    out = np.floor(v)
    bad = ~(np.abs(out) < 2.0**52)  # NaN compares false
    if bad.any():
        out[bad] = -1.0
    return out.astype(np.int64)


@dataclass(frozen=True)
class GridGeometry:
    """Geometry of a row-major grid like nav_msgs/OccupancyGrid: cell (row, col) = (0, 0) has its
    lower-left corner at ``origin``; columns grow along the origin's x axis, rows along its y axis."""

    resolution: float
    width: int
    height: int
    origin: Pose2D = field(default_factory=Pose2D)

    def world_to_cell(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 2) world points -> integer (rows, cols); may fall outside the grid."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        with np.errstate(over="ignore", invalid="ignore"):  # absurd points: off the grid, below
            if self.origin.theta != 0.0:
                local = self.origin.inverse().transform_points(xy)
            else:
                local = xy - np.array([self.origin.x, self.origin.y])
            q = local / self.resolution
        return _cell_index(q[:, 1]), _cell_index(q[:, 0])

    def cell_to_world(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Cell centres as (N, 2) world points."""
        local = np.column_stack(
            ((np.asarray(cols) + 0.5) * self.resolution, (np.asarray(rows) + 0.5) * self.resolution)
        )
        return self.origin.transform_points(local)

    def in_bounds(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        return (rows >= 0) & (rows < self.height) & (cols >= 0) & (cols < self.width)

    @property
    def size_m(self) -> tuple[float, float]:
        return self.width * self.resolution, self.height * self.resolution


@dataclass
class OccupancyGrid:
    """nav_msgs/OccupancyGrid: ``data`` is int8 (height, width), -1 unknown, 0..100 occupancy."""

    geometry: GridGeometry
    data: np.ndarray

    def __post_init__(self) -> None:
        if self.data.shape != (self.geometry.height, self.geometry.width):
            raise ValueError(
                f"grid data shape {self.data.shape} != (height, width) "
                f"({self.geometry.height}, {self.geometry.width})"
            )

    @property
    def resolution(self) -> float:
        return self.geometry.resolution

    def occupied_mask(self, threshold: int = 65) -> np.ndarray:
        return self.data >= threshold

    def free_mask(self, threshold: int = 25) -> np.ndarray:
        return (self.data >= 0) & (self.data <= threshold)


@dataclass
class Costmap:
    """A Nav2-style costmap: uint8 costs (height, width), 0 free .. 253 inscribed, 254 lethal,
    255 unknown, over ``geometry``."""

    geometry: GridGeometry
    costs: np.ndarray

    def cost_at(self, xy: np.ndarray) -> np.ndarray:
        """Costs at (N, 2) world points; points off the grid read NO_INFORMATION."""
        rows, cols = self.geometry.world_to_cell(xy)
        inside = self.geometry.in_bounds(rows, cols)
        out = np.full(rows.shape, NO_INFORMATION, dtype=np.uint8)
        out[inside] = self.costs[rows[inside], cols[inside]]
        return out


@dataclass(frozen=True)
class Path:
    """nav_msgs/Path in the map frame: (N, 3) array of x, y, theta."""

    poses: np.ndarray

    def __len__(self) -> int:
        return int(self.poses.shape[0])

    @property
    def length(self) -> float:
        if len(self) < 2:
            return 0.0
        return float(np.sum(np.hypot(*np.diff(self.poses[:, :2], axis=0).T)))
