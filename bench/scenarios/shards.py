"""Scenario sets run in shards: a trial range per process, each trial logged as one JSON line.

A set of 200 trials takes longer than one session on the shared 2-core machine, and trial ``i`` of
a set depends on (seed, i) alone (virtual clock, seeded generators). So a set can be split into
ranges run by several processes (or sessions) and put back together from their logs, as long as
every line was measured on the same code: each line carries the commit (and whether the tree had
uncommitted changes) it ran on, and ``summarize`` keeps the lines of one commit only.

Environment of the family and forest benches:

- ``<PREFIX>_FIRST``: first trial index (default 0); the set runs ``first .. first + N - 1``;
- ``<PREFIX>_LOG``: a JSONL file every trial is appended to as it ends;
- ``<PREFIX>_BUDGET_S``: CPU seconds after which no new trial starts (the set keeps its true N);
- ``<PREFIX>_ONLY``: a comma-separated list of trial indices to run instead of a range (to re-run, on
  new code, the trials a change can affect).

``python -m bench.scenarios.shards LOG [LOG ...] [--commit SHA]`` prints, per set, N, the trial
ranges present and the counts by outcome.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import time
from collections import Counter, defaultdict
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]


def _positive(var: str, raw: str) -> float:
    try:
        value = float(raw)
    except ValueError:
        value = math.nan
    if not value > 0:
        raise ValueError(f"{var} must be a positive number of seconds, got {raw!r}")
    return value


def budget_s(var: str, env: Mapping[str, str] = os.environ) -> float | None:
    """CPU seconds in ``var``, None when unset."""
    raw = env.get(var)
    return None if raw is None else _positive(var, raw)


def only_trials(var: str, env: Mapping[str, str] = os.environ) -> frozenset[int] | None:
    """The trial indices listed in ``var`` ("3,17,84"), None when unset."""
    raw = env.get(var)
    if raw is None:
        return None
    try:
        picked = frozenset(int(part) for part in raw.split(","))
    except ValueError:
        picked = frozenset({-1})
    if not picked or min(picked) < 0:
        raise ValueError(f"{var} must list trial indices >= 0 separated by commas, got {raw!r}")
    return picked


def first_trial(var: str, env: Mapping[str, str] = os.environ) -> int:
    """The non-negative trial index in ``var`` (0 when unset)."""
    raw = env.get(var, "0")
    try:
        value = int(raw)
    except ValueError:
        value = -1
    if value < 0:
        raise ValueError(f"{var} must be a trial index >= 0, got {raw!r}")
    return value


def code_version() -> str:
    """The commit the code runs from, with ``+dirty`` when tracked files differ from it."""
    try:
        sha = subprocess.run(
            ["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(REPO), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return sha + ("+dirty" if dirty else "")


class TrialLog:
    """Appends one JSON line per trial to ``path`` (nothing when ``path`` is None)."""

    def __init__(self, path: str | None, set_name: str) -> None:
        self.path = Path(path) if path else None
        self.set_name = set_name
        self.commit = code_version() if path else ""
        self._cpu_mark = time.process_time()

    def cpu_lap(self) -> float:
        """CPU seconds of this process since the log was made or the last lap: one trial's cost."""
        now = time.process_time()
        lap, self._cpu_mark = now - self._cpu_mark, now
        return lap

    def write(self, index: int, outcome: str, cpu_s: float, **fields: Any) -> None:
        if self.path is None:
            return
        line = {"set": self.set_name, "i": index, "outcome": outcome, "cpu_s": round(cpu_s, 3)}
        line.update(fields, commit=self.commit)
        with self.path.open("a", encoding="utf-8") as f:
            f.write(json.dumps(line) + "\n")


def read_lines(paths: Iterable[str | Path]) -> list[dict[str, Any]]:
    lines: list[dict[str, Any]] = []
    for p in paths:
        for raw in Path(p).read_text(encoding="utf-8").splitlines():
            if raw.strip():
                lines.append(json.loads(raw))
    return lines


def _ranges(indices: list[int]) -> str:
    """[0, 1, 2, 5, 7, 8] -> "0-2, 5, 7-8"."""
    spans: list[list[int]] = []
    for i in sorted(set(indices)):
        if spans and spans[-1][1] == i - 1:
            spans[-1][1] = i
        else:
            spans.append([i, i])
    return ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in spans)


def summarize(lines: list[dict[str, Any]], commit: str | None = None) -> dict[str, dict[str, Any]]:
    """Per set: N (distinct trial indices; a repeated index keeps its last line), ranges, outcomes,
    the sums of the numeric fields of the set's lines and the smallest value of its ``min_*`` fields."""
    by_set: dict[str, dict[int, dict[str, Any]]] = defaultdict(dict)
    for line in lines:
        if commit is None or line.get("commit") == commit:
            by_set[line["set"]][int(line["i"])] = line
    out: dict[str, dict[str, Any]] = {}
    for name, trials in sorted(by_set.items()):
        rows = list(trials.values())
        keys = {
            k for r in rows for k, v in r.items() if isinstance(v, int | float) and not isinstance(v, bool)
        }
        numeric = sorted(keys - {"i", "world_seed"})
        smallest = [k for k in numeric if k.startswith("min_")]
        out[name] = {
            "n": len(rows),
            "ranges": _ranges(list(trials)),
            "outcomes": dict(Counter(r["outcome"] for r in rows).most_common()),
            "sums": {
                k: round(sum(float(r.get(k) or 0) for r in rows), 3) for k in numeric if k not in smallest
            },
            "smallest": {k: min(float(r[k]) for r in rows if r.get(k) is not None) for k in smallest},
            "commits": sorted({r.get("commit", "") for r in rows}),
        }
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+")
    ap.add_argument("--commit", help="keep only the lines measured on this commit")
    args = ap.parse_args(argv)
    print(json.dumps(summarize(read_lines(args.logs), args.commit), indent=1))


if __name__ == "__main__":
    main()
