"""The "robot is lost" monitor behind the localization_divergence recovery trigger."""

from __future__ import annotations

import math

import pytest

from nav.localization import AmclConfigError
from nav.localization.divergence import DivergenceMonitor, DivergenceOptions


def test_lost_after_bad_updates_in_a_row_only() -> None:
    m = DivergenceMonitor(DivergenceOptions(min_match_score=0.7, bad_updates=3))
    assert not m.update(0.95, 0.05)
    assert not m.update(0.3, 0.05)
    assert not m.update(0.4, 0.05)
    assert not m.update(0.9, 0.05)  # one good fit starts the count again
    assert not m.update(0.2, 0.05)
    assert not m.update(0.2, 0.05)
    assert m.update(0.2, 0.05)
    assert "0.20" in m.reason and "3 updates" in m.reason
    m.reset()
    assert m.bad == 0 and not m.update(0.2, 0.05)


def test_a_spread_cloud_is_lost_too_whatever_the_fit() -> None:
    m = DivergenceMonitor(DivergenceOptions(max_std_xy=1.0, bad_updates=2))
    assert not m.update(0.99, 1.5)
    assert m.update(0.99, math.nan)  # a NaN spread is no estimate at all
    assert "spreads" in m.reason


@pytest.mark.parametrize(
    ("kw", "field"),
    [
        ({"min_match_score": 1.5}, "min_match_score"),
        ({"max_std_xy": 0.0}, "max_std_xy"),
        ({"max_std_xy": math.inf}, "max_std_xy"),
        ({"bad_updates": 0}, "bad_updates"),
    ],
)
def test_bad_options_name_the_field(kw: dict, field: str) -> None:
    with pytest.raises(AmclConfigError, match=field):
        DivergenceOptions(**kw)
