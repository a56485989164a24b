"""The 3D view's Zones layer: keepout and speed outlines from the zones stage's snapshot field,
labelled, redrawn only when the zones change, with its own checkbox (issue 19)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from test_viewer_scene import FOOTPRINT, snap

from app.bus import SnapshotBus
from app.viewer import palette
from app.viewer.scene import Viewer


@pytest.fixture
def viewer() -> Iterator[Viewer]:
    v = Viewer(SnapshotBus(), footprint=FOOTPRINT)
    v.start()
    try:
        yield v
    finally:
        v.stop()


def test_zones_layer_draws_each_kind_in_its_colour(viewer: Viewer) -> None:
    s = viewer.server.scene
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    tri = np.array([[2.0, 0.0], [3.0, 0.0], [2.5, 1.0]])
    layer = (("keepout", "lab (keepout)", square), ("speed", "aisle (30 %)", tri))
    viewer.apply(snap(extras={"zone_layer": layer}))
    assert viewer.is_shown("/zones")
    keep = s.get_handle_by_name("/zones/keepout")
    speed = s.get_handle_by_name("/zones/speed")
    assert keep.points.shape == (4, 2, 3) and speed.points.shape == (3, 2, 3)  # closed outlines
    np.testing.assert_allclose(keep.points[:, 0, :2], square, atol=1e-6)
    assert (np.asarray(keep.colors).reshape(-1, 3) == palette.KEEPOUT_ZONE).all()
    assert (np.asarray(speed.colors).reshape(-1, 3) == palette.SPEED_ZONE).all()
    label = s.get_handle_by_name("/zones/label_1")
    assert label.text == "aisle (30 %)" and label.visible
    np.testing.assert_allclose(label.position[:2], tri.mean(axis=0))

    viewer.set_layer_enabled("Zones", False)
    assert not viewer.is_shown("/zones")
    viewer.set_layer_enabled("Zones", True)

    viewer.apply(snap(extras={"zone_layer": layer[:1]}))  # one zone deleted
    assert speed.points.shape == (0, 2, 3) and s.get_handle_by_name("/zones/label_1").visible is False
    viewer.apply(snap(extras={"zone_layer": ()}))
    assert not viewer.is_shown("/zones")
