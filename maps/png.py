"""A minimal PNG encoder (zlib only) for thumbnails and map previews: no imaging dependency."""

from __future__ import annotations

import struct
import zlib

import numpy as np


def _chunk(tag: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)


def encode_png(image: np.ndarray, compress_level: int = 6) -> bytes:
    """Encode a uint8 image: (H, W) grey, (H, W, 3) RGB or (H, W, 4) RGBA. Row 0 is the top row."""
    img = np.ascontiguousarray(image, dtype=np.uint8)
    if img.ndim == 2:
        color_type, channels = 0, 1
    elif img.ndim == 3 and img.shape[2] in (3, 4):
        color_type, channels = (2 if img.shape[2] == 3 else 6), img.shape[2]
    else:
        raise ValueError(f"cannot encode an image of shape {img.shape}")
    h, w = img.shape[:2]
    rows = img.reshape(h, w * channels)
    raw = np.hstack((np.zeros((h, 1), dtype=np.uint8), rows)).tobytes()  # filter type 0 per row
    header = struct.pack(">IIBBBBB", w, h, 8, color_type, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + _chunk(b"IHDR", header)
        + _chunk(b"IDAT", zlib.compress(raw, compress_level))
        + (_chunk(b"IEND", b""))
    )
