"""Serial-link benchmarks: base frame decode rate and RPLidar node parse rate (one core)."""

from __future__ import annotations

import time

import numpy as np

from bench.core import Benchmark, Figure


def _rate(fn, units: int, min_time: float = 0.3) -> float:
    """Best-of units/s of ``fn`` over repeated runs lasting at least ``min_time`` seconds."""
    best = 0.0
    t_end = time.perf_counter() + min_time
    while True:
        t0 = time.perf_counter()
        fn()
        dt = time.perf_counter() - t0
        best = max(best, units / dt)
        if time.perf_counter() > t_end:
            return best


def frame_decode() -> list[Figure]:
    from robot.serial.protocol import MessageDecoder, Sequencer, Telemetry, VelocityCommand

    rng = np.random.default_rng(0)
    seq = Sequencer()
    n = 5000
    frames = []
    for i in range(n):
        enc = rng.integers(-(2**31), 2**31 - 1, 4).tolist()
        frames.append(seq.encode(Telemetry(i * 20000, *enc, 0.1, 0.0, 0.0, 9.81, 1, 12000, 0)))
    stream = b"".join(frames)
    chunks = [stream[i : i + 64] for i in range(0, len(stream), 64)]  # 64-byte USB-serial reads

    def run() -> None:
        dec = MessageDecoder()
        for c in chunks:
            dec.feed(c)

    rate = _rate(run, n)
    small = b"".join(Sequencer().encode(VelocityCommand(0.1, 0.0, 0.2)) for _ in range(n))
    rate_cmd = _rate(lambda: MessageDecoder().feed(small), n)
    return [
        Figure("telemetry frames decoded", rate, "frames/s", ">= 10000", rate >= 10_000),
        Figure("velocity frames decoded", rate_cmd, "frames/s", ">= 10000", rate_cmd >= 10_000),
    ]


def rplidar_parse() -> list[Figure]:
    from robot.profiles import load_profile
    from robot.serial.rplidar import NodeParser, ScanAssembler, encode_nodes, rotation_to_scan

    rng = np.random.default_rng(0)
    per_rot, rots = 364, 55  # 2000 samples/s at 5.5 Hz, 10 s of data
    n = per_rot * rots
    ang = np.tile(np.arange(per_rot) * 360.0 / per_rot, rots)
    start = np.zeros(n, dtype=bool)
    start[::per_rot] = True
    raw = encode_nodes(ang, rng.uniform(150, 6000, n), np.full(n, 47), start)
    chunks = [raw[i : i + 256] for i in range(0, len(raw), 256)]
    spec = load_profile("skid4").lidar

    def parse_only() -> None:
        p = NodeParser()
        for c in chunks:
            p.feed(c)

    def full() -> None:
        p, asm = NodeParser(), ScanAssembler()
        for c in chunks:
            for rot, stamp in asm.push(p.feed(c), 0.0):
                rotation_to_scan(rot, spec, stamp)

    corrupt = bytearray(raw)
    hits = rng.integers(0, len(raw), 200)
    corrupt_arr = np.frombuffer(corrupt, dtype=np.uint8).copy()
    corrupt_arr[hits] = rng.integers(0, 256, hits.size)
    corrupt_chunks = [corrupt_arr[i : i + 256].tobytes() for i in range(0, corrupt_arr.size, 256)]

    def noisy() -> None:
        p = NodeParser()
        for c in corrupt_chunks:
            p.feed(c)

    r_parse = _rate(parse_only, n)
    r_full = _rate(full, n)
    r_noisy = _rate(noisy, n)
    return [
        Figure("nodes parsed (256-byte reads)", r_parse, "samples/s", ">= 20000", r_parse >= 20_000),
        Figure("nodes -> LaserScans", r_full, "samples/s", ">= 20000", r_full >= 20_000),
        Figure("nodes parsed, 200 bad bytes", r_noisy, "samples/s", ">= 20000", r_noisy >= 20_000),
    ]


def emulated_link() -> list[Figure]:
    """SerialDriver against EmulatorPair over real ptys for 3 s of wall time: rates and watchdog."""
    import tempfile

    from nav.types import Twist2D
    from robot.base import LinkState
    from robot.profiles import load_profile
    from robot.serial.driver import SerialDriver, wait_for
    from robot.serial.emulate import EmulatorPair

    profile = load_profile("skid4")
    with tempfile.TemporaryDirectory() as tmp, EmulatorPair(profile, world="office", link_dir=tmp) as pair:
        d = SerialDriver.from_url(pair.url(), profile)
        try:
            assert wait_for(lambda: d.read().scan is not None, timeout=3.0)
            lidar = d._lidar
            assert lidar is not None
            t0, tel0, scans0, samples0 = time.monotonic(), d._base.good_frames, lidar.scans, lidar.samples
            while time.monotonic() - t0 < 3.0:
                d.command(Twist2D(0.1, 0.0, 0.3))
                d.read()
                time.sleep(0.05)
            dt = time.monotonic() - t0
            tel_hz = (d._base.good_frames - tel0) / dt
            scan_hz = (lidar.scans - scans0) / dt
            samples = (lidar.samples - samples0) / dt
            pair.base.faults.stall = True
            t1 = time.monotonic()
            wait_for(lambda: d.read().link.state is LinkState.LOST, timeout=2.0, period=0.002)
            lost_after = time.monotonic() - t1
        finally:
            d.close()
    rate = profile.lidar.rate_hz
    return [
        Figure("telemetry received", tel_hz, "Hz", "50 +- 5", abs(tel_hz - 50) <= 5),
        Figure("scans assembled", scan_hz, "Hz", f"{rate} +- 10%", abs(scan_hz - rate) <= 0.1 * rate),
        Figure("lidar samples received", samples, "samples/s", ">= 1800", samples >= 1800),
        Figure("stall -> LinkStatus LOST", lost_after * 1000, "ms", "<= 350", lost_after <= 0.35),
    ]


BENCHMARKS = [
    Benchmark(name="serial.frame_decode", run=frame_decode),
    Benchmark(name="serial.rplidar_parse", run=rplidar_parse),
    Benchmark(name="serial.emulated_link", run=emulated_link, group="slow"),
]
