"""The safety feature in a real Runtime (simulated apartment, virtual clock): installed on the session,
stops teleop at the sofa, logs one event per stop."""

from __future__ import annotations

from pathlib import Path

from conftest import make_settings

from nav.types import Pose2D, Twist2D
from robot.clock import VirtualClock


def test_feature_installs_the_filter_and_records_stops(tmp_path: Path) -> None:
    from app.features import discover, safety
    from app.runtime import Runtime

    assert safety in discover() and safety.ORDER == 90
    rt = Runtime.build(make_settings(tmp_path, world="apartment"), clock=VirtualClock())
    try:
        feature = safety.setup(rt)
        s = rt.session
        assert s.safety is feature and feature.filter.profile is rt.profile
        s.driver.options = type(s.driver.options)(ir_stop=False)  # only the filter may stop it
        s.driver.teleport(Pose2D(1.3, 1.8, -1.5707963))  # facing the sofa (y <= 1.1), 0.58 m away
        s.request_mode("teleop")
        for _ in range(round(6.0 / s.period)):
            s.set_teleop(Twist2D(0.26, 0.0, 0.0), "test")
            s.run_for(s.period)
        truth = s.driver.truth_pose
        assert s.collisions == 0
        assert 1.1 < truth.y - 0.12 < 1.1 + 0.08  # drove up to the sofa and stopped just short
        assert s.last_command.vx == 0.0 and (s.safety_stop or "").startswith("stop")
        stops = [e for e in s.events if e["type"] == "safety"]
        assert len(stops) == 1 and stops[0]["action"] == "stop"
        feature.close()
        assert s.safety is None
    finally:
        rt.close()
