"""Zones <-> Nav2 costmap filter masks (issue 19): export -> import -> export is bit-exact for keepout
and both speed types on seeded random polygons; masks written the way map_server's format and the
Nav2 tutorials say (trinary, scale, raw) import; regions with holes are split; bad input is a 422."""

from __future__ import annotations

import io
import re
import zipfile
from collections.abc import Iterator
from datetime import UTC, datetime

import numpy as np
import pytest
from conftest import make_settings
from fastapi.testclient import TestClient

from app.main import create_app
from app.runtime import Runtime
from app.zone_masks import (
    DEFAULT_INFO,
    FilterInfo,
    FilterType,
    MaskError,
    export_zip,
    mask_values,
    parse_filter_info,
    read_mask,
    region_polygons,
    zones_from_mask,
)
from app.zone_store import SpeedUnit, Zone, ZoneKind, ZoneSpec
from nav.costmap.filter_layer import rasterize_polygons, validate_polygon
from nav.types import GridGeometry, Pose2D

GEOM = GridGeometry(0.05, 160, 120, Pose2D(-2.0, -1.5, 0.0))
NOW = datetime(2026, 1, 1, tzinfo=UTC)


def star(rng: np.random.Generator, geometry: GridGeometry) -> list[list[float]]:
    """A random simple (star-shaped) polygon inside the map."""
    w, h = geometry.size_m
    o = geometry.origin
    r_max = rng.uniform(0.3, 1.5)
    cx = o.x + rng.uniform(r_max, w - r_max)
    cy = o.y + rng.uniform(r_max, h - r_max)
    n = int(rng.integers(3, 12))
    ang = np.sort(rng.uniform(0, 2 * np.pi, n))
    rad = rng.uniform(0.3, 1.0, n) * r_max
    return np.column_stack((cx + rad * np.cos(ang), cy + rad * np.sin(ang))).tolist()


def as_zones(specs: list[ZoneSpec]) -> list[Zone]:
    return [
        Zone(i, 1, s.name, s.kind, tuple(map(tuple, s.polygon)), s.speed_limit, s.speed_limit_unit, NOW, NOW)
        for i, s in enumerate(specs, 1)
    ]


def random_zones(seed: int, ftype: FilterType) -> list[Zone]:
    rng = np.random.default_rng(seed)
    specs = []
    for i in range(6):
        poly = star(rng, GEOM)
        try:
            validate_polygon(poly, GEOM)
        except ValueError:
            continue  # three nearly collinear angles: not a zone
        if ftype == FilterType.KEEPOUT:
            specs.append(ZoneSpec(f"k{i}", ZoneKind.KEEPOUT, poly))
        elif ftype == FilterType.SPEED_PERCENT:
            specs.append(ZoneSpec(f"s{i}", ZoneKind.SPEED, poly, float(rng.integers(5, 100))))
        else:
            specs.append(
                ZoneSpec(
                    f"a{i}", ZoneKind.SPEED, poly, round(float(rng.uniform(0.02, 0.5)), 3), SpeedUnit.MPS
                )
            )
    return as_zones(specs)


def unzip(data: bytes) -> dict[str, bytes]:
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        return {n: z.read(n) for n in z.namelist()}


def reimport(zipped: bytes, info: FilterInfo) -> list[Zone]:
    files = unzip(zipped)
    stem = "keepout" if info.type == FilterType.KEEPOUT else "speed"
    values = read_mask(files[f"{stem}_mask.yaml"], files[f"{stem}_mask.pgm"], "m.pgm", GEOM)
    got = parse_filter_info(files[f"{stem}_filter_info.yaml"].decode())
    assert got == info
    return as_zones(zones_from_mask(values, GEOM, got, "imported"))


@pytest.mark.parametrize("mode", ["scale", "raw"])
@pytest.mark.parametrize("ftype", list(FilterType))
@pytest.mark.parametrize("seed", range(4))
def test_round_trip_is_bit_exact(seed: int, ftype: FilterType, mode: str) -> None:
    info = DEFAULT_INFO[ftype]
    zones = random_zones(seed, ftype)
    first = export_zip(zones, GEOM, info, mode)
    values = mask_values(zones, GEOM, info)
    assert (values > 0).sum() > 100  # the zones are in the mask
    imported = reimport(first, info)
    assert imported and all(validate_polygon(z.polygon, GEOM) is not None for z in imported)
    assert export_zip(imported, GEOM, info, mode) == first
    # and the imported zones are the same cells the navigator keeps out of / slows down in
    assert np.array_equal(mask_values(imported, GEOM, info), values)


