"""Occupancy grids as pictures (map_saver's grey levels), for thumbnails and previews."""

from __future__ import annotations

import numpy as np

from maps.png import encode_png
from nav.types import OccupancyGrid


def grid_to_grey(grid: OccupancyGrid, occupied_thresh: int = 65, free_thresh: int = 25) -> np.ndarray:
    """map_saver's trinary colours, top row first: free 254, occupied 0, unknown 205."""
    d = grid.data
    img = np.full(d.shape, 205, dtype=np.uint8)
    img[(d >= 0) & (d <= free_thresh)] = 254
    img[d >= occupied_thresh] = 0
    return img[::-1]


def thumbnail_png(grid: OccupancyGrid, max_side: int = 256) -> bytes:
    """A small PNG: block-min downsampling keeps thin walls visible."""
    img = grid_to_grey(grid)
    h, w = img.shape
    k = max(1, int(np.ceil(max(h, w) / max_side)))
    if k > 1:
        ph, pw = (-h) % k, (-w) % k
        img = np.pad(img, ((0, ph), (0, pw)), constant_values=205)
        img = img.reshape(img.shape[0] // k, k, img.shape[1] // k, k).min(axis=(1, 3))
    return encode_png(img)
