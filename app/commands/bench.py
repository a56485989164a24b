"""``navdeck bench``: run the benchmarks in ``bench/`` and print their figures."""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

from app.cli import CliError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="run benchmarks and print a table of figures")
    p.add_argument("names", nargs="*", help="benchmark names or prefixes (default: the default group)")
    p.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    p.add_argument("--list", action="store_true", help="list benchmarks and exit")
    p.set_defaults(func=run)


def _machine() -> dict:
    import os

    import numpy

    return {
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "cpu": platform.processor() or platform.machine(),
        "cores": os.cpu_count(),
        "platform": platform.platform(),
    }


def run(args: argparse.Namespace) -> int:
    from bench.core import discover, figure_dict

    benches = discover()
    if args.list:
        for b in benches:
            print(f"{b.name:32s} [{b.group}]")
        return 0
    if args.names:
        chosen = [b for b in benches if any(b.name == n or b.name.startswith(n + ".") for n in args.names)]
        if not chosen:
            raise CliError(f"no benchmark matches {' '.join(args.names)} (try --list)")
    else:
        chosen = [b for b in benches if b.group == "default"]
    rows: list[dict] = []
    print(f"{'benchmark':28s} {'figure':34s} {'value':>12s} {'unit':8s} {'target':12s} ok")
    all_ok = True
    for b in chosen:
        t0 = time.perf_counter()
        figures = b.run()
        for f in figures:
            rows.append(figure_dict(b.name, f))
            ok = "" if f.ok is None else ("yes" if f.ok else "NO")
            all_ok = all_ok and f.ok is not False
            print(f"{b.name:28s} {f.name:34s} {f.value:12.3f} {f.unit:8s} {f.target:12s} {ok}")
        print(f"{'':28s} ({time.perf_counter() - t0:.1f} s)", file=sys.stderr)
    if args.json:
        args.json.write_text(json.dumps({"machine": _machine(), "figures": rows}, indent=2))
    return 0 if all_ok else 1
