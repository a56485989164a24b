"""Experiment: log each front-end search of a corridor replay (prior, correlative lattice pose,
refined pose, score, wide re-search) to see where the along-track jumps come from."""

import sys
from dataclasses import replace

import numpy as np

import nav.slam.matcher as matcher
import nav.slam.system as system
from bench.slamscale import lattice_phase, replay
from bench.slamscale_runs.sweep import DRIVES

LOG: list[tuple] = []
_corr = matcher.correlative_search
_fallback = matcher.match_scan_with_fallback
_fuse = system.fuse_with_prediction


def _mm(a, b) -> str:  # type: ignore[no-untyped-def]
    """Offset of pose b from pose a, mm."""
    return f"({(b.x - a.x) * 1000:+6.1f},{(b.y - a.y) * 1000:+6.1f})mm"


def corr(field, pts, prior, window, *a, **k):
    pose, score = _corr(field, pts, prior, window, *a, **k)
    LOG.append(("corr", window.linear_search_window, prior, pose, score))
    return pose, score


def fallback(field, pts, prior, *a, **k):
    pose, score = _fallback(field, pts, prior, *a, **k)
    LOG.append(("refined", prior, pose, score, len(pts)))
    return pose, score


def fuse(match, prediction, info, threshold):
    out = _fuse(match, prediction, info, threshold)
    lam = np.linalg.eigvalsh(0.5 * (info + info.T))
    LOG.append(("fused", match, out, lam.min() / max(lam.max(), 1e-12)))
    return out


_match = system.GraphSlam._match


def match(self, pts_laser, pred, laser_pose):
    LOG.append(("node", len(self._nodes)))
    return _match(self, pts_laser, pred, laser_pose)


system.GraphSlam._match = match
matcher.correlative_search = corr
system.match_scan_with_fallback = fallback
system.fuse_with_prediction = fuse

if __name__ == "__main__":
    drive, phase, noise = sys.argv[1], float(sys.argv[2]), sys.argv[3] == "noise"
    with lattice_phase(phase):
        r = replay(replace(DRIVES[drive], noise=noise))
    for e in LOG:
        if e[0] == "corr":
            _, w, prior, pose, score = e
            print(f"  corr w{w:.2f} d={_mm(prior, pose)} {score:.3f}")
        elif e[0] == "refined":
            _, prior, pose, score, n = e
            print(f"  refined d={_mm(prior, pose)} {score:.3f} n={n}")
        elif e[0] == "node":
            print(f"node {e[1]}")
        else:
            _, m, out, ratio = e
            print(f"  fused ratio {ratio:.3f} moved {_mm(m, out)}")
    print(r.slope_pct)
