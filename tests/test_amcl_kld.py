"""KLD-sampling bound (Fox 2003), low-variance resampling (Thrun Table 4.4) and clustering."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2, norm

from nav.localization.clustering import best_cluster, cluster_labels, cluster_stats, weighted_pose_stats
from nav.localization.kld import count_bins, kld_limit, kld_sample_count
from nav.localization.resampling import effective_sample_size, low_variance_resample

BIN_T = math.radians(10.0)


def test_kld_limit_approximates_chi_square_quantile() -> None:
    """Wilson-Hilferty's form (Fox eq. 11) tracks the exact chi^2 quantile bound of eq. 9."""
    z = float(norm.ppf(0.99))
    for k in (10, 50, 200, 1000):
        exact = chi2.ppf(0.99, k - 1) / (2 * 0.05)
        assert kld_limit(k, 0.05, z, 1, 10**9) == pytest.approx(exact, rel=0.01)


def test_kld_limit_clamps_and_grows() -> None:
    ks = np.arange(1, 400)
    n = kld_limit(ks, 0.05, 0.99, 500, 2000)
    assert n[0] == 2000  # k <= 1: Nav2 returns max
    assert np.all(n[1:] >= 500) and np.all(n <= 2000)
    assert np.all(np.diff(n[1:]) >= 0)
    assert n[1] == 500 and n[-1] == 2000


def test_kld_sample_count_small_for_concentrated_large_for_spread() -> None:
    rng = np.random.default_rng(0)
    tight = np.column_stack(
        (rng.normal(1.2, 0.02, 5000), rng.normal(1.2, 0.02, 5000), rng.normal(0, 0.01, 5000))
    )
    spread = np.column_stack(
        (rng.uniform(0, 20, 5000), rng.uniform(0, 20, 5000), rng.uniform(-math.pi, math.pi, 5000))
    )
    assert kld_sample_count(tight, 0.05, 0.99, 500, 5000) == 500
    assert kld_sample_count(spread, 0.05, 0.99, 500, 5000) == 5000
    # An intermediate spread stops where n first reaches the bound for the bins seen so far.
    mid = np.column_stack((rng.normal(0, 0.4, 5000), rng.normal(0, 0.4, 5000), rng.normal(0, 0.15, 5000)))
    n = kld_sample_count(mid, 0.05, 0.99, 100, 5000)
    assert 100 < n < 5000
    assert n >= kld_limit(count_bins(mid[:n], 0.5, BIN_T), 0.05, 0.99, 100, 5000)
    assert n - 1 < kld_limit(count_bins(mid[: n - 1], 0.5, BIN_T), 0.05, 0.99, 100, 5000)


def test_low_variance_resample_is_systematic() -> None:
    rng = np.random.default_rng(3)
    idx = low_variance_resample(np.full(10, 0.1), 10, rng)
    np.testing.assert_array_equal(np.sort(idx), np.arange(10))
    w = np.array([0.5, 0.25, 0.125, 0.125])
    for _ in range(20):
        counts = np.bincount(low_variance_resample(w, 8, rng), minlength=4)
        np.testing.assert_array_equal(counts, [4, 2, 1, 1])
    w = rng.random(50)
    w /= w.sum()
    counts = np.bincount(low_variance_resample(w, 1000, rng), minlength=50)
    assert np.all(np.abs(counts - 1000 * w) < 1.0 + 1e-9)
    assert effective_sample_size(np.full(4, 0.25)) == pytest.approx(4.0)


def test_clusters_separate_and_heaviest_wins() -> None:
    rng = np.random.default_rng(1)
    a = np.column_stack((rng.normal(2, 0.05, 300), rng.normal(2, 0.05, 300), rng.normal(0.5, 0.02, 300)))
    b = np.column_stack((rng.normal(8, 0.05, 100), rng.normal(3, 0.05, 100), rng.normal(-1.0, 0.02, 100)))
    poses = np.vstack((a, b))
    labels = cluster_labels(poses, 0.5, BIN_T)
    assert len(set(labels[:300])) == 1 and len(set(labels[300:])) == 1 and labels[0] != labels[300]
    w = np.concatenate((np.full(300, 1.0), np.full(100, 9.0)))  # b carries 3/4 of the weight
    best = best_cluster(poses, w, 0.5, BIN_T)
    assert best.weight == pytest.approx(0.75)
    assert best.count == 100
    np.testing.assert_allclose(best.mean[:2], [8, 3], atol=0.02)
    stats = cluster_stats(poses, w, 0.5, BIN_T)
    assert [s.count for s in stats] == [100, 300]


def test_cluster_wraps_heading_at_pi() -> None:
    rng = np.random.default_rng(2)
    th = np.concatenate(
        (rng.uniform(math.pi - 0.05, math.pi, 100), rng.uniform(-math.pi, -math.pi + 0.05, 100))
    )
    poses = np.column_stack((rng.normal(1, 0.05, 200), rng.normal(1, 0.05, 200), th))
    assert len(set(cluster_labels(poses, 0.5, BIN_T))) == 1
    mean, cov = weighted_pose_stats(poses, np.ones(200))
    assert abs(abs(mean[2]) - math.pi) < 0.01
    assert cov[2, 2] < 0.01  # wrapped residuals, not (2 pi)^2 / 4