def test_speed_limits_survive_with_their_values() -> None:
    info = DEFAULT_INFO[FilterType.SPEED_ABSOLUTE]
    square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
    zones = as_zones([ZoneSpec("aisle", ZoneKind.SPEED, square, 0.07, SpeedUnit.MPS)])
    (z,) = reimport(export_zip(zones, GEOM, info), info)
    assert z.speed_limit == 0.07 and z.speed_limit_unit == SpeedUnit.MPS
    info = DEFAULT_INFO[FilterType.SPEED_PERCENT]
    zones = as_zones([ZoneSpec("aisle", ZoneKind.SPEED, square, 30.0)])
    (z,) = reimport(export_zip(zones, GEOM, info), info)
    assert z.speed_limit == 30.0 and z.speed_limit_unit == SpeedUnit.PERCENT
    # a square along cell boundaries comes back as the same 4 corners
    assert sorted(map(tuple, np.round(z.vertices(), 9).tolist())) == sorted(map(tuple, square))


def test_overlapping_speed_zones_keep_the_lowest_limit() -> None:
    info = DEFAULT_INFO[FilterType.SPEED_PERCENT]
    a = [[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]]
    b = [[1.0, 0.0], [3.0, 0.0], [3.0, 1.0], [1.0, 1.0]]
    values = mask_values(
        as_zones([ZoneSpec("a", ZoneKind.SPEED, a, 20.0), ZoneSpec("b", ZoneKind.SPEED, b, 60.0)]), GEOM, info
    )
    row, col = 40, 70  # the cell whose centre is (1.525, 0.525)
    assert values[row, col] == 80  # 100 - 20: the 20 % zone wins where both are


def test_hole_and_pinch_regions_are_split_exactly() -> None:
    ring = np.ones((7, 9), dtype=bool)
    ring[2:5, 3:6] = False
    pinch = np.zeros((6, 6), dtype=bool)
    pinch[0:3, 0:3] = True
    pinch[3:6, 3:6] = True  # touches the first block at one corner only
    pinch[0:6, 5] = True  # ... and both are joined on the right: one 4-connected region
    # the ring is cut once through its hole (two U shapes), the pinch along the touching corners' row
    for region, pieces in ((ring, 2), (pinch, 3)):
        polys = region_polygons(region)
        assert len(polys) == pieces
        geom = GridGeometry(1.0, region.shape[1], region.shape[0], Pose2D(0.0, 0.0, 0.0))
        for p in polys:
            validate_polygon(p, geom)
        assert np.array_equal(rasterize_polygons(polys, geom), region)
    l_shape = np.zeros((5, 5), dtype=bool)
    l_shape[0:5, 0:2] = True
    l_shape[0:2, 0:5] = True
    (outline,) = region_polygons(l_shape)
    assert len(outline) == 6  # an L is one rectilinear polygon of 6 corners


# ------------------------------------------------------------------------------ Nav2-shaped masks

TUTORIAL_INFO = """costmap_filter_info_server:
  ros__parameters:
    use_sim_time: true
    type: {type}
    filter_info_topic: "/costmap_filter_info"
    mask_topic: "/filter_mask"
    base: {base}
    multiplier: {multiplier}
"""


def mask_yaml(mode: str, occ: float = 0.65, free: float = 0.196) -> bytes:
    return (
        f"image: mask.pgm\nmode: {mode}\nresolution: 0.050000\norigin: [-2.0, -1.5, 0.0]\n"
        f"negate: 0\noccupied_thresh: {occ}\nfree_thresh: {free}\n"
    ).encode()


def pgm(pixels_top_row_first: np.ndarray) -> bytes:
    h, w = pixels_top_row_first.shape
    return f"P5\n{w} {h}\n255\n".encode() + pixels_top_row_first.astype(np.uint8).tobytes()


