"""Sign-in in a real browser when the server requires it (as when bound to a non-local address).

The 3D view is off here (the page works without it); this module is about the login page, the
session cookie and a viewer's browser that must never move the robot.
"""

from __future__ import annotations

import pathlib
import time
from collections.abc import Iterator

import pytest
from conftest import ARTIFACTS, BROWSER_MARKS, make_settings
from test_dashboard_browser import LONG

from app.auth import UserStore
from app.embedded import EmbeddedServer, serve_in_thread

pytestmark = BROWSER_MARKS

OPERATOR = ("olga", "operator-pass-1")
VIEWER = ("victor", "viewer-pass-1")


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EmbeddedServer]:
    tmp = tmp_path_factory.mktemp("dash-auth")
    with serve_in_thread(make_settings(tmp, require_auth=True)) as s:
        store = UserStore(s.runtime.engine)
        store.add_user(*OPERATOR, role="operator")
        store.add_user(*VIEWER, role="viewer")
        yield s


def new_page(browser):
    ctx = browser.new_context(
        viewport={"width": 1024, "height": 768}, bypass_csp=True
    )  # see test_dashboard_browser
    ctx.set_default_timeout(LONG)
    return ctx, ctx.new_page()


def sign_in(page, who: tuple[str, str]) -> None:
    page.get_by_label("Username").fill(who[0])
    page.get_by_label("Password").fill(who[1])
    page.get_by_role("button", name="Sign in").click()


def test_sign_in_flow(browser, server: EmbeddedServer) -> None:
    ctx, page = new_page(browser)
    try:
        page.goto(server.url + "/maps.html")
        page.wait_for_url("**/login.html?next=%2Fmaps.html")
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "dashboard_login.png"), timeout=LONG)
        sign_in(page, (OPERATOR[0], "not-the-password"))
        page.wait_for_selector("#login-error:has-text('wrong username or password')")
        assert "navdeck_session" not in {c["name"] for c in ctx.cookies()}
        time.sleep(0.6)  # the throttle's first back-off
        sign_in(page, OPERATOR)
        page.wait_for_url("**/maps.html")
        page.wait_for_selector("#user-name:has-text('olga (operator)')")
        cookie = next(c for c in ctx.cookies() if c["name"] == "navdeck_session")
        assert cookie["httpOnly"] and cookie["sameSite"] == "Strict"
        assert page.evaluate("document.cookie").find("navdeck_session") < 0  # not readable by scripts
        page.goto(server.url + "/")
        page.wait_for_function("document.querySelector('#st-pose').textContent.startsWith('x ')")
        page.get_by_role("button", name="Sign out").click()
        page.wait_for_url("**/login.html**")
    finally:
        ctx.close()


def test_viewer_browser_cannot_drive(browser, server: EmbeddedServer) -> None:
    session = server.runtime.session
    ctx, page = new_page(browser)
    try:
        page.goto(server.url + "/")
        page.wait_for_url("**/login.html**")
        sign_in(page, VIEWER)
        page.wait_for_url(server.url + "/")
        page.wait_for_function("document.querySelector('#st-pose').textContent.startsWith('x ')")
        page.wait_for_selector("#user-name:has-text('victor (viewer)')")
        assert page.locator("#take-control").is_disabled()
        pose = session.pose
        page.locator("#st-pose").click()
        page.keyboard.down("w")
        page.wait_for_timeout(1000)
        page.keyboard.up("w")
        page.wait_for_selector("#messages li.error:has-text('viewers cannot drive')")
        assert page.get_by_role("button", name="Teleop: drive by hand").is_disabled()
        assert page.get_by_role("button", name="Start mapping").is_disabled()
        r = page.request.post(
            server.url + "/api/robot/mode", data={"mode": "teleop"}
        )  # the server says no too
        assert r.status == 403 and "viewer" in r.json()["detail"]
        assert session.pose.distance_to(pose) < 1e-3 and session.modes.mode.value == "idle"
        page.screenshot(path=str(ARTIFACTS / "dashboard_viewer.png"), timeout=LONG)
        page.get_by_role("button", name="Emergency stop").click()  # e-stop: allowed for everyone
        page.wait_for_function("document.querySelector('#mode-badge').textContent.startsWith('estop')")
        assert session.estop_latched
    finally:
        ctx.close()
    session.reset()


def test_maps_page_gallery_and_import(browser, server: EmbeddedServer) -> None:
    """Signed in as an operator: stock maps show with thumbnails; an import shows upload progress."""

    ctx, page = new_page(browser)
    try:
        page.goto(server.url + "/maps.html")
        sign_in(page, OPERATOR)
        page.wait_for_url("**/maps.html")
        page.wait_for_selector(".card h3:has-text('apartment')")
        img = page.locator(".card img").first
        img.wait_for()
        page.wait_for_function(
            "[...document.querySelectorAll('.card img')].some(i => i.complete && i.naturalWidth > 0)"
        )
        assert page.get_by_role("link", name="download apartment map.yaml").count() >= 1
        page.screenshot(path=str(ARTIFACTS / "dashboard_maps.png"), timeout=LONG)
        if "/api/maps/import" not in server.app.openapi()["paths"]:
            pytest.skip("POST /api/maps/import is not in this server yet (mapping issue)")
        stock = pathlib.Path(__file__).resolve().parent.parent / "maps" / "stock"
        page.set_input_files("#import-yaml", str(stock / "office.yaml"))
        page.set_input_files("#import-image", str(stock / "office.pgm"))
        page.fill("#import-name", "imported office")
        cards = page.locator(".card").count()
        page.get_by_role("button", name="Import").click()
        page.wait_for_function(f"document.querySelectorAll('.card').length > {cards}")
        assert page.locator("#import-progress").evaluate("p => p.value") == 1
    finally:
        ctx.close()
