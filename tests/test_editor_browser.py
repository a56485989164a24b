"""The map editor on the Maps page in a real browser (Debian chromium): draw a line wall and a
keepout zone on the active map, undo/redo, save a version, which is not activated; a self-crossing
zone is refused in the page before any request; the operator activates the version and a goal whose
shortest route crossed the zone is reached around it (issue 19)."""

from __future__ import annotations

import time
from collections.abc import Iterator

import httpx
import pytest
from conftest import ARTIFACTS, BROWSER_MARKS, make_settings, operator_page

from app.embedded import EmbeddedServer, serve_in_thread

pytestmark = BROWSER_MARKS
LONG = 60_000


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EmbeddedServer]:
    with serve_in_thread(make_settings(tmp_path_factory.mktemp("editor"))) as s:
        yield s


def canvas_xy(page, x: float, y: float, m: dict) -> tuple[float, float]:
    """Page pixel of map point (x, y) on the editor canvas (one cell = ``scale`` pixels, top = max y)."""
    box = page.locator("#ed-canvas").bounding_box()
    col = (x - m["origin"][0]) / m["resolution"]
    row_top = m["height"] - (y - m["origin"][1]) / m["resolution"]
    return box["x"] + col * box["width"] / m["width"], box["y"] + row_top * box["height"] / m["height"]


def test_draw_wall_and_zone_save_a_version(browser, server: EmbeddedServer) -> None:
    api = httpx.Client(base_url=server.url, timeout=10.0)
    maps = api.get("/api/maps?limit=500").json()
    m = next(i for i in maps["items"] if i["id"] == maps["active_map_id"])
    ctx = browser.new_context(viewport={"width": 1280, "height": 900}, bypass_csp=True)
    ctx.set_default_timeout(LONG)
    page = ctx.new_page()
    answers = iter(["wet floor"])  # the bow tie is refused before its name is asked
    page.on("dialog", lambda d: d.accept(next(answers)) if d.type == "prompt" else d.accept())
    try:
        page.goto(server.url + "/maps.html")
        page.get_by_role("button", name=f"edit {m['name']}: walls, erasing, zones, places").first.click()
        page.wait_for_selector("#editor:not([hidden])")

        page.select_option("#ed-tool", "line")  # a wall the lidar cannot see, y = 2 m, x 1..5 m
        page.mouse.move(*canvas_xy(page, 1.0, 2.0, m))
        page.mouse.down()
        page.mouse.move(*canvas_xy(page, 3.0, 2.0, m), steps=4)
        page.mouse.move(*canvas_xy(page, 5.0, 2.0, m), steps=4)
        page.mouse.up()
        assert page.locator("#ed-count").inner_text().startswith("1 edit")
        page.get_by_role("button", name="undo the last edit").click()
        assert page.locator("#ed-count").inner_text().startswith("0 edits")
        page.get_by_role("button", name="redo the last undone edit").click()
        assert page.locator("#ed-count").inner_text().startswith("1 edit")

        page.select_option("#ed-tool", "keepout")  # a bow tie: refused in the page, nothing sent
        for x, y in ((6.5, 1.0), (7.5, 2.0), (7.5, 1.0), (6.5, 2.0)):
            page.mouse.click(*canvas_xy(page, x, y, m))
        page.get_by_role("button", name="close the polygon being drawn").click()
        page.wait_for_selector("#messages li:has-text('intersects itself')")
        assert api.get(f"/api/maps/{m['id']}/zones").json()["total"] == 0
        page.select_option("#ed-tool", "keepout")  # starts a new polygon
        for x, y in ((2.0, 2.9), (2.4, 2.9), (2.4, 4.9), (2.0, 4.9)):
            page.mouse.click(*canvas_xy(page, x, y, m))
        page.get_by_role("button", name="close the polygon being drawn").click()
        page.wait_for_selector("#messages li:has-text('saved on map')")
        zones = api.get(f"/api/maps/{m['id']}/zones").json()["items"]
        assert [z["kind"] for z in zones] == ["keepout"]
        ARTIFACTS.mkdir(exist_ok=True)
        page.locator("#editor").screenshot(path=str(ARTIFACTS / "editor.png"), timeout=LONG)

        page.get_by_role("button", name="save the edits as a new version of the map").click()
        page.wait_for_selector("#messages li:has-text('version 2')")
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            items = api.get("/api/maps?limit=500").json()["items"]
            v2 = [i for i in items if i["parent_id"] == m["id"]]
            if v2:
                break
            time.sleep(0.1)
        assert v2 and v2[0]["version"] == 2 and not v2[0]["active"]  # saved, not activated
        assert [z["name"] for z in api.get(f"/api/maps/{v2[0]['id']}/zones").json()["items"]] == ["wet floor"]
        pgm_old = api.get(f"/api/maps/{m['id']}/map.pgm").content
        assert api.get(f"/api/maps/{v2[0]['id']}/map.pgm").content != pgm_old  # the wall is in v2 only

        # the operator activates v2 on the page; a goal whose straight route crosses the zone is reached
        # around it (the robot has not moved: it is at the sim's start, 3.0, 3.5)
        page.goto(server.url + "/maps.html")
        page.get_by_role("button", name=f"make {v2[0]['name']} the active map").click()
        deadline = time.monotonic() + 30
        while api.get("/api/maps?limit=500").json()["active_map_id"] != v2[0]["id"]:
            assert time.monotonic() < deadline, "v2 not activated"
            time.sleep(0.1)
        assert api.post("/api/control/acquire", json={"take_over": True}).status_code == 200
        r = api.post("/api/localization/initial_pose", json={"x": 3.0, "y": 3.5, "theta": 0.0})
        assert r.status_code == 200, r.text
        r = api.post("/api/navigation/goals", json={"x": 1.2, "y": 3.5, "theta": 3.14})
        assert r.status_code == 200, r.text
        poses, state = [], {}
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:
            state = api.get("/api/navigation").json()
            poses.append(api.get("/api/robot").json()["pose"])
            if state["outcome"] is not None and not state["active"]:
                break
            time.sleep(0.05)
        assert state["outcome"] is not None and state["outcome"]["kind"] == "succeeded", state
        inside = [p for p in poses if 2.0 <= p["x"] <= 2.4 and 2.9 <= p["y"] <= 4.9]
        assert not inside, inside[:3]
        assert any(2.0 <= p["x"] <= 2.4 for p in poses)  # it crossed the zone's x band, around the zone
    finally:
        ctx.close()
        api.close()


