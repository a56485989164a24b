"""Take the exploration screenshots of docs/exploration.md from a running dashboard.

Each shot needs a fresh simulated dashboard in the stock apartment (``./scripts/serve.sh --port 8801
--db sqlite:////tmp/shots/navdeck.db``, a new database file each time), then ``.venv/bin/python
scripts/docs_screenshots.py http://localhost:8801 docs/images SHOT [world]`` (SHOT
``navigate_while_mapping`` or ``exploration``; world: the server's ``--world``, default apartment).
It works the dashboard as an operator would, its requests sent from the page (which holds control):
start mapping and send a goal into space the map has not seen yet (``allow_unknown``, what the 3D
view's "goal in unknown space" click sends), or press Explore. The page is reloaded before the
screenshot, so the 3D view's camera aims at the map as it is then (viser aims a new page's camera,
never a connected one's). Needs playwright and a chromium (``NAVDECK_CHROMIUM``, default
/usr/bin/chromium). About two minutes of real time per shot.
"""

from __future__ import annotations

import json
import os
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np
from playwright.sync_api import Page, sync_playwright

from app.commands.explore import load_world

VIEWPORT = {"width": 1600, "height": 960}
RENDER_MS = 15_000  # the 3D view renders in software in headless chromium
FETCH = """async ([method, path, body]) => {
  const opts = { method, headers: { "Content-Type": "application/json" } };
  if (body !== null) opts.body = JSON.stringify(body);
  const res = await fetch(path, opts);
  return [res.status, res.headers.get("Retry-After"), await res.text()];
}"""


class Refused(Exception):
    def __init__(self, status: int, detail: str) -> None:
        super().__init__(f"{status}: {detail}")
        self.status = status


def call(page: Page, method: str, path: str, body: dict | None = None) -> Any:
    """A request from the page (its session holds control); waits out the server's rate limit."""
    while True:
        status, retry_after, text = page.evaluate(FETCH, [method, path, body])
        if status != 429:
            break
        time.sleep(float(retry_after or 1))
    if status >= 400:
        raise Refused(status, text)
    return json.loads(text or "{}")


def start_pose(base: str, timeout_s: float = 180.0) -> tuple[float, float]:
    """The robot's pose in the stock world before mapping (GET needs no control); waits for the server."""
    end = time.monotonic() + timeout_s
    while True:
        try:
            with urllib.request.urlopen(base + "/api/robot", timeout=30) as resp:
                pose = json.loads(resp.read())["pose"]
            return float(pose["x"]), float(pose["y"])
        except (urllib.error.URLError, ConnectionError):
            if time.monotonic() > end:
                raise
            time.sleep(1.0)


def far_free_points(world_name: str, start_xy: tuple[float, float], clearance: float = 0.3) -> np.ndarray:
    """World points with ``clearance`` in free space, farthest from the start first (one per metre):
    goals the live map has not seen at the start; the first one inside its extent is sent."""
    world = load_world(world_name)
    rows, cols = np.nonzero(world.clearance_map >= clearance)
    keep = (rows % 20 == 0) & (cols % 20 == 0)
    xy = world.geometry.cell_to_world(rows[keep], cols[keep])
    return xy[np.argsort(-np.hypot(xy[:, 0] - start_xy[0], xy[:, 1] - start_xy[1]))]


def send_far_goal(page: Page, candidates: np.ndarray, start_xy: tuple[float, float]) -> None:
    """The farthest candidate the navigator accepts (a goal off the live map's extent is refused)."""
    for x, y in candidates:
        # the map frame starts at the robot's pose when mapping starts (heading 0 in the stock worlds)
        goal = {"x": float(x - start_xy[0]), "y": float(y - start_xy[1]), "theta": 0.0, "allow_unknown": True}
        try:
            call(page, "POST", "/api/navigation/goals", goal)
        except Refused as exc:
            if exc.status != 422:
                raise
            continue
        print(f"goal sent: {goal}", flush=True)
        return
    raise RuntimeError("no goal accepted")


def tidy(page: Page) -> None:
    """Close the viewer's toasts (software WebGL warning) and minimise its control panel."""
    viewer = page.frame_locator("#viewer")
    for button in viewer.locator(".mantine-Notification-closeButton").all():
        button.click()
    minimise = viewer.get_by_label("Minimize panel")
    if minimise.count():
        minimise.first.click()
    for close in page.locator("#messages button").all():
        if close.is_visible():
            close.click()
    page.mouse.move(VIEWPORT["width"] // 3, VIEWPORT["height"] // 2)  # no hover tooltip in the shot


def open_dashboard(page: Page, base: str) -> None:
    """Load the page (its 3D camera aims at the map as it is now) and let the view render."""
    page.goto(base + "/")
    page.wait_for_function("document.querySelector('#mode-badge').textContent.length > 1")
    page.wait_for_timeout(RENDER_MS)
    tidy(page)
    page.wait_for_timeout(3_000)


def screenshot(page: Page, out: Path) -> None:
    page.screenshot(path=str(out))
    print(f"wrote {out}", flush=True)


def navigate_while_mapping(page: Page, base: str, out_dir: Path, world: str) -> None:
    """Mapping, a goal beyond what the map has seen: the path crosses unknown space."""
    start = start_pose(base)
    candidates = far_free_points(world, start)
    call(page, "POST", "/api/mapping/start")
    page.wait_for_timeout(20_000)  # SLAM's first maps: what the lidar sees from the start
    open_dashboard(page, base)
    send_far_goal(page, candidates, start)
    page.wait_for_timeout(8_000)  # the robot on its way
    screenshot(page, out_dir / "navigate_while_mapping.png")
    call(page, "POST", "/api/navigation/cancel")


def exploration(page: Page, base: str, out_dir: Path, world: str) -> None:
    """Explore from the start: frontiers and the chosen one in the view, progress in the panel."""
    call(page, "POST", "/api/exploration/start")
    page.wait_for_timeout(25_000)  # frontiers left to show: the apartment is explored in ~2 min
    open_dashboard(page, base)
    screenshot(page, out_dir / "exploration_dashboard.png")
    call(page, "POST", "/api/exploration/stop")


SHOTS = {"navigate_while_mapping": navigate_while_mapping, "exploration": exploration}


def main(base: str, out_dir: Path, shot: str, world: str) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    start_pose(base)  # the server is up
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=os.environ.get("NAVDECK_CHROMIUM", "/usr/bin/chromium"))
        page = browser.new_page(viewport=VIEWPORT)
        page.set_default_timeout(120_000)
        open_dashboard(page, base)  # the page takes control
        SHOTS[shot](page, base, out_dir, world)
        browser.close()


if __name__ == "__main__":
    if len(sys.argv) < 4 or sys.argv[3] not in SHOTS:
        sys.exit(f"usage: {sys.argv[0]} URL OUT_DIR {{{'|'.join(SHOTS)}}} [world]")
    world_name = sys.argv[4] if len(sys.argv) > 4 else "apartment"
    main(sys.argv[1].rstrip("/"), Path(sys.argv[2]), sys.argv[3], world_name)
