"""Codecs, schemas and metrics of recorded runs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap_ros2._dynamic import serialize_dynamic

from app.export.msgdefs import DEFS, dependencies, msgdef
from app.runs import codec
from app.runs.metrics import outcome_for, summarize
from nav.types import LaserScan


@settings(max_examples=50, deadline=None)
@given(
    st.lists(
        st.floats(min_value=0.0, max_value=70.0) | st.sampled_from([math.inf, math.nan, 0.0005, 65.534]),
        max_size=50,
    )
)
def test_range_quantisation_keeps_ros_semantics(values: list[float]) -> None:
    r = np.array(values, dtype=np.float64)
    back = codec.dequantize_ranges(codec.quantize_ranges(r))
    nan = np.isnan(r)
    assert np.array_equal(np.isnan(back), nan)
    no_return = np.isinf(r) | (np.rint(np.where(np.isfinite(r), r, 0.0) * 1000.0) >= 65535) | (r == 0.0)
    assert np.all(np.isinf(back[no_return & ~nan]))
    ok = ~nan & ~no_return
    assert np.all(np.abs(back[ok] - r[ok]) <= np.where(r[ok] < 0.0005, 0.001, 0.0005) + 1e-5)  # >= 1 mm


def test_scan_chunk_round_trip_with_different_beam_counts() -> None:
    rng = np.random.default_rng(2)
    scans = [
        LaserScan(0.0, -math.pi, 2 * math.pi / 360, rng.uniform(0.2, 5.0, 360), 0.15, 6.0),
        LaserScan(0.5, -1.0, 0.01, np.array([1.0, np.inf, np.nan, 2.5]), 0.1, 12.0),
    ]
    back = codec.unpack_scans(codec.pack_scans([0.0, 0.5], scans))
    assert [t for t, _ in back] == [0.0, 0.5]
    assert back[1][1].angle_min == pytest.approx(-1.0) and back[1][1].range_max == pytest.approx(12.0)
    np.testing.assert_allclose(back[0][1].ranges, scans[0].ranges, atol=5e-4)
    r = back[1][1].ranges
    assert r[0] == 1.0 and math.isinf(r[1]) and math.isnan(r[2]) and r[3] == 2.5


def test_sample_chunk_round_trip_and_corruption_is_typed() -> None:
    arr = np.zeros(7, dtype=codec.SAMPLE_DTYPE)
    arr["t"] = np.arange(7) * 0.1
    arr["x"] = np.linspace(0, 1, 7)
    arr["mode"] = codec.MODE_CODE["navigating"]
    back = codec.unpack_samples(codec.pack_samples(arr))
    assert np.array_equal(back, arr)
    import zlib

    with pytest.raises(codec.CodecError):
        codec.unpack_samples(zlib.compress(b"\x00" * 5))


@pytest.mark.parametrize("name", sorted(DEFS))
def test_every_schema_parses_with_the_ros2_serializer(name: str) -> None:
    text = msgdef(name)
    assert name in serialize_dynamic(name, text)
    for dep in dependencies(name):
        assert f"MSG: {dep}\n" in text


def test_summary_metrics_from_samples_and_events() -> None:
    n = 51
    s = np.zeros(n, dtype=codec.SAMPLE_DTYPE)
    s["t"] = np.arange(n) * 0.1
    s["ox"] = np.arange(n) * 0.02  # 1 m in 5 s
    s["vx"] = 0.2
    s["vx"][10] = 0.5
    s["wz"] = -0.3
    s["clearance"] = np.nan
    s["clearance"][20] = 0.12
    s["mode"][25:] = codec.MODE_CODE["estop"]
    events = [
        {"t": 1.0, "type": "estop"},
        {"t": 2.0, "type": "recovery", "behavior": "spin"},
        {"t": 3.0, "type": "recovery", "behavior": "backup"},
        {"t": 3.5, "type": "plan_failed"},
        {"t": 4.0, "type": "collision"},
    ]
    out = summarize(s, events, [{"outcome": "succeeded"}, {"outcome": "failed"}, {"outcome": "succeeded"}])
    assert out["distance_m"] == pytest.approx(1.0) and out["duration_s"] == pytest.approx(5.0)
    assert out["max_speed"] == pytest.approx(0.5)
    assert out["mean_speed"] == pytest.approx((0.2 * 50 + 0.5) / 51, abs=1e-3)  # rounded to mm/s
    assert out["max_angular_speed"] == pytest.approx(0.3) and out["min_clearance_m"] == pytest.approx(0.12)
    assert (out["goals"], out["goals_reached"], out["goals_failed"]) == (3, 2, 1)
    assert out["recoveries"] == 2 and out["recovery_behaviors"] == {"spin": 1, "backup": 1}
    assert (out["estops"], out["collisions"], out["plan_failures"]) == (1, 1, 1)
    assert out["mode_time_s"] == {"idle": 2.5, "estop": 2.5}
    assert outcome_for("navigation", out, aborted=False) == "failed"
    assert outcome_for("navigation", {"goals_reached": 1, "goals_failed": 0}, aborted=False) == "succeeded"
    assert outcome_for("teleop", out, aborted=True) == "aborted"
    empty = summarize(np.zeros(0, dtype=codec.SAMPLE_DTYPE), [])
    assert empty["samples"] == 0 and empty["max_speed"] is None
