"""RPLidar A1 protocol: node layout, resync after corruption, scan assembly, CW -> CCW conversion."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robot.profiles import LidarSpec, load_profile
from robot.serial.rplidar import (
    SCAN_DESCRIPTOR,
    Cmd,
    DeviceInfo,
    Health,
    NodeParser,
    Nodes,
    ScanAssembler,
    StreamParser,
    encode_nodes,
    request,
    rotation_to_scan,
)

FUZZ = settings(
    max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)


def _rotations(n_rot: int, per_rot: int = 360, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    ang = np.tile(np.arange(per_rot) * (360.0 / per_rot), n_rot)
    dist = rng.uniform(150, 6000, ang.size)
    start = np.zeros(ang.size, dtype=bool)
    start[::per_rot] = True
    return ang, dist, start


def test_published_byte_layout() -> None:
    # angle 90.0 deg -> q6 5760 = 0x1680; distance 1000.25 mm -> q2 4001 = 0x0FA1; quality 15, start.
    raw = encode_nodes(np.array([90.0]), np.array([1000.25]), np.array([15]), np.array([True]))
    assert raw == bytes([15 << 2 | 0b01, (0x1680 & 0x7F) << 1 | 1, 0x1680 >> 7, 0xA1, 0x0F])
    assert request(Cmd.SCAN) == b"\xa5\x20"
    assert bytes.fromhex("a55a0500004081") == SCAN_DESCRIPTOR
    assert Health(0, 0).encode() == bytes.fromhex("a55a0300000006000000")


def test_requests_with_payload_have_xor_checksum() -> None:
    pkt = request(0xF0, b"\x94\x02")
    assert pkt[:3] == b"\xa5\xf0\x02"
    assert pkt[-1] == 0xA5 ^ 0xF0 ^ 0x02 ^ 0x94 ^ 0x02


def test_parse_round_trip_any_chunking() -> None:
    ang, dist, start = _rotations(3)
    raw = encode_nodes(ang, dist, np.full(ang.size, 47), start)
    p = NodeParser()
    parts = [p.feed(raw[i : i + 13]) for i in range(0, len(raw), 13)]
    nodes = Nodes.concat(parts)
    np.testing.assert_allclose(nodes.angle_deg, ang, atol=1 / 64)
    np.testing.assert_allclose(nodes.dist_mm, dist, atol=0.125)
    assert np.array_equal(nodes.start, start)
    assert p.skipped_bytes == 0


@given(st.binary(max_size=2000))
@FUZZ
def test_garbage_never_raises(garbage: bytes) -> None:
    sp = StreamParser()
    sp.feed(garbage)
    sp.reset()
    sp.feed(SCAN_DESCRIPTOR)
    sp.feed(garbage)


@given(st.lists(st.tuples(st.integers(0, 5 * 360 * 2 - 1), st.integers(0, 255)), max_size=15))
@FUZZ
def test_resync_after_corruption(hits: list[tuple[int, int]]) -> None:
    ang, dist, start = _rotations(2)
    raw = bytearray(encode_nodes(ang, dist, np.full(ang.size, 47), start))
    for pos, val in hits:
        raw[pos] = val
    p = NodeParser()
    nodes = p.feed(bytes(raw))
    # Every corrupted byte costs at most the few nodes around it; the rest decode exactly.
    assert len(nodes) >= ang.size - 4 * len(hits) - 2
    assert len(nodes) <= ang.size
    key = np.round(ang * 64).astype(int)
    got = np.round(nodes.angle_deg * 64).astype(int)
    assert np.isin(got, key).mean() > 0.97 if len(hits) else np.array_equal(got, key)


def test_resync_after_dropped_bytes() -> None:
    ang, dist, start = _rotations(1)
    raw = encode_nodes(ang, dist, np.full(ang.size, 47), start)
    broken = raw[:502] + raw[505:]  # three bytes lost inside node 100
    nodes = NodeParser().feed(broken)
    assert ang.size - 3 <= len(nodes) <= ang.size - 1
    assert nodes.angle_deg[-1] == pytest.approx(ang[-1])


def test_stream_parser_responses_then_scan() -> None:
    info = DeviceInfo(
        model=0x18, firmware=(1, 29), hardware=7, serial_number="00112233445566778899AABBCCDDEEFF"
    )
    ang, dist, start = _rotations(1)
    nodes_raw = encode_nodes(ang, dist, np.full(ang.size, 47), start)
    stream = b"junk" + Health(2, 0x8002).encode() + info.encode() + SCAN_DESCRIPTOR + nodes_raw
    sp = StreamParser()
    responses, nodes = [], []
    for i in range(0, len(stream), 17):
        r, n = sp.feed(stream[i : i + 17])
        responses += r
        nodes.append(n)
    assert responses == [Health(2, 0x8002), info]
    assert len(Nodes.concat(nodes)) == ang.size


def test_assembler_splits_at_start_flags() -> None:
    ang, dist, start = _rotations(4, per_rot=100)
    raw = encode_nodes(ang, dist, np.full(ang.size, 47), start)
    nodes = NodeParser().feed(raw[5 * 30 :])  # join mid-rotation
    asm = ScanAssembler()
    rots = []
    for i in range(0, len(nodes), 37):
        rots += asm.push(nodes.slice(i, i + 37), float(i))
    assert [len(r) for r, _ in rots] == [100, 100]  # the partial first and the open last are not emitted
    assert all(r.start[0] and not r.start[1:].any() for r, _ in rots)


def test_clockwise_to_ccw_known_scan() -> None:
    spec = LidarSpec(beams=360, angle_min=-math.pi, range_min=0.15, range_max=6.0)
    # A1 clockwise angles: obstacle at 1 m straight ahead (0 deg), 2 m at 90 deg CW = the robot's
    # RIGHT (-90 deg CCW), 3 m at 270 deg CW = the LEFT (+90 deg CCW); 45 deg CW reads 0 (no return).
    nodes = Nodes(
        angle_deg=np.array([0.0, 90.0, 270.0, 45.0]),
        dist_mm=np.array([1000.0, 2000.0, 3000.0, 0.0]),
        quality=np.array([47, 47, 47, 0]),
        start=np.array([True, False, False, False]),
    )
    scan = rotation_to_scan(nodes, spec, stamp=3.0)
    assert scan.stamp == 3.0 and scan.frame_id == "laser"

    def at(deg: float) -> float:
        return float(scan.ranges[round((math.radians(deg) - scan.angle_min) / scan.angle_increment) % 360])

    assert at(0) == pytest.approx(1.0)
    assert at(-90) == pytest.approx(2.0)
    assert at(90) == pytest.approx(3.0)
    assert at(-45) == math.inf  # measured, no return (REP-117)
    assert math.isnan(at(10))  # no sample fell in this beam
    pts = scan.points()
    # the 2 m return lies on the right (y < 0) in REP-103
    right = pts[np.argmin(pts[:, 1])]
    np.testing.assert_allclose(right, [0.0, -2.0], atol=1e-9)


def test_binning_keeps_nearest_and_profile_beams() -> None:
    spec = load_profile("skid4").lidar
    nodes = Nodes(
        np.array([10.1, 9.9, 10.0]), np.array([3000.0, 1500.0, 0.0]), np.full(3, 40), np.zeros(3, bool)
    )
    scan = rotation_to_scan(nodes, spec, 0.0)
    assert scan.ranges.shape == (spec.beams,)
    assert np.nanmin(scan.ranges) == pytest.approx(1.5)


def test_partial_fov_drops_samples_outside() -> None:
    spec = LidarSpec(beams=181, fov=math.pi, angle_min=-math.pi / 2)
    nodes = Nodes(np.array([0.0, 180.0]), np.array([1000.0, 1000.0]), np.full(2, 40), np.zeros(2, bool))
    scan = rotation_to_scan(nodes, spec, 0.0)
    assert np.isfinite(scan.ranges).sum() == 1
    assert scan.ranges[90] == pytest.approx(1.0)