def test_nav2_trinary_keepout_mask_imports() -> None:
    img = np.full((GEOM.height, GEOM.width), 254, dtype=np.uint8)  # free
    img[:10, :] = 205  # unknown: not a zone
    img[20:40, 30:70] = 0  # black: occupied = keepout (image row 20 from the top)
    img[60:70, 100:110] = 0
    info = parse_filter_info(TUTORIAL_INFO.format(type=0, base=0.0, multiplier=1.0))
    values = read_mask(mask_yaml("trinary"), pgm(img), "mask.pgm", GEOM)
    specs = zones_from_mask(values, GEOM, info, "keepout")
    assert len(specs) == 2 and all(s.kind == ZoneKind.KEEPOUT for s in specs)
    cells = rasterize_polygons([np.asarray(s.polygon) for s in specs], GEOM)
    assert np.array_equal(cells, np.flipud(img == 0))


def test_nav2_scale_speed_mask_imports() -> None:
    # scale mode with the tutorial's thresholds: occ = 1 - p / 255 between free and occupied is
    # scaled to 0..100; darker = larger value = (base 100, multiplier -1) a lower percentage
    img = np.full((GEOM.height, GEOM.width), 254, dtype=np.uint8)
    img[10:30, 10:50] = 100  # occ 0.608: rint((0.608 - 0.196) / 0.454 * 100) = 91 -> 9 %
    img[50:80, 60:90] = 150  # occ 0.412 -> 48 -> 52 %
    info = parse_filter_info(TUTORIAL_INFO.format(type=1, base=100.0, multiplier=-1.0))
    values = read_mask(mask_yaml("scale"), pgm(img), "mask.pgm", GEOM)
    specs = zones_from_mask(values, GEOM, info, "speed")
    limits = sorted(s.speed_limit for s in specs)
    expected = [100 - round((1 - p / 255 - 0.196) / (0.65 - 0.196) * 100) for p in (150, 100)]
    assert limits == sorted(expected) == [9.0, 52.0]
    assert all(s.speed_limit_unit == SpeedUnit.PERCENT for s in specs)


def test_nav2_raw_speed_mask_in_mps_imports() -> None:
    img = np.zeros((GEOM.height, GEOM.width), dtype=np.uint8)  # raw 0: no limit
    img[5:25, 5:25] = 20  # base 0.0 + 0.01 * 20 = 0.2 m/s
    img[40:45, 40:80] = 5
    info = parse_filter_info(TUTORIAL_INFO.format(type=2, base=0.0, multiplier=0.01))
    values = read_mask(mask_yaml("raw"), pgm(img), "mask.pgm", GEOM)
    specs = zones_from_mask(values, GEOM, info, "slow")
    assert sorted(s.speed_limit for s in specs) == [0.05, 0.2]
    assert all(s.speed_limit_unit == SpeedUnit.MPS for s in specs)


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("base: 0\nmultiplier: 1\n", "has no 'type'"),
        ("type: 7\n", "must be 0 (keepout)"),
        ("type: 1\nbase: 100\nmultiplier: 0\n", "must not be 0"),
        ("type: 1\nbase: abc\n", "'base' must be a number"),
    ],
)
def test_bad_filter_info_says_what_is_wrong(text: str, reason: str) -> None:
    with pytest.raises(MaskError, match=re.escape(reason)):
        parse_filter_info(text)


def test_mask_of_another_size_or_out_of_range_limits_are_refused() -> None:
    small = np.zeros((10, 10), dtype=np.uint8)
    with pytest.raises(MaskError, match="does not cover the map"):
        read_mask(mask_yaml("raw"), pgm(small), "m.pgm", GEOM)
    values = np.zeros((GEOM.height, GEOM.width), dtype=np.int8)
    values[3:6, 3:6] = 50
    with pytest.raises(MaskError, match="a limit must be > 0"):  # 0 - 1 * 50 < 0
        zones_from_mask(values, GEOM, FilterInfo(FilterType.SPEED_PERCENT, 0.0, -1.0), "x")
    square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
    zones = as_zones([ZoneSpec("fast", ZoneKind.SPEED, square, 3.0, SpeedUnit.MPS)])
    with pytest.raises(MaskError, match="cannot be encoded"):  # 3 m/s > 100 x 0.01
        export_zip(zones, GEOM, DEFAULT_INFO[FilterType.SPEED_ABSOLUTE])
    with pytest.raises(MaskError, match="cannot be encoded"):  # (3 - 0) / 1e-320 overflows
        export_zip(zones, GEOM, FilterInfo(FilterType.SPEED_ABSOLUTE, 0.0, 1e-320))
    with pytest.raises(MaskError, match="a limit must be > 0"):  # 1e308 + 1e308 * 50 is not a limit
        zones_from_mask(values, GEOM, FilterInfo(FilterType.SPEED_ABSOLUTE, 1e308, 1e308), "x")


