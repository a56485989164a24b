"""A map without cells is refused wherever one could come in (an image of size 0, a store call),
so navigation never gets a 0 x 0 costmap."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

from app.map_store import map_record
from maps.mapio import MapFormatError, decode_png
from nav.types import GridGeometry, OccupancyGrid


def _png_header(width: int, height: int) -> bytes:
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    chunk = b"IHDR" + ihdr
    return b"\x89PNG\r\n\x1a\n" + struct.pack(">I", len(ihdr)) + chunk + struct.pack(">I", zlib.crc32(chunk))


@pytest.mark.parametrize("size", [(0, 10), (10, 0), (0, 0)])
def test_a_png_of_size_zero_is_a_format_error(size: tuple[int, int]) -> None:
    with pytest.raises(MapFormatError, match="invalid size"):
        decode_png(_png_header(*size))


def test_the_store_refuses_a_grid_without_cells() -> None:
    empty = OccupancyGrid(GridGeometry(0.05, 0, 0), np.zeros((0, 0), dtype=np.int8))
    with pytest.raises(ValueError, match="needs cells"):
        map_record("empty", empty)
