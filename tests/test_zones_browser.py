"""The Zones layer in a real browser (headless chromium + SwiftShader) through the relay: the apartment
map with a keepout and a speed zone renders; the screenshot is docs/editor.md's picture."""

from __future__ import annotations

import pathlib
import time

import numpy as np
from conftest import BROWSER_MARKS
from test_viewer_relay import Served
from test_viewer_scene import FOOTPRINT, snap

from app.bus import SnapshotBus
from app.viewer.scene import Viewer
from maps.mapio import load_map_yaml

ROOT = pathlib.Path(__file__).resolve().parent.parent
ARTIFACTS = ROOT / "test-artifacts"

pytestmark = BROWSER_MARKS


def test_zones_layer_renders_in_the_browser(browser) -> None:
    viewer = Viewer(SnapshotBus(), footprint=FOOTPRINT)
    viewer.start()
    try:
        grid = load_map_yaml(ROOT / "maps/stock/apartment.yaml")
        keepout = np.array([[2.0, 2.9], [2.4, 2.9], [2.4, 4.95], [2.0, 4.95]])
        speed = np.array([[6.2, 0.4], [9.0, 0.4], [9.0, 2.4], [6.2, 2.4]])
        layer = (("keepout", "wet floor (keepout)", keepout), ("speed", "aisle (30 %)", speed))
        viewer.apply(snap(grid=grid, grid_version=1, extras={"zone_layer": layer}))
        with Served(viewer) as served:
            page = browser.new_page(viewport={"width": 960, "height": 600})
            try:
                page.goto(f"http://127.0.0.1:{served.port}/viz/?fixedDpr=1")
                page.wait_for_selector("canvas", timeout=60_000)
                deadline = time.monotonic() + 60
                while not viewer.server.get_clients() and time.monotonic() < deadline:
                    page.wait_for_timeout(100)
                assert viewer.server.get_clients(), "browser never registered with viser through the relay"
                assert viewer.is_shown("/zones")
                page.wait_for_timeout(2500)  # let the map textures arrive and render
                ARTIFACTS.mkdir(exist_ok=True)
                page.screenshot(path=str(ARTIFACTS / "zones.png"), timeout=90_000)
            finally:
                page.close()
    finally:
        viewer.stop()
