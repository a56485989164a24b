"""Stock worlds: present, loadable, reproducible from generate.py, with free start poses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from maps.mapio import load_map_yaml
from maps.stock import STOCK_DIR, UnknownWorldError, available_worlds, stock_world_path
from maps.stock.generate import generate
from robot.profiles import load_profile
from robot.sim import World
from robot.sim.physics import SimOptions, footprint_samples

SIZES = {"apartment": (10.0, 8.0), "office": (30.0, 20.0), "greenhouse": (20.0, 12.0)}


def test_available_and_unknown() -> None:
    assert available_worlds() == sorted(SIZES)
    with pytest.raises(UnknownWorldError, match="choose one of apartment"):
        stock_world_path("mars")
    with pytest.raises(KeyError):
        stock_world_path("../office")


def test_committed_files_match_the_generator(tmp_path: Path) -> None:
    generate(tmp_path)
    for name in SIZES:
        for ext in ("pgm", "yaml"):
            assert (tmp_path / f"{name}.{ext}").read_bytes() == (STOCK_DIR / f"{name}.{ext}").read_bytes()


@pytest.mark.parametrize("name", sorted(SIZES))
def test_world_size_resolution_and_free_start(name: str) -> None:
    grid = load_map_yaml(stock_world_path(name))
    assert grid.resolution == 0.05
    assert grid.geometry.size_m == pytest.approx(SIZES[name])
    world = World.stock(name)
    assert "navdeck_start:" in stock_world_path(name).read_text()
    assert world.start_pose.x > 0 and world.start_pose.y > 0
    for profile_name in ("skid4", "omni4"):
        profile = load_profile(profile_name)
        pts = footprint_samples(profile.footprint_polygon(32), SimOptions().footprint_spacing)
        assert not world.any_occupied(world.start_pose.transform_points(pts))
    # closed: the border is walled all round
    occ = world.occupied
    assert occ[0].all() and occ[-1].all() and occ[:, 0].all() and occ[:, -1].all()


def test_apartment_has_chair_legs_and_office_doors() -> None:
    from scipy import ndimage

    occ = World.stock("apartment").occupied
    labels, _ = ndimage.label(occ)
    sizes = np.bincount(labels.ravel())[1:]
    assert (sizes == 1).sum() >= 8  # 4 x 4 cm legs are single 5 cm cells
    office = World.stock("office").occupied
    # doorways in the corridor's lower wall (row of y = 9.0 m): gaps of 0.8-0.9 m
    row = office[round(9.0 / 0.05)]
    gaps = np.diff(
        np.flatnonzero(np.diff(np.concatenate(([1], row.astype(int), [1]))) != 0).reshape(-1, 2), axis=1
    )
    widths = gaps.ravel() * 0.05
    assert len(widths) == 6 and np.all((widths >= 0.8 - 1e-9) & (widths <= 0.95))


def test_greenhouse_rows_are_parallel_corridors() -> None:
    occ = World.stock("greenhouse").occupied
    column = occ[:, round(10.0 / 0.05)]  # a vertical cut through the rows at x = 10 m
    runs = np.flatnonzero(np.diff(column.astype(int)) != 0)
    assert len(runs) >= 10  # several rows crossed
