"""The Runs page in a real browser (headless chromium): list, detail plots, replay in the 3D view."""

from __future__ import annotations

import pathlib
import time
from datetime import UTC, datetime

import pytest
from conftest import ARTIFACTS, BROWSER_MARKS, make_settings

from app.embedded import serve_in_thread
from bench.runs import synth_run

pytestmark = BROWSER_MARKS


def test_runs_page_lists_shows_a_run_and_replays_it_in_3d(tmp_path: pathlib.Path, browser) -> None:
    sync_api = pytest.importorskip("playwright.sync_api")
    expect = sync_api.expect  # no string-evaluated predicates: the page's CSP forbids eval
    with serve_in_thread(make_settings(tmp_path, viewer=True)) as server:
        rt = server.runtime
        store = rt.features["recording"].store
        grid = rt.session.grid
        g = grid.geometry
        synth_run(store, kind="teleop", duration_s=5.0, started_at=datetime(2026, 2, 1, tzinfo=UTC))
        rid = synth_run(
            store,
            duration_s=30.0,
            map_id=1,
            grid=grid,
            started_at=datetime(2026, 2, 2, tzinfo=UTC),
            events=[
                {"t": 4.0, "type": "estop", "reason": "operator"},
                {"t": 9.0, "type": "recovery", "behavior": "spin"},
            ],
            goals=[
                {"t": 1.0, "x": g.origin.x + 3.0, "y": g.origin.y + 3.0, "theta": 0.0, "outcome": "succeeded"}
            ],
        )
        errors: list[str] = []
        page = browser.new_page(viewport={"width": 1400, "height": 900})
        try:
            page.on("pageerror", lambda exc: errors.append(str(exc)))
            page.goto(f"{server.url}/runs.html")
            page.wait_for_selector("tr.run", timeout=30_000)
            assert page.locator("tr.run").count() == 2
            assert page.locator("tr.run").first.get_attribute("data-id") == str(rid)
            page.select_option("#filters select[name=kind]", "teleop")
            page.click("#filters button[type=submit]")
            expect(page.locator("tr.run")).to_have_count(1, timeout=60_000)
            page.select_option("#filters select[name=kind]", "")
            page.click("#filters button[type=submit]")
            expect(page.locator("tr.run")).to_have_count(2, timeout=60_000)
            page.click(f"tr.run[data-id='{rid}']")
            page.wait_for_selector("#traj polyline", timeout=10_000)
            assert page.locator("#traj image").count() == 1
            assert page.locator("#speed polyline").count() == 2
            assert page.locator("#timeline circle").count() == 3  # mode, estop, recovery
            assert "estop" in page.locator("#event-list").inner_text()
            assert page.locator("#downloads a").count() == 3
            page.click("#replay-load")
            page.wait_for_selector("#replay-view:not([hidden])", timeout=30_000)
            player = rt.features["recording"].replay
            deadline = time.monotonic() + 60
            while not player.viewer.server.get_clients() and time.monotonic() < deadline:
                page.wait_for_timeout(100)
            assert player.viewer.server.get_clients(), "replay view never connected through /replay/viz"
            page.select_option("#replay-speed", "10")
            click = "(sel) => document.querySelector(sel).click()"  # no wait for a 'stable' layout
            page.evaluate(click, "#replay-play")
            deadline = time.monotonic() + 60
            while player.state()["t"] <= 0.5 and time.monotonic() < deadline:
                time.sleep(0.05)
            page.evaluate(click, "#replay-pause")
            deadline = time.monotonic() + 30
            while player.state()["playing"] and time.monotonic() < deadline:
                time.sleep(0.05)
            st = player.state()
            assert st["speed"] == 10.0 and 0.5 < st["t"] <= st["duration"] and not st["playing"]
            # the view shows the paused instant once the replay thread's last frame is out (a loaded
            # machine's in-flight frame once lagged the paused time by 0.9 s of the run)
            deadline = time.monotonic() + 15
            while abs(player.bus.latest.stamp - st["t"]) > 0.2 and time.monotonic() < deadline:
                time.sleep(0.05)
            assert player.bus.latest.stamp == pytest.approx(st["t"], abs=0.2)
            ARTIFACTS.mkdir(exist_ok=True)
            page.screenshot(path=str(ARTIFACTS / "runs.png"), timeout=90_000)
        finally:
            page.close()
        assert errors == []
