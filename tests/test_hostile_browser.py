"""The Content-Security-Policy must not break the pages it protects: in a real browser the dashboard and
viser's 3D view (inline, self-unpacking client) load with zero CSP violations (app/hardening.py)."""

from __future__ import annotations

from conftest import BROWSER_MARKS

pytestmark = BROWSER_MARKS


def test_pages_load_under_the_csp(live_server_viewer, browser) -> None:
    violations: list[str] = []
    page = browser.new_page(viewport={"width": 800, "height": 500})
    try:
        page.on(
            "console",
            lambda m: violations.append(m.text) if "Content Security Policy" in m.text else None,
        )
        resp = page.goto(f"{live_server_viewer.url}/viz/?fixedDpr=1")
        assert resp is not None and "script-src" in resp.headers["content-security-policy"]
        page.wait_for_selector("canvas", timeout=60_000)
        page.wait_for_timeout(1500)
        resp = page.goto(f"{live_server_viewer.url}/")
        assert resp is not None and resp.headers["x-frame-options"] == "SAMEORIGIN"
        page.wait_for_load_state("load", timeout=30_000)
        page.wait_for_timeout(2000)  # module scripts, websockets, the framed 3D view
    finally:
        page.close()
    assert violations == []
