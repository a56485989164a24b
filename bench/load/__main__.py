"""``python -m bench.load``: the load run, or a soak with ``--minutes``; prints a JSON report."""

from __future__ import annotations

import argparse
import json
import sys

from bench.load.run import LoadOptions, run_load


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.load", description=__doc__)
    p.add_argument("--viewers", type=int, default=50, help="telemetry websocket clients (default 50)")
    p.add_argument("--seconds", type=float, default=30.0, help="measured duration of a load run")
    p.add_argument("--minutes", type=float, default=0.0, help="soak: run this long and report RSS growth")
    p.add_argument("--warmup", type=float, default=None, help="warm-up seconds (default 5, soak 120)")
    p.add_argument("--db", default="", help="database URL (default: a temporary SQLite file)")
    p.add_argument("--world", default="apartment")
    p.add_argument("--json", help="also write the report to this file")
    a = p.parse_args(argv)
    soak = a.minutes > 0
    opts = LoadOptions(
        viewers=a.viewers,
        seconds=a.minutes * 60.0 if soak else a.seconds,
        warmup_s=a.warmup if a.warmup is not None else (120.0 if soak else 5.0),
        db_url=a.db,
        world=a.world,
        sample_every_s=30.0 if soak else 5.0,
    )

    def progress(sample: tuple[float, float]) -> None:
        if soak:
            print(f"  t={sample[0]:7.0f} s  rss={sample[1]:7.1f} MB", file=sys.stderr, flush=True)

    report = run_load(opts, progress)
    out = report.as_dict()
    if soak:
        out["rss_samples"] = [(round(t), round(m, 1)) for t, m in report.rss_mb]
    print(json.dumps(out, indent=2))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
