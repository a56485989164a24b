"""Particle clustering and pose statistics for the AMCL estimate.

As Nav2's ``pf_cluster_stats``: particles are binned in the KLD histogram (0.5 m, 0.5 m, 10 deg);
bins that touch (Chebyshev distance 1 in bin space, heading wrapping round) form one cluster; the
estimate is the weighted mean of the cluster holding the most weight. A multimodal belief (e.g.
during global localization in a symmetric map) thus yields the best hypothesis, not the meaningless
average of all of them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from nav.localization.kld import bin_keys, pack_keys
from nav.types import wrap_angle


@dataclass(frozen=True)
class ClusterStats:
    """One cluster: total normalised weight, particle count, weighted mean [x, y, theta] and 3x3 cov."""

    weight: float
    count: int
    mean: np.ndarray
    cov: np.ndarray


def weighted_pose_stats(poses: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean (circular for theta) and covariance (theta residuals wrapped about the mean)."""
    w = weights / np.sum(weights)
    mx = float(w @ poses[:, 0])
    my = float(w @ poses[:, 1])
    mt = float(np.arctan2(w @ np.sin(poses[:, 2]), w @ np.cos(poses[:, 2])))
    d = np.column_stack((poses[:, 0] - mx, poses[:, 1] - my, wrap_angle(poses[:, 2] - mt)))
    cov = (d * w[:, None]).T @ d
    return np.array([mx, my, mt]), cov


# Half of the 26 neighbours of a bin in (x, y, theta) bin space (the graph is undirected, so
# looking up one of each pair of opposite offsets finds every edge).
_OFFSETS = np.array(
    [(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) > (0, 0, 0)],
    dtype=np.int64,
)


def cluster_labels(poses: np.ndarray, bin_xy: float, bin_theta: float) -> np.ndarray:
    """Connected-component label (0..C-1) of every pose; neighbouring histogram bins connect.

    Neighbours are found by looking the 26 neighbour keys of every occupied bin up in the sorted
    occupied keys (``searchsorted``), heading indices taken modulo one turn."""
    keys = bin_keys(poses, bin_xy, bin_theta)
    packed = pack_keys(keys)
    uniq_packed, first, inverse = np.unique(packed, return_index=True, return_inverse=True)
    uniq = keys[first]
    u = uniq.shape[0]
    n_theta = int(np.ceil(2.0 * np.pi / bin_theta - 1e-9))
    nb = (uniq[:, None, :] + _OFFSETS[None, :, :]).reshape(-1, 3)
    nb[:, 2] %= n_theta
    nb_packed = pack_keys(nb)
    pos = np.minimum(np.searchsorted(uniq_packed, nb_packed), u - 1)
    found = uniq_packed[pos] == nb_packed
    hits = np.flatnonzero(found)
    a = hits // _OFFSETS.shape[0]
    b = pos[hits]
    graph = coo_matrix((np.ones(a.shape[0]), (a, b)), shape=(u, u))
    _, comp = connected_components(graph, directed=False)
    return comp[inverse.ravel()]


def cluster_stats(
    poses: np.ndarray, weights: np.ndarray, bin_xy: float, bin_theta: float
) -> list[ClusterStats]:
    """Statistics of every cluster, heaviest first."""
    labels = cluster_labels(poses, bin_xy, bin_theta)
    w = weights / np.sum(weights)
    totals = np.bincount(labels, weights=w)
    counts = np.bincount(labels)
    out: list[ClusterStats] = []
    for c in np.argsort(-totals):
        m = labels == c
        mean, cov = weighted_pose_stats(poses[m], w[m])
        out.append(ClusterStats(float(totals[c]), int(counts[c]), mean, cov))
    return out


def best_cluster(poses: np.ndarray, weights: np.ndarray, bin_xy: float, bin_theta: float) -> ClusterStats:
    """The cluster with the largest total weight (Nav2's published hypothesis)."""
    labels = cluster_labels(poses, bin_xy, bin_theta)
    w = weights / np.sum(weights)
    totals = np.bincount(labels, weights=w)
    c = int(np.argmax(totals))
    m = labels == c
    mean, cov = weighted_pose_stats(poses[m], w[m])
    return ClusterStats(float(totals[c]), int(np.count_nonzero(m)), mean, cov)
