"""Experiment: office:4 explored from seed 4 (bench.explore.run_one) on this branch's code."""

import json
import time

from bench.explore import run_one

if __name__ == "__main__":
    t0 = time.process_time()
    out = run_one("office:4", 4)
    out["process_cpu_s"] = time.process_time() - t0
    print(json.dumps(out), flush=True)
