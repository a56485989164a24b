"""KLD-sampling: adapt the number of particles to the spread of the belief.

Fox, "Adapting the sample size in particle filters through KLD-sampling", IJRR 22(12), 2003,
eq. (11): with ``k`` occupied histogram bins, ``n = (k-1)/(2 eps) * (1 - 2/(9(k-1)) +
sqrt(2/(9(k-1))) z)^3`` samples bound the K-L distance between the sample-based and the true
posterior by ``eps`` with probability ``1 - delta`` (``z`` its upper normal quantile). Bins are
0.5 m x 0.5 m x 10 deg like Nav2's ``pf_kdtree``. Nav2 (``pf_update_resample``) draws samples one at
a time until the count exceeds the bound for the bins seen so far; here the same stopping rule is
evaluated for every prefix of a pre-drawn sample set at once.
"""

from __future__ import annotations

import numpy as np


def kld_limit(k: np.ndarray | int, pf_err: float, pf_z: float, min_n: int, max_n: int) -> np.ndarray:
    """Fox's bound for ``k`` occupied bins, clamped to [min_n, max_n]; ``max_n`` when k <= 1
    (Nav2 ``pf_resample_limit``)."""
    k = np.asarray(k, dtype=float)
    km1 = np.maximum(k - 1.0, 1.0)
    b = 2.0 / (9.0 * km1)
    x = 1.0 - b + np.sqrt(b) * pf_z
    n = np.ceil(km1 / (2.0 * pf_err) * x * x * x)
    n = np.where(k <= 1.0, max_n, n)
    return np.clip(n, min_n, max_n).astype(np.int64)


def bin_keys(poses: np.ndarray, bin_xy: float, bin_theta: float) -> np.ndarray:
    """(N, 3) integer histogram bin indices of poses [x, y, theta]."""
    return np.column_stack(
        (
            np.floor(poses[:, 0] / bin_xy),
            np.floor(poses[:, 1] / bin_xy),
            np.floor((poses[:, 2] + np.pi) / bin_theta),
        )
    ).astype(np.int64)


def pack_keys(keys: np.ndarray) -> np.ndarray:
    """One int64 per (N, 3) bin index row (21 bits each for x and y, the rest for theta), so bins
    can be compared with 1-D ``np.unique`` / ``searchsorted`` instead of row-wise operations."""
    off = 1 << 20
    return ((keys[:, 0] + off) << 42) | ((keys[:, 1] + off) << 21) | (keys[:, 2] & ((1 << 21) - 1))


def packed_bin_keys(poses: np.ndarray, bin_xy: float, bin_theta: float) -> np.ndarray:
    """``pack_keys(bin_keys(...))``."""
    return pack_keys(bin_keys(poses, bin_xy, bin_theta))


def count_bins(poses: np.ndarray, bin_xy: float, bin_theta: float) -> int:
    """Number of distinct occupied bins (Fox's ``k``)."""
    if poses.shape[0] == 0:
        return 0
    return int(np.unique(packed_bin_keys(poses, bin_xy, bin_theta)).shape[0])


def kld_sample_count(
    poses: np.ndarray,
    pf_err: float,
    pf_z: float,
    min_n: int,
    max_n: int,
    bin_xy: float = 0.5,
    bin_theta: float = np.radians(10.0),
) -> int:
    """How many of the (M, 3) ``poses``, taken in order, KLD-sampling keeps: the first prefix length
    ``n`` with ``n >= limit(k(n))``, where ``k(n)`` counts distinct bins among the first ``n`` poses.
    The poses must be in random order (e.g. a shuffled resample). Returns at most M."""
    m = poses.shape[0]
    if m == 0:
        return 0
    _, first = np.unique(packed_bin_keys(poses, bin_xy, bin_theta), return_index=True)
    new_bin = np.zeros(m, dtype=bool)
    new_bin[first] = True
    k = np.cumsum(new_bin)
    limit = kld_limit(k, pf_err, pf_z, min_n, max_n)
    counts = np.arange(1, m + 1)
    done = np.flatnonzero(counts >= limit)
    return int(counts[done[0]]) if done.size else m
