"""Summarise sweep logs (JSON lines): mean, min, max slope per drive and noise setting."""

import json
import sys
from collections import defaultdict

import numpy as np

if __name__ == "__main__":
    with open(sys.argv[1]) as f:
        rows = [json.loads(line) for line in f if line.startswith("{")]
    groups = defaultdict(list)
    for r in rows:
        groups[(r["drive"], r["tag"])].append(r["slope_pct"])
    for (drive, tag), v in sorted(groups.items()):
        v = np.array(v)
        print(
            f"{drive:7s} {tag:6s} n={len(v)} mean {v.mean():+.3f} % min {v.min():+.3f} "
            f"max {v.max():+.3f} |mean| of runs {np.abs(v).mean():.3f}"
        )
    allv = np.array([r["slope_pct"] for r in rows])
    cpu = sum(r["cpu_s"] for r in rows)
    rms = np.sqrt((allv**2).mean())
    print(f"all n={len(allv)} mean {allv.mean():+.3f} % rms {rms:.3f} % cpu {cpu:.0f} s")
