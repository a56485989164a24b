"""Pure array conversions behind the viewer layers."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from app.viewer import geometry as geo
from nav.types import LaserScan, Pose2D


def test_polyline_drops_non_finite_and_short_input() -> None:
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [np.nan, 1.0], [1.0, 1.0]])
    seg = geo.polyline_segments(xy, 0.1)
    assert seg.shape == (2, 2, 3) and seg.dtype == np.float32
    np.testing.assert_allclose(seg[1], [[1, 0, 0.1], [1, 1, 0.1]])
    assert geo.polyline_segments(np.zeros((1, 2))).shape == (0, 2, 3)
    assert geo.polyline_segments(np.zeros((0, 3))).shape == (0, 2, 3)


def test_ring_closes_the_footprint() -> None:
    seg = geo.ring_segments(np.array([[0.1, 0.1], [-0.1, 0.1], [-0.1, -0.1]]))
    assert seg.shape == (3, 2, 3)
    np.testing.assert_allclose(seg[-1, 1, :2], [0.1, 0.1])


def test_trajectories_are_subsampled() -> None:
    samples = np.random.default_rng(0).normal(size=(1000, 20, 2))
    seg = geo.trajectory_segments(samples, 0.0, max_samples=100)
    assert seg.shape == (100 * 19, 2, 3)
    np.testing.assert_allclose(seg[19, 0, :2], samples[10, 0], atol=1e-6)  # every 10th trajectory


def test_scan_points_in_base_link() -> None:
    ranges = np.array([1.0, np.inf, np.nan, 0.05, 2.0])
    scan = LaserScan(0.0, 0.0, math.pi / 2, ranges, 0.1, 6.0)
    pts, r = geo.scan_points(scan, Pose2D(0.1, 0.0, math.pi), 0.2)
    np.testing.assert_allclose(r, [1.0, 2.0])
    np.testing.assert_allclose(pts, [[-0.9, 0.0, 0.2], [-1.9, 0.0, 0.2]], atol=1e-6)  # laser faces back


def test_edges() -> None:
    e = geo.edge_segments(np.array([[[0, 0], [1, 1]], [[np.inf, 0], [1, 1]]]), 0.5)
    assert e.shape == (1, 2, 3) and e[0, 1, 2] == np.float32(0.5)


@settings(max_examples=50, deadline=None)
@given(arrays(np.float64, st.tuples(st.integers(1, 50), st.just(3)), elements=st.floats(-50, 50)))
def test_pose_arrows_start_at_pose_and_point_along_heading(poses: np.ndarray) -> None:
    arrows = geo.pose_arrows(poses, 0.2, 0.0)
    np.testing.assert_allclose(arrows[:, 0, :2], poses[:, :2], atol=1e-4 + 1e-6 * 50)
    d = (arrows[:, 1, :2] - arrows[:, 0, :2]).astype(float)
    np.testing.assert_allclose(np.hypot(d[:, 0], d[:, 1]), 0.2, atol=1e-4)
    heading = np.arctan2(d[:, 1], d[:, 0])
    np.testing.assert_allclose(np.cos(heading - poses[:, 2]), 1.0, atol=1e-3)


def test_pose_arrow_lines_shaft_and_head() -> None:
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, np.pi / 2], [np.nan, 0.0, 0.0]])
    a = geo.pose_arrow_lines(poses, 0.2, 0.01)
    assert a.shape == (2, 3, 2, 3)  # the non-finite pose dropped
    np.testing.assert_allclose(a[1, 0, :, :2], [[1.0, 2.0], [1.0, 2.2]], atol=1e-6)  # shaft along theta
    heads = a[1, 1:, 1, :2]  # both strokes start at the tip and end behind it, one each side
    np.testing.assert_allclose(a[1, 1:, 0, :2], [[1.0, 2.2], [1.0, 2.2]], atol=1e-6)
    back = 0.06 * np.cos(np.pi / 6)  # strokes 0.3 of the length, 30 degrees off the shaft
    np.testing.assert_allclose(sorted(heads[:, 0]), [0.97, 1.03], atol=1e-6)
    np.testing.assert_allclose(heads[:, 1], [2.2 - back, 2.2 - back], atol=1e-6)
    assert np.allclose(a[..., 2], 0.01)
