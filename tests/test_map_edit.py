"""Map editing (issue 19): brush, line wall and polygon edits on a grid, the costmaps updating only
the edited region, and edits saved as new map versions through the API (zones carried over; the new
version activated only on request, then picked up by the costmaps without a restart)."""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np
import pytest
from conftest import make_settings
from fastapi.testclient import TestClient

from app.main import create_app
from app.runtime import Runtime
from nav.costmap import Costmap2D
from nav.costmap.filter_layer import rasterize_polygons
from nav.map_edit import Fill, Stroke, apply_edits
from nav.types import LETHAL_OBSTACLE, GridGeometry, OccupancyGrid, Pose2D

GEO = GridGeometry(0.05, 200, 160, Pose2D(0.0, 0.0, 0.0))


def free_grid() -> OccupancyGrid:
    return OccupancyGrid(GEO, np.zeros((GEO.height, GEO.width), np.int8))


def test_brush_line_and_polygon_set_the_cells_they_cover() -> None:
    grid = free_grid()
    brush = Stroke(np.array([[2.0, 2.0]]), 0.5, "unknown")
    wall = Stroke(np.array([[5.0, 1.0], [5.0, 7.0]]), 0.05, "occupied")
    square = np.array([[7.0, 1.0], [9.0, 1.0], [9.0, 3.0], [7.0, 3.0]])
    edited, bounds, n = apply_edits(grid, [brush, wall, Fill(square, "occupied")])
    disc = edited.data == -1
    assert abs(disc.sum() - np.pi * 0.5**2 / 0.05**2) < 0.05 * disc.sum()  # a disc of r = 0.5 m
    assert (edited.data[20:140, 100] == 100).all() or (edited.data[20:140, 99] == 100).all()  # x = 5 m
    assert (edited.data[rasterize_polygons([square], GEO)] == 100).all()
    assert n == int((edited.data != grid.data).sum()) and bounds is not None
    assert (grid.data == 0).all()  # the original is untouched
    _, none, zero = apply_edits(edited, [Fill(square, "occupied")])
    assert none is None and zero == 0


def test_costmap_update_only_in_the_edited_region_equals_a_rebuild() -> None:
    rng = np.random.default_rng(3)
    grid = free_grid()
    grid.data[rng.random(grid.data.shape) < 0.01] = 100
    cm = Costmap2D.from_map(grid)
    before = cm.costmap()
    edited, bounds, _ = apply_edits(grid, [Stroke(np.array([[2.0, 4.0], [8.0, 4.0]]), 0.05, "occupied")])
    cm.update_static(edited, bounds)
    assert np.array_equal(cm.costmap().costs, Costmap2D.from_map(edited).costmap().costs)
    assert cm.cost_at(np.array([[5.0, 4.0]]))[0] == LETHAL_OBSTACLE
    assert before.cost_at(np.array([[5.0, 4.0]]))[0] != LETHAL_OBSTACLE  # snapshots keep the old map


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator:
    runtime = Runtime.build(make_settings(tmp_path_factory.mktemp("mapedit")))
    with TestClient(create_app(runtime)) as c:
        yield c


def test_an_edit_is_a_new_version_activated_on_request(client) -> None:
    map_id = client.get("/api/localization").json()["map_id"]
    zone = {"name": "lab", "kind": "keepout", "polygon": [[2.0, 1.0], [2.5, 1.0], [2.5, 1.5], [2.0, 1.5]]}
    assert client.post(f"/api/maps/{map_id}/zones", json=zone).status_code == 201
    wall = {"op": "line", "start": [1.0, 2.0], "end": [5.0, 2.0], "width": 0.1}
    erase = {"op": "polygon", "polygon": [[6.0, 1.0], [7.0, 1.0], [7.0, 2.0]], "value": "unknown"}
    r = client.post(f"/api/maps/{map_id}/versions", json={"operations": [wall, erase]})
    assert r.status_code == 201, r.text
    v2 = r.json()
    assert v2["version"] == 2 and v2["parent_id"] == map_id and v2["changed_cells"] > 80
    assert v2["name"] == "apartment v2" and v2["active"] is False
    assert r.headers["location"] == f"/api/maps/{v2['id']}"
    chain = client.get(f"/api/maps/{v2['id']}/versions").json()["items"]
    assert [m["id"] for m in chain] == [map_id, v2["id"]]
    assert (
        client.get(f"/api/maps/{map_id}/map.pgm").content
        != client.get(f"/api/maps/{v2['id']}/map.pgm").content
    )
    assert [z["name"] for z in client.get(f"/api/maps/{v2['id']}/zones").json()["items"]] == ["lab"]

    rt = client.app.state.runtime
    assert rt.features["localization"].map_id == map_id  # saving did not activate it
    assert client.post(f"/api/maps/{v2['id']}/activate").status_code == 200
    nav = rt.features["navigation"]
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline:
        cm = nav.global_costmap
        if cm is not None and cm.cost_at(np.array([[3.0, 2.0]]))[0] == LETHAL_OBSTACLE:
            break
        time.sleep(0.05)
    assert nav.global_costmap.cost_at(np.array([[3.0, 2.0]]))[0] == LETHAL_OBSTACLE  # the new wall
    assert nav.in_keepout(2.25, 1.25)  # the zone came with the version

    bad = {"op": "polygon", "polygon": [[1.0, 1.0], [2.0, 2.0], [2.0, 1.0], [1.0, 2.0]], "value": "free"}
    r = client.post(f"/api/maps/{map_id}/versions", json={"operations": [bad]})
    assert r.status_code == 422 and r.json()["type"].endswith("/invalid-polygon")
    assert client.post("/api/maps/99999/versions", json={"operations": [wall]}).status_code == 404
    assert client.post(f"/api/maps/{map_id}/activate").status_code == 200  # restore the original
