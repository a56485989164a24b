"""Real browser (headless chromium + SwiftShader) through the relay: the page renders and a click lands."""

from __future__ import annotations

import pathlib
import time

import numpy as np
from conftest import BROWSER_MARKS
from test_viewer_relay import Served
from test_viewer_scene import FOOTPRINT, make_scan, office_grid, snap

from app.bus import SnapshotBus
from app.viewer.scene import Viewer
from nav.types import Path, Pose2D

ARTIFACTS = pathlib.Path(__file__).resolve().parent.parent / "test-artifacts"

pytestmark = BROWSER_MARKS


def test_browser_renders_viewer_and_click_sets_goal(browser) -> None:
    got: list[tuple[str, Pose2D]] = []
    viewer = Viewer(SnapshotBus(), footprint=FOOTPRINT, on_pose_input=lambda k, p, _tab: got.append((k, p)))
    viewer.start()
    try:
        path = Path(np.column_stack((np.linspace(0, 8, 40), np.linspace(0, 4, 40), np.zeros(40))))
        particles = np.random.default_rng(0).normal([1.0, 2.0, 0.0], [0.3, 0.3, 0.3], (300, 3))
        viewer.apply(
            snap(grid=office_grid(), grid_version=1, scan=make_scan(), path=path, particles=particles)
        )
        with Served(viewer) as served:
            page = browser.new_page(viewport={"width": 960, "height": 600})
            try:
                page.goto(f"http://127.0.0.1:{served.port}/viz/?fixedDpr=1")
                page.wait_for_selector("canvas", timeout=60_000)
                deadline = time.monotonic() + 60
                while not viewer.server.get_clients() and time.monotonic() < deadline:
                    page.wait_for_timeout(100)
                assert viewer.server.get_clients(), "browser never registered with viser through the relay"
                page.wait_for_timeout(2500)  # let the map textures arrive and render
                ARTIFACTS.mkdir(exist_ok=True)
                page.screenshot(path=str(ARTIFACTS / "viewer.png"), timeout=90_000)
                page.mouse.click(300, 330)  # the camera looks down at the map: this pixel is ground
                deadline = time.monotonic() + 10
                while not got and time.monotonic() < deadline:
                    page.wait_for_timeout(100)
                # Rviz-style "2D Goal Pose": Shift + press on the map, drag to the right, release.
                page.keyboard.down("Shift")
                page.mouse.move(300, 360)
                page.mouse.down()
                page.mouse.move(420, 360, steps=12)
                page.mouse.up()
                page.keyboard.up("Shift")
                deadline = time.monotonic() + 10
                while len(got) < 2 and time.monotonic() < deadline:
                    page.wait_for_timeout(100)
            finally:
                page.close()
        assert (ARTIFACTS / "viewer.png").stat().st_size > 10_000
        assert got and got[0][0] == "goal" and got[0][1].is_finite()
        assert len(got) == 2, "shift+drag on the map did not set a pose"
        kind, pose = got[1]
        assert kind == "goal" and abs(pose.theta) < 0.6  # dragged towards screen-right: world +x here
    finally:
        viewer.stop()
