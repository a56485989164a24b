"""Experiment sweep for issue 18: lattice phase, noise, resolution, on both corridor directions."""

import json
import sys
from dataclasses import replace

from bench.slamscale import Drive, lattice_phase, replay
from nav.slam.system import SlamOptions

DRIVES = {
    "o4east": Drive(x_from=1.0, x_to=26.0),
    "o4west": Drive(x_from=26.0, x_to=1.0),
    "o1east": Drive(world="office:1", y=10.46, x_from=1.0, x_to=22.0),
    "o1west": Drive(world="office:1", y=10.46, x_from=22.0, x_to=1.0),
}


def run(tag: str, drive: str, phase: float | None = None, options: SlamOptions | None = None, **kw) -> None:
    d = replace(DRIVES[drive], **kw)
    if phase is None:
        r = replay(d, options)
    else:
        with lattice_phase(phase):
            r = replay(d, options)
    scalars = {k: round(v, 5) for k, v in r.__dict__.items() if isinstance(v, float | int)}
    row = {"tag": tag, "drive": drive, "phase": phase, **scalars}
    print(json.dumps(row), flush=True)


if __name__ == "__main__":
    which = sys.argv[1]
    drives = sys.argv[2].split(",") if len(sys.argv) > 2 else list(DRIVES)
    for dr in drives:
        if which == "phase":
            for p in (0.0, 0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875):
                run("phase", dr, p)
        elif which == "noise":
            for p in (0.0, 0.25, 0.5, 0.75):
                run("noise", dr, p, noise=True)
        elif which in ("grid", "grid_on"):  # the before/after figure: 4 lattice phases, clean, noisy
            on = SlamOptions(unobserved_points_at_prediction=which == "grid_on")
            for noise in (False, True):
                for p in (0.0, 0.25, 0.5, 0.75):
                    run("noise" if noise else "clean", dr, p, on, noise=noise)
        elif which == "trace":
            with lattice_phase(float(sys.argv[3])):
                r = replay(replace(DRIVES[dr], noise=sys.argv[4] == "noise"))
            c = 0.0
            for i, (x, e) in enumerate(zip(r.node_x[1:], r.node_step_error, strict=True)):
                c += e
                mark = " <- submap" if (i + 1) % 40 == 0 else ""
                print(f"{i + 1:4d} x {x:6.2f} step_err {1000 * e:+7.2f} mm cum {1000 * c:+7.1f} mm{mark}")
            print(r.slope_pct)
        elif which == "res":
            run("res0.025", dr, options=SlamOptions(resolution=0.025, voxel_filter_size=0.05))
        elif which == "speed":
            for v in (0.065, 0.13, 0.2, 0.26):
                run(f"speed{v}", dr, speed=v)
