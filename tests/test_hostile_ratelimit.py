"""Rate limits on the control endpoints (issue 9 part 5, app/ratelimit.py): a per-client token bucket,
429 with Retry-After when empty, and the e-stop never limited."""

from __future__ import annotations

import time

import pytest

from app.ratelimit import RateLimiter, is_limited


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_bucket_allows_a_burst_then_refills_at_its_rate() -> None:
    clock = FakeClock()
    rl = RateLimiter(rate=2.0, burst=3.0, clock=clock)
    assert [rl.take("a", "1.2.3.4") for _ in range(3)] == [0.0, 0.0, 0.0]
    wait = rl.take("a", "1.2.3.4")
    assert wait == pytest.approx(0.5) and rl.retry_after(wait) == 1
    assert rl.take("b", "1.2.3.4") == 0.0  # another client on the same address has its own bucket
    clock.t += 0.5
    assert rl.take("a", "1.2.3.4") == 0.0 and rl.take("a", "1.2.3.4") > 0.0


def test_rotating_client_ids_hits_the_address_bucket() -> None:
    rl = RateLimiter(rate=1.0, burst=2.0, per_address=3.0, clock=FakeClock())
    allowed = sum(rl.take(f"client-{i}", "6.6.6.6") == 0.0 for i in range(50))
    assert allowed == 6  # 3 clients wide
    assert rl.take("fresh", "7.7.7.7") == 0.0


def test_which_requests_are_limited() -> None:
    assert is_limited("POST", "/api/robot/mode") and is_limited("POST", "/api/robot/reset")
    assert is_limited("POST", "/api/navigation/goals") and is_limited("POST", "/api/mapping/start")
    assert is_limited("POST", "/api/control/acquire") and is_limited("POST", "/api/localization/initial_pose")
    assert not is_limited("POST", "/api/robot/estop")
    assert not is_limited("GET", "/api/robot") and not is_limited("GET", "/api/navigation")
    assert not is_limited("POST", "/api/auth/login")  # its own throttle (app.auth)


def test_control_flood_gets_429_with_retry_after_and_estop_always_works(client) -> None:
    statuses = []
    for _ in range(300):
        r = client.post("/api/robot/mode", json={"mode": "idle"})
        statuses.append(r.status_code)
        if r.status_code == 429:
            break
    assert statuses[-1] == 429, f"no 429 after {len(statuses)} requests"
    assert statuses.count(200) >= 20  # the burst is honoured
    after = int(r.headers["retry-after"])
    assert after >= 1 and "too many control requests" in r.json()["detail"]
    for _ in range(60):  # the e-stop is never limited, even for a client that is being limited
        assert client.post("/api/robot/estop").status_code == 200
    assert client.get("/api/robot").json()["mode"] == "estop"
    time.sleep(after)
    assert client.post("/api/robot/reset").status_code == 200


def test_429_is_documented_on_limited_operations_only(client) -> None:
    paths = client.get("/openapi.json").json()["paths"]
    assert "429" in paths["/api/robot/mode"]["post"]["responses"]
    assert "429" in paths["/api/navigation/goals"]["post"]["responses"]
    assert "429" not in paths["/api/robot/estop"]["post"]["responses"]
    assert "429" not in paths["/api/maps"]["get"]["responses"]
