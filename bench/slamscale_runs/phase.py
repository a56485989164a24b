"""Experiment: corridor slope against the submap lattice's phase (issue 18, hypothesis 1)."""

import json
import sys

from bench.slamscale import Drive, lattice_phase, replay

if __name__ == "__main__":
    east = Drive(x_from=1.0, x_to=26.0)
    west = Drive(x_from=26.0, x_to=1.0)
    for name, d in (("east", east), ("west", west)):
        for phase in [float(p) for p in sys.argv[1:]] or [0.0, 0.25, 0.5, 0.75]:
            with lattice_phase(phase):
                r = replay(d)
            print(json.dumps({"drive": name, "phase": phase, **r.__dict__}), flush=True)