def test_go_to_a_place_from_the_live_page(browser, server: EmbeddedServer) -> None:
    api = httpx.Client(base_url=server.url, timeout=10.0)
    map_id = api.get("/api/maps?limit=1").json()["active_map_id"]
    r = api.post(f"/api/maps/{map_id}/places", json={"name": "sofa", "x": 1.5, "y": 3.5, "theta": 3.14})
    assert r.status_code == 201
    # where the robot is (the first test drove it): an initial pose elsewhere is refused (scan fit)
    here = api.get("/api/robot").json()["pose"]
    assert (
        api.post(
            "/api/localization/initial_pose", json={"x": here["x"], "y": here["y"], "theta": here["theta"]}
        ).status_code
        == 200
    )
    # the page's operator takes control (the test's API client held it) and localizes
    try:
        with operator_page(
            browser, server.url, {"x": here["x"], "y": here["y"], "theta": here["theta"]}, LONG
        ) as page:
            page.wait_for_selector("#place-select option[value='sofa']", state="attached")
            page.select_option("#place-select", "sofa")
            page.get_by_role("button", name="Go to the chosen place").click()
            deadline = time.monotonic() + 20
            goals = []
            while not goals and time.monotonic() < deadline:
                page.wait_for_timeout(100)
                goals = api.get("/api/navigation").json()["goals"]
            assert goals and goals[0]["x"] == 1.5 and goals[0]["y"] == 3.5
    finally:
        api.post("/api/navigation/cancel")
        api.close()
