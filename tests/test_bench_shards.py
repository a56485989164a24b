"""Scenario sets split into shards: trial ranges, JSONL lines, and putting them back together."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from bench.scenarios.shards import TrialLog, budget_s, first_trial, only_trials, read_lines, summarize


def test_first_trial_and_budget_read_the_environment() -> None:
    assert first_trial("X_FIRST", {}) == 0
    assert first_trial("X_FIRST", {"X_FIRST": "120"}) == 120
    assert budget_s("X_BUDGET", {}) is None
    assert budget_s("X_BUDGET", {"X_BUDGET": "90"}) == 90.0
    for bad in ("-1", "one"):
        with pytest.raises(ValueError, match="X_FIRST"):
            first_trial("X_FIRST", {"X_FIRST": bad})
    with pytest.raises(ValueError, match="X_BUDGET"):
        budget_s("X_BUDGET", {"X_BUDGET": "0"})


def test_only_lists_the_trials_to_re_run() -> None:
    assert only_trials("X_ONLY", {}) is None
    assert only_trials("X_ONLY", {"X_ONLY": "84,3,17"}) == {3, 17, 84}
    for bad in ("", "3,,4", "-1", "one"):
        with pytest.raises(ValueError, match="X_ONLY"):
            only_trials("X_ONLY", {"X_ONLY": bad})


def test_shards_of_one_commit_sum_into_one_set(tmp_path: Path) -> None:
    a, b = tmp_path / "a.jsonl", tmp_path / "b.jsonl"
    log_a, log_b = TrialLog(str(a), "family office dwa"), TrialLog(str(b), "family office dwa")
    assert log_a.commit and log_a.commit == log_b.commit  # the lines name the code they ran on
    for i in (0, 1, 2, 5):
        log_a.write(i, "reached", 2.0, contacts_while_moving=0)
    for i in (6, 7):
        log_b.write(i, "timeout" if i == 7 else "reached", 3.0, contacts_while_moving=i - 6, min_gap_m=i / 10)
    log_b.write(2, "fault", 1.0, contacts_while_moving=0)  # a re-run index keeps its last line
    stray = {"set": "family office dwa", "i": 9, "outcome": "reached", "cpu_s": 1, "commit": "other"}
    b.open("a").write(json.dumps(stray) + "\n")

    got = summarize(read_lines([a, b]), commit=log_a.commit)["family office dwa"]
    assert got["n"] == 6 and got["ranges"] == "0-2, 5-7"
    assert got["outcomes"] == {"reached": 4, "timeout": 1, "fault": 1}
    assert got["sums"]["contacts_while_moving"] == 1.0 and got["sums"]["cpu_s"] == 13.0
    assert got["smallest"] == {"min_gap_m": 0.6}
    assert summarize(read_lines([a, b]))["family office dwa"]["n"] == 7  # no commit filter


def test_no_log_path_writes_nothing(tmp_path: Path) -> None:
    TrialLog(None, "x").write(0, "reached", 1.0)
    assert list(tmp_path.iterdir()) == []


def test_cpu_lap_counts_this_process_since_the_last_lap(tmp_path):
    log = TrialLog(str(tmp_path / "l.jsonl"), "x")
    log.cpu_lap()
    t_end = time.process_time() + 0.05
    while time.process_time() < t_end:  # burn CPU: the lap measures process time, not wall time
        pass
    first = log.cpu_lap()
    assert first >= 0.05
    assert log.cpu_lap() < first
