"""Compact binary chunks for per-run bulk data: trajectory samples, laser scans, plans, grids.

Why binary chunks rather than one row per sample: at 10 Hz a one-hour run has 36,000 samples and
7,200 scans; one row per sample costs ~100 B of SQLite overhead each and a seek must scan an index of
that size. Packing about one second per row (numpy record arrays, zlib level 6) makes an hour a few
thousand rows, ~3-15 MB, and a seek one indexed probe plus one small decompression.

Scans keep ROS semantics (sensor_msgs/LaserScan, REP-117): ranges are quantised to millimetres in a
uint16 (0.001 m is below the RPLidar A1's own resolution); code 0 means "no return" (+inf) and 65535
"invalid" (NaN). Everything is little-endian so chunks read back identically on any host.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

from nav.types import LaserScan

ZLIB_LEVEL = 6

# One trajectory sample. Poses in map (x, y, theta) and odom (ox, oy, otheta) frames, measured body
# velocity (vx, vy, wz), the command sent (cmd_*), localization covariance diagonal (x, y, yaw; NaN when
# no estimate), clearance (m from the footprint to the nearest scan return; NaN when unknown), the mode
# code (index in MODES) and the behaviour code (index into the chunk's labels, 0 = none).
SAMPLE_DTYPE = np.dtype(
    [
        ("t", "<f8"),
        ("x", "<f4"),
        ("y", "<f4"),
        ("theta", "<f4"),
        ("ox", "<f4"),
        ("oy", "<f4"),
        ("otheta", "<f4"),
        ("vx", "<f4"),
        ("vy", "<f4"),
        ("wz", "<f4"),
        ("cmd_vx", "<f4"),
        ("cmd_vy", "<f4"),
        ("cmd_wz", "<f4"),
        ("cov_x", "<f4"),
        ("cov_y", "<f4"),
        ("cov_theta", "<f4"),
        ("clearance", "<f4"),
        ("mode", "u1"),
        ("behavior", "u1"),
    ]
)

# app.modes.Mode values in a fixed order (codes are stored: append only, never reorder).
MODES: tuple[str, ...] = (
    "idle",
    "teleop",
    "mapping",
    "localizing",
    "navigating",
    "recovering",
    "estop",
    "fault",
)
MODE_CODE = {m: i for i, m in enumerate(MODES)}

SCAN_HEADER_DTYPE = np.dtype(
    [
        ("t", "<f8"),
        ("angle_min", "<f4"),
        ("angle_increment", "<f4"),
        ("range_min", "<f4"),
        ("range_max", "<f4"),
        ("n", "<u4"),
    ]
)
RANGE_NO_RETURN = 0
RANGE_INVALID = 65535
RANGE_SCALE = 1000.0  # mm


class CodecError(ValueError):
    """A stored chunk that does not decode (corrupt or from an unknown format)."""


def pack_samples(samples: np.ndarray) -> bytes:
    """(N,) SAMPLE_DTYPE -> compressed bytes."""
    arr = np.ascontiguousarray(samples, dtype=SAMPLE_DTYPE)
    return zlib.compress(arr.tobytes(), ZLIB_LEVEL)


def unpack_samples(blob: bytes) -> np.ndarray:
    raw = zlib.decompress(blob)
    if len(raw) % SAMPLE_DTYPE.itemsize:
        raise CodecError("sample chunk size is not a whole number of samples")
    return np.frombuffer(raw, dtype=SAMPLE_DTYPE).copy()


def quantize_ranges(ranges: np.ndarray) -> np.ndarray:
    """Metres -> uint16 millimetres; +inf or beyond 65.534 m -> 0 (no return), NaN -> 65535."""
    r = np.asarray(ranges, dtype=np.float64)
    finite = np.isfinite(r) & (r > 0.0)
    mm = np.rint(np.where(finite, r, 0.0) * RANGE_SCALE)
    q = np.where(finite & (mm < RANGE_INVALID), np.clip(mm, 1, RANGE_INVALID - 1), RANGE_NO_RETURN)
    q = q.astype(np.uint16)
    q[np.isnan(r)] = RANGE_INVALID
    return q


def dequantize_ranges(q: np.ndarray) -> np.ndarray:
    r = q.astype(np.float32) / np.float32(RANGE_SCALE)
    r[q == RANGE_NO_RETURN] = np.inf
    r[q == RANGE_INVALID] = np.nan
    return r


def pack_scans(times: list[float], scans: list[LaserScan]) -> bytes:
    """Scans taken at run times ``times`` -> one compressed chunk."""
    if len(times) != len(scans):
        raise ValueError("times and scans differ in length")
    head = np.zeros(len(scans), dtype=SCAN_HEADER_DTYPE)
    parts = []
    for i, (t, s) in enumerate(zip(times, scans, strict=True)):
        head[i] = (t, s.angle_min, s.angle_increment, s.range_min, s.range_max, s.ranges.shape[0])
        parts.append(quantize_ranges(s.ranges))
    ranges = np.concatenate(parts) if parts else np.zeros(0, np.uint16)
    body = struct.pack("<I", len(scans)) + head.tobytes() + ranges.astype("<u2").tobytes()
    return zlib.compress(body, ZLIB_LEVEL)


def unpack_scans(blob: bytes) -> list[tuple[float, LaserScan]]:
    """A chunk -> [(run time, LaserScan)], ranges as float32 metres (+inf no return)."""
    raw = zlib.decompress(blob)
    (n,) = struct.unpack_from("<I", raw)
    off = 4 + n * SCAN_HEADER_DTYPE.itemsize
    head = np.frombuffer(raw[4:off], dtype=SCAN_HEADER_DTYPE)
    ranges = np.frombuffer(raw[off:], dtype="<u2")
    if int(head["n"].sum()) != ranges.shape[0]:
        raise CodecError("scan chunk ranges do not match its headers")
    out = []
    ends = np.cumsum(head["n"].astype(np.int64))
    starts = ends - head["n"]
    for h, a, b in zip(head, starts, ends, strict=True):
        scan = LaserScan(
            stamp=float(h["t"]),
            angle_min=float(h["angle_min"]),
            angle_increment=float(h["angle_increment"]),
            ranges=dequantize_ranges(ranges[a:b]),
            range_min=float(h["range_min"]),
            range_max=float(h["range_max"]),
        )
        out.append((float(h["t"]), scan))
    return out


def pack_path(poses: np.ndarray) -> bytes:
    return zlib.compress(np.ascontiguousarray(poses, dtype="<f4").reshape(-1, 3).tobytes(), ZLIB_LEVEL)


def unpack_path(blob: bytes) -> np.ndarray:
    return np.frombuffer(zlib.decompress(blob), dtype="<f4").reshape(-1, 3).astype(np.float64)


def pack_grid(data: np.ndarray) -> bytes:
    return zlib.compress(np.ascontiguousarray(data, dtype=np.int8).tobytes(), ZLIB_LEVEL)


def unpack_grid(blob: bytes, height: int, width: int) -> np.ndarray:
    return np.frombuffer(zlib.decompress(blob), dtype=np.int8).reshape(height, width).copy()
