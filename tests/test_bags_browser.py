"""A recorded bag imported on the Runs page in a real browser (headless chromium): upload with a
progress bar, the run shown like a live one (what the reader chose, trajectory over the SLAM map),
then replayed in the 3D view (issue 21)."""

from __future__ import annotations

import pathlib
import time

import pytest
from conftest import ARTIFACTS, BROWSER_MARKS, make_settings
from test_bags import ROS1

from app.embedded import serve_in_thread

pytestmark = BROWSER_MARKS


def test_import_a_bag_on_the_runs_page_and_replay_it(tmp_path: pathlib.Path, browser) -> None:
    sync_api = pytest.importorskip("playwright.sync_api")
    expect = sync_api.expect
    with serve_in_thread(make_settings(tmp_path, viewer=True)) as server:
        rt = server.runtime
        errors: list[str] = []
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        try:
            page.on("pageerror", lambda exc: errors.append(str(exc)))
            page.goto(f"{server.url}/runs.html")
            expect(page.locator("#runs-body")).to_contain_text("no runs match", timeout=30_000)
            page.set_input_files("#bag-file", str(ROS1))
            page.click("#bag-submit")
            expect(page.locator("#bag-progress")).to_be_visible(timeout=10_000)
            expect(page.locator("#bag-status")).to_contain_text("run #", timeout=240_000)
            run_id = int(page.locator("#bag-status").inner_text().split("#")[1])
            expect(page.locator("tr.run")).to_have_count(1, timeout=30_000)
            assert page.locator("tr.run").first.get_attribute("data-id") == str(run_id)
            assert float(page.locator("#bag-progress").get_attribute("value") or 0) == 1.0
            # the run's detail opens by itself, with what the reader found in the bag
            expect(page.locator("#import-notes")).to_contain_text(
                "scan topic: /base_scan (the only LaserScan topic)", timeout=30_000
            )
            assert f"imported from {ROS1.name}: 205 scans" in page.locator("#import-notes").inner_text()
            page.wait_for_selector("#traj polyline", timeout=30_000)
            assert page.locator("#traj image").count() == 1  # the map offline SLAM built
            assert page.locator("#speed polyline").count() == 2
            page.click("#replay-load")
            page.wait_for_selector("#replay-view:not([hidden])", timeout=30_000)
            player = rt.features["recording"].replay
            deadline = time.monotonic() + 60
            while not player.viewer.server.get_clients() and time.monotonic() < deadline:
                page.wait_for_timeout(100)
            assert player.viewer.server.get_clients(), "replay view never connected through /replay/viz"
            page.select_option("#replay-speed", "10")
            page.evaluate("(sel) => document.querySelector(sel).click()", "#replay-play")
            deadline = time.monotonic() + 60
            while player.state()["t"] <= 5.0 and time.monotonic() < deadline:
                time.sleep(0.05)
            st = player.state()
            assert st["run_id"] == run_id and st["t"] > 5.0
            assert player.bus.latest.scan is not None and player.bus.latest.grid is not None
            page.evaluate("(sel) => document.querySelector(sel).click()", "#replay-pause")
            page.wait_for_timeout(1500)  # let the 3D view draw the paused frame
            ARTIFACTS.mkdir(exist_ok=True)
            page.screenshot(path=str(ARTIFACTS / "runs-imported-bag.png"), timeout=90_000)
        finally:
            page.close()
        assert errors == []
