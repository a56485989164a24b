"""``navdeck slam-eval --trajectory T --relations R``: the Kümmerle et al. 2009 SLAM metric as JSON
``{n, trans_mean, trans_std, rot_mean_deg, rot_std_deg}``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from app.cli import CliError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("slam-eval", help="score a SLAM trajectory against ground-truth relations")
    p.add_argument("--trajectory", type=Path, required=True, help="lines 'timestamp x y theta'")
    p.add_argument("--relations", type=Path, required=True, help="lines 't1 t2 x y z roll pitch yaw'")
    p.add_argument("--tolerance", type=float, default=1e-3, help="timestamp matching tolerance (s)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from nav.slam.metric import MetricError, parse_relations, parse_trajectory, score_trajectory

    try:
        traj = parse_trajectory(args.trajectory.read_text())
        rel = parse_relations(args.relations.read_text())
        score = score_trajectory(traj, rel, args.tolerance)
    except OSError as exc:
        raise CliError(str(exc)) from None
    except MetricError as exc:
        raise CliError(str(exc)) from None
    d = score.as_dict()
    print(
        json.dumps(
            {k: d[k] for k in ("n", "trans_mean", "trans_std", "rot_mean_deg", "rot_std_deg", "skipped")}
        )
    )
    return 0
