"""Explore with one click in a real browser (headless chromium): start Explore in the apartment, watch
the frontier count in the status panel shrink as the robot maps, stop, and save the explored map.
The screenshot of the dashboard while exploring goes to ``test-artifacts/`` (docs/exploration.md)."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
from conftest import ARTIFACTS, BROWSER_MARKS, make_settings

from app.embedded import EmbeddedServer, serve_in_thread

LONG = 120_000  # ms: the page can stall while the 3D view renders in software

pytestmark = BROWSER_MARKS


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EmbeddedServer]:
    with serve_in_thread(make_settings(tmp_path_factory.mktemp("explore"), viewer=True)) as s:
        yield s


@pytest.fixture(scope="module")
def page(browser, server: EmbeddedServer):
    ctx = browser.new_context(viewport={"width": 1280, "height": 800}, bypass_csp=True)
    ctx.set_default_timeout(LONG)
    p = ctx.new_page()
    p.on("dialog", lambda d: d.accept("explored apartment") if d.type == "prompt" else d.accept())
    yield p
    ctx.close()


def frontiers(page) -> int | None:
    text = page.locator("#st-explore").get_attribute("data-frontiers")
    return int(text) if text else None


def test_explore_watch_frontiers_shrink_and_save(page, server: EmbeddedServer) -> None:
    page.goto(server.url + "/")
    page.wait_for_function("document.querySelector('#mode-badge').textContent.length > 1", timeout=LONG)
    page.get_by_role("button", name="Explore: map the place by driving to its frontiers").click()
    page.wait_for_function(
        "document.querySelector('#mode-badge').textContent.startsWith('mapping')", timeout=LONG
    )
    page.wait_for_function("document.querySelector('#st-explore').dataset.frontiers > 0", timeout=LONG)
    most = frontiers(page) or 0
    shrunk = False
    end = time.monotonic() + 420.0  # real time: the robot drives at 0.26 m/s
    while time.monotonic() < end:
        n = frontiers(page)
        state = page.locator("#st-explore").get_attribute("data-state")
        if n is not None and n < most:
            shrunk = True
            break
        if state not in (None, "exploring"):
            break
        most = max(most, n or 0)
        page.wait_for_timeout(500)
    assert shrunk, f"the frontier count never fell below its peak {most}"
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "exploration_dashboard.png"), timeout=LONG)
    assert server.runtime.viewer is not None
    assert server.runtime.viewer.is_shown("/frontiers")  # the 3D view's Frontiers layer has them
    page.get_by_role("button", name="Stop exploring").click()
    page.get_by_role("button", name="Save the explored map").click()  # prompt answered by the fixture
    page.wait_for_function(
        "[...document.querySelectorAll('#messages li')].some(li => li.textContent.includes('saved'))",
        timeout=LONG,
    )
    assert server.runtime.maps.find("explored apartment") is not None
