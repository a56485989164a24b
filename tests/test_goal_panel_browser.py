"""The Live page's goal panel in a real browser (Debian chromium): waypoints sent as a patrol show the
mission's legs with their outcomes, reached legs as they are reached and, after a cancel, the
cancelled leg with its reason (issue 19)."""

from __future__ import annotations

from collections.abc import Iterator

import httpx
import pytest
from conftest import ARTIFACTS, BROWSER_MARKS, make_settings, operator_page

from app.embedded import EmbeddedServer, serve_in_thread

pytestmark = BROWSER_MARKS
LONG = 120_000


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EmbeddedServer]:
    with serve_in_thread(make_settings(tmp_path_factory.mktemp("goalpanel"))) as s:
        yield s


def test_patrol_legs_and_outcomes_in_the_goal_panel(browser, server: EmbeddedServer) -> None:
    api = httpx.Client(base_url=server.url, timeout=10.0)
    try:
        with operator_page(browser, server.url, {"x": 3.0, "y": 3.5}, LONG) as page:
            for x, y in ((2.4, 3.5), (3.0, 3.0)):  # two near, free spots of the apartment's living room
                page.fill("#goal-form input[name=x]", str(x))
                page.fill("#goal-form input[name=y]", str(y))
                page.get_by_role("button", name="Add waypoint to the list").click()
            page.check("#route-patrol")
            page.get_by_role("button", name="Navigate through the waypoints").click()
            # a patrol starts with two laps queued: four legs, the first active
            page.wait_for_function("document.querySelectorAll('#mission-legs li').length >= 4")
            page.wait_for_selector("#mission-legs li.leg-reached")  # a leg reached, shown as such
            mission = api.get("/api/missions?limit=1").json()["items"][0]
            assert mission["state"] == "active"
            r = page.request.post(server.url + f"/api/missions/{mission['id']}/cancel")
            assert r.ok, r.text()
            page.wait_for_selector("#mission-legs li.leg-canceled")
            assert "canceled" in (page.text_content("#mission-head") or "")
            text = page.text_content("#mission-legs") or ""
            assert "reached" in text and "operator_cancel" in text
            ARTIFACTS.mkdir(exist_ok=True)  # docs/editor.md's picture of the panel
            page.locator("section[aria-labelledby=goals-h]").screenshot(
                path=str(ARTIFACTS / "goal-panel.png")
            )
    finally:
        api.post("/api/navigation/cancel")
        api.close()


def test_unknown_space_box_sends_the_waypoints_with_allow_unknown(browser, server: EmbeddedServer) -> None:
    """Navigating while mapping from the panel: ticked, the waypoints go with Nav2's allow_unknown;
    unticked, without it (the server then refuses a waypoint in unknown space)."""
    with operator_page(browser, server.url, {"x": 3.0, "y": 3.5}, LONG) as page:
        sent = []
        for ticked in (False, True):
            page.set_checked("#goals-unknown", ticked)
            page.fill("#goal-form input[name=x]", "2.4")
            page.fill("#goal-form input[name=y]", "3.5")
            page.get_by_role("button", name="Add waypoint to the list").click()
            with page.expect_request(
                lambda req: req.url.endswith("/api/navigation/goals") and req.method == "POST"
            ) as request:
                page.get_by_role("button", name="Navigate through the waypoints").click()
            sent.append(request.value.post_data_json)
            page.request.post(server.url + "/api/navigation/cancel")
        assert "allow_unknown" not in sent[0]
        assert sent[1]["allow_unknown"] is True and (sent[1]["x"], sent[1]["y"]) == (2.4, 3.5)
