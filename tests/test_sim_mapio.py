"""map_server YAML + PGM/PNG reading and map_saver-compatible writing."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from bench.datasets import ROS_MAPS
from maps.mapio import (
    MapFormatError,
    encode_pgm,
    load_map_yaml,
    parse_map_yaml,
    read_map_bytes,
    save_map,
)
from nav.types import GridGeometry, OccupancyGrid, Pose2D

YAMLS = sorted(ROS_MAPS.glob("*/*.yaml"))
pytestmark = pytest.mark.skipif(not YAMLS, reason="ros_maps dataset not present")


def _pgm_pixels(data: bytes) -> tuple[int, int, np.ndarray]:
    from maps.mapio import _pgm_tokens

    (w, h, _), pos = _pgm_tokens(data, 3)
    return w, h, np.frombuffer(data[pos + 1 :], dtype=np.uint8).reshape(h, w)


@pytest.mark.parametrize("yaml_path", YAMLS, ids=lambda p: p.stem)
def test_loads_every_upstream_map_like_map_server(yaml_path: Path) -> None:
    grid = load_map_yaml(yaml_path)
    meta = parse_map_yaml(yaml_path.read_text())
    w, h, pix = _pgm_pixels((yaml_path.parent / str(meta["image"])).read_bytes())
    assert (grid.geometry.width, grid.geometry.height) == (w, h)
    assert grid.geometry.resolution == pytest.approx(float(meta["resolution"]))
    assert grid.geometry.origin.x == pytest.approx(float(meta["origin"][0]))
    # map_server's trinary rule on the flipped image
    occ = 1.0 - pix[::-1].astype(float) / 255.0
    want = np.where(
        occ > float(meta["occupied_thresh"]), 100, np.where(occ < float(meta["free_thresh"]), 0, -1)
    )
    np.testing.assert_array_equal(grid.data, want)
    assert set(np.unique(grid.data)) <= {-1, 0, 100}


@pytest.mark.parametrize("yaml_path", YAMLS, ids=lambda p: p.stem)
def test_round_trip_is_byte_stable(yaml_path: Path, tmp_path: Path) -> None:
    grid = load_map_yaml(yaml_path)
    first = save_map(grid, tmp_path / "a", "map")
    again = load_map_yaml(first)
    np.testing.assert_array_equal(again.data, grid.data)  # unknown stays unknown (free_thresh 0.196)
    assert again.geometry == grid.geometry
    second = save_map(again, tmp_path / "b", "map")
    assert (tmp_path / "a/map.pgm").read_bytes() == (tmp_path / "b/map.pgm").read_bytes()
    assert first.read_bytes() == second.read_bytes()


def test_map_saver_output_reproduced_byte_for_byte(tmp_path: Path) -> None:
    """turtlebot3's map.pgm was written by map_saver: loading and saving gives the same bytes."""
    src = ROS_MAPS / "turtlebot3_navigation2/map.yaml"
    save_map(load_map_yaml(src), tmp_path, "map")
    assert (tmp_path / "map.pgm").read_bytes() == src.with_suffix(".pgm").read_bytes()
    text = (tmp_path / "map.yaml").read_text()
    assert text == (
        "image: map.pgm\nmode: trinary\nresolution: 0.05\norigin: [-10, -10, 0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )


def test_save_header_values_and_flip(tmp_path: Path) -> None:
    data = np.array([[0, 100, -1], [30, 70, 0]], dtype=np.int8)  # row 0 at the origin (bottom)
    grid = OccupancyGrid(GridGeometry(0.1, 3, 2, Pose2D(1.5, -2.25, 0.0)), data)
    blob = encode_pgm(grid)
    assert blob.startswith(b"P5\n# CREATOR: map_saver.cpp 0.100 m/pix\n3 2\n255\n")
    pix = np.frombuffer(blob[-6:], dtype=np.uint8).reshape(2, 3)
    # image row 0 is the top of the map: the grid's last row
    np.testing.assert_array_equal(pix[0], [205, 0, 254])  # 30 -> unknown (between thresholds), 70 -> occupied
    np.testing.assert_array_equal(pix[1], [254, 0, 205])
    path = save_map(grid, tmp_path, "m", extra={"navdeck_start": [1.0, 2.5, 0.0]})
    assert "origin: [1.5, -2.25, 0]" in path.read_text()
    back = load_map_yaml(path)
    np.testing.assert_array_equal(back.data, [[0, 100, -1], [-1, 100, 0]])


def test_negate_scale_raw_modes() -> None:
    pgm = b"P5\n2 2\n255\n" + bytes([0, 255, 128, 200])
    base = "image: x.pgm\nresolution: 0.5\norigin: [0, 0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.25\n"
    tri = read_map_bytes((base + "negate: 0\n").encode(), pgm).data
    np.testing.assert_array_equal(tri, [[-1, 0], [100, 0]])  # flipped: image row 1 is grid row 0
    neg = read_map_bytes((base + "negate: 1\n").encode(), pgm).data
    np.testing.assert_array_equal(neg, [[-1, 100], [0, 100]])
    scale = read_map_bytes((base + "mode: scale\n").encode(), pgm).data
    occ128 = 1 - 128 / 255
    assert scale[0, 0] == round((occ128 - 0.25) / 0.4 * 100)
    raw = read_map_bytes((base + "mode: raw\n").encode(), b"P5\n2 1\n255\n" + bytes([42, 180])).data
    np.testing.assert_array_equal(raw, [[42, -1]])


def test_ascii_pgm_png_and_yaml_syntax() -> None:
    yaml = b"""# a comment
image: "map file.png"   # quoted, trailing comment
resolution: 0.05
origin:
  - -1.0
  - 2
  - 0.0
negate: 0
occupied_thresh: 0.65
free_thresh: 0.196
"""
    import imageio.v3 as iio

    img = np.array([[0, 254], [205, 254]], dtype=np.uint8)
    buf = io.BytesIO()
    iio.imwrite(buf, img, extension=".png")
    grid = read_map_bytes(yaml, buf.getvalue(), "map file.png")
    np.testing.assert_array_equal(grid.data, [[-1, 0], [100, 0]])
    assert grid.geometry.origin == Pose2D(-1.0, 2.0, 0.0)
    p2 = b"P2\n# c\n2 2\n255\n0 254\n205 254\n"
    np.testing.assert_array_equal(read_map_bytes(yaml, p2).data, grid.data)


@pytest.mark.parametrize(
    ("yaml", "image", "message"),
    [
        ("resolution: 0.05\norigin: [0,0,0]\n", b"P5\n1 1\n255\n\x00", "image"),
        ("image: a.pgm\norigin: [0,0,0]\n", b"P5\n1 1\n255\n\x00", "resolution"),
        ("image: a.pgm\nresolution: 0.05\n", b"P5\n1 1\n255\n\x00", "origin"),
        ("image: a.pgm\nresolution: 0.05\norigin: [0, 0]\n", b"P5\n1 1\n255\n\x00", "origin"),
        ("image: a.pgm\nresolution: 0.05\norigin: [0, nan, 0]\n", b"P5\n1 1\n255\n\x00", "origin"),
        ("image: a.pgm\nresolution: -1\norigin: [0,0,0]\n", b"P5\n1 1\n255\n\x00", "positive"),
        ("image: a.pgm\nresolution: 0.05\norigin: [0,0,0]\nmode: fancy\n", b"P5\n1 1\n255\n\x00", "mode"),
        ("image: a.pgm\nresolution: 0.05\norigin: [0,0,0]\n", b"P5\n4 4\n255\n\x00\x00", "truncated"),
        ("image: a.pgm\nresolution: 0.05\norigin: [0,0,0]\n", b"P5\n4", "truncated"),
        ("image: a.pgm\nresolution: 0.05\norigin: [0,0,0]\n", b"GIF89a", "neither"),
        ("image: a.pgm\nresolution: 0.05\norigin: [0,0,0]\n", b"\x89PNG\r\n\x1a\n" + b"\x00" * 30, "PNG"),
        (
            "image: a.pgm\nresolution: 0.05\norigin: [0,0,0]\nfree_thresh: 0.9\n",
            b"P5\n1 1\n255\n\x00",
            "thresh",
        ),
        ("image: a.pgm\n: broken\n", b"P5\n1 1\n255\n\x00", "line 2"),
    ],
)
def test_errors_are_typed_and_clear(yaml: str, image: bytes, message: str) -> None:
    with pytest.raises(MapFormatError, match=message):
        read_map_bytes(yaml.encode(), image, "a.pgm")


def test_oversize_image_rejected_before_decoding() -> None:
    yaml = b"image: a.pgm\nresolution: 0.05\norigin: [0,0,0]\n"
    with pytest.raises(MapFormatError, match="limit"):
        read_map_bytes(yaml, b"P5\n100000 100000\n255\n", max_pixels=10_000_000)


def test_missing_files(tmp_path: Path) -> None:
    with pytest.raises(MapFormatError, match="cannot read"):
        load_map_yaml(tmp_path / "nope.yaml")
    (tmp_path / "m.yaml").write_text("image: gone.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(MapFormatError, match=r"gone\.pgm"):
        load_map_yaml(tmp_path / "m.yaml")


def test_sixteen_bit_pgm_and_scale_mode_alpha_png() -> None:
    yaml = b"image: a\nresolution: 0.1\norigin: [0, 0, 0]\nmode: scale\n"
    pgm16 = b"P5\n2 1\n65535\n" + (0).to_bytes(2, "big") + (65535).to_bytes(2, "big")
    np.testing.assert_array_equal(read_map_bytes(yaml, pgm16).data, [[100, 0]])
    import imageio.v3 as iio

    rgba = np.array([[[0, 0, 0, 255], [255, 255, 255, 0]]], dtype=np.uint8)  # opaque black, transparent
    buf = io.BytesIO()
    iio.imwrite(buf, rgba, extension=".png")
    np.testing.assert_array_equal(read_map_bytes(yaml, buf.getvalue()).data, [[100, -1]])