# ------------------------------------------------------------------------------------------- API


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator:
    runtime = Runtime.build(make_settings(tmp_path_factory.mktemp("zonemasks")))
    with TestClient(create_app(runtime)) as c:
        yield c


def test_api_export_import_export_is_bit_exact(client) -> None:
    map_id = client.get("/api/localization").json()["map_id"]
    m = client.get(f"/api/maps/{map_id}").json()
    geom = GridGeometry(m["resolution"], m["width"], m["height"], Pose2D(*m["origin"]))
    rng = np.random.default_rng(7)
    url = f"/api/maps/{map_id}/zones"
    for i in range(3):
        r = client.post(url, json={"name": f"k{i}", "kind": "keepout", "polygon": star(rng, geom)})
        assert r.status_code == 201, r.text
        speed = {"name": f"s{i}", "kind": "speed", "polygon": star(rng, geom), "speed_limit": 10 + 20 * i}
        assert client.post(url, json=speed).status_code == 201
    for kind in ("keepout", "speed"):
        first = client.get(f"{url}/export", params={"kind": kind})
        assert first.status_code == 200 and first.headers["content-type"] == "application/zip"
        files = unzip(first.content)
        stem = kind
        r = client.post(
            f"{url}/import",
            files={
                "yaml": ("m.yaml", files[f"{stem}_mask.yaml"]),
                "image": ("m.pgm", files[f"{stem}_mask.pgm"]),
                "filter_info": ("f.yaml", files[f"{stem}_filter_info.yaml"]),
            },
            data={"replace": "true"},
        )
        assert r.status_code == 201, r.text
        assert r.json()["replaced"] == 3 and r.json()["items"]
        again = client.get(f"{url}/export", params={"kind": kind})
        assert again.content == first.content


def test_api_bad_masks_are_422_problems(client) -> None:
    map_id = client.get("/api/localization").json()["map_id"]
    url = f"/api/maps/{map_id}/zones/import"
    before = client.get(f"/api/maps/{map_id}/zones").json()["total"]
    small = pgm(np.zeros((10, 10), dtype=np.uint8))
    r = client.post(
        url, files={"yaml": ("m.yaml", mask_yaml("raw")), "image": ("m.pgm", small)}, data={"kind": "keepout"}
    )
    assert r.status_code == 422 and "does not cover the map" in r.json()["detail"]
    assert r.json()["type"].endswith("/invalid-mask")
    r = client.post(url, files={"yaml": ("m.yaml", mask_yaml("raw")), "image": ("m.pgm", small)})
    assert r.status_code == 422 and "filter_info" in r.json()["detail"]
    r = client.post(
        url,
        files={"yaml": ("m.yaml", b"image: m.pgm\n"), "image": ("m.pgm", small)},
        data={"kind": "keepout"},
    )
    assert r.status_code == 422 and "resolution" in r.json()["detail"]
    assert client.get(f"/api/maps/{map_id}/zones").json()["total"] == before  # nothing stored
    assert client.get(f"/api/maps/{map_id}/zones/export", params={"kind": "nope"}).status_code == 422
    assert client.get("/api/maps/99999/zones/export", params={"kind": "keepout"}).status_code == 404


@pytest.mark.parametrize("seed", range(3))
def test_noisy_masks_with_holes_and_touching_corners_import_exactly(seed: int) -> None:
    """Seeded random masks full of holes, diagonal contacts and single cells: every cell comes back."""
    rng = np.random.default_rng(seed)
    keep = np.where(rng.random((GEOM.height, GEOM.width)) < 0.45, 100, 0).astype(np.int8)
    info = DEFAULT_INFO[FilterType.KEEPOUT]
    zones = as_zones(zones_from_mask(keep, GEOM, info, "k"))
    assert np.array_equal(mask_values(zones, GEOM, info), keep.astype(np.uint8))
    speed = rng.choice(np.array([0, 20, 50, 70], dtype=np.int8), size=(GEOM.height, GEOM.width))
    info = DEFAULT_INFO[FilterType.SPEED_PERCENT]
    zones = as_zones(zones_from_mask(speed, GEOM, info, "s"))
    assert np.array_equal(mask_values(zones, GEOM, info), speed.astype(np.uint8))
