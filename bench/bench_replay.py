"""Replay: reprocessing a recording (``run --source recording:``) on 2 cores.

Recordings of the same live stream (simulated depth at 30 fps, thermal at 8.7 fps, paired
online): ``--depth paired`` and ``--depth all`` with the default codec (lz4), and ``--depth
paired`` with zstd. For each, per pair (medians of the per-pair means over ``RUNS`` passes):
the floor (each pair's depth and thermal chunks read from disk and decoded with blosc
directly on the main thread, nothing else), reading the pairs (``Recording.pairs``: chunk
files, checksums, frames, dropped as they come), and reading + fusing them
(``Pipeline.process``); the peer is the fusion alone on pairs already in memory. Start-up (a
fresh process: imports, numba cache load, opening the recording, one pair) is reported
apart. Targets: reading <= 2.5x the floor; an
hour of the rig (31,320 pairs) in <= 75 s.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numcodecs import blosc

from thermodepth.frames import DepthFrame, StreamEvent, ThermalFrame
from thermodepth.io.recording import Recording, RecordingWriter
from thermodepth.pipeline import Pipeline, Settings
from thermodepth.sim import Rig, camera_pose, plate_scene
from thermodepth.sources.pairing import StreamPairer

from .common import Timing, report

N_DEPTH = 600  # 20 s of the rig: 600 depth, 174 thermal frames
RUNS = 3
HOUR_PAIRS = 31_320


def live_events(n_depth: int) -> list[StreamEvent]:
    """The rig's events: 8 simulated pairs' frames reused at 30 + 8.7 fps, paired online."""
    rig = Rig(plate_scene(chip_temp_c=70.0), camera_pose(1.0))
    pairs = list(rig.frames(8))
    frames: list[DepthFrame | ThermalFrame] = [
        DepthFrame(pairs[i % 8].depth, i / 30, i) for i in range(n_depth)
    ]
    frames += [
        ThermalFrame(pairs[k % 8].thermal, k / 8.7 + 0.004, k, pairs[k % 8].telemetry)
        for k in range(int(n_depth / 30 * 8.7))
    ]
    pairer = StreamPairer()
    events: list[StreamEvent] = []
    for f in sorted(frames, key=lambda f: f.time_s):
        events.append(f)
        events += pairer.add_depth(f) if isinstance(f, DepthFrame) else pairer.add_thermal(f)
    return events + pairer.flush()


def write(out: Path, events: list[StreamEvent], depth_frames: str, codec: str) -> None:
    with RecordingWriter(out, Rig(plate_scene(), camera_pose(1.0)).calibration,
                         depth_frames=depth_frames, codec=codec) as w:  # fmt: skip
        for e in events:
            w.add(e)


def per_pair(name: str, n: int, run: Callable[[], object]) -> Timing:
    """ms per pair: each of RUNS passes timed whole and divided by its ``n`` pairs."""
    times = []
    for _ in range(RUNS):
        t0 = time.perf_counter()
        run()
        times.append((time.perf_counter() - t0) / n)
    return Timing.of(name, np.array(times))


def floor(path: Path) -> None:
    """Each pair's depth and thermal chunks read and blosc-decoded directly (no zarr, no
    checks): the least a replay must do."""
    rec = Recording(path)
    for d_row, t_row, _ in rec._pairs.rows.tolist():
        for stream, row in (("depth", d_row), ("thermal", t_row)):
            data = (path / stream / "image" / "c" / str(row) / "0" / "0").read_bytes()
            blosc.decompress(data[:-4])  # the last 4 bytes: the chunk's CRC-32C


def startup_s(path: Path) -> float:
    """A fresh `thermodepth run` on one pair of the recording, seconds (median of 3)."""
    cmd = [sys.executable, "-m", "thermodepth.cli", "run", "--source", f"recording:{path}",
           "--frames", "1", "--quiet"]  # fmt: skip
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def replay_table(path: Path, mode: str) -> None:
    rec = Recording(path)
    n = rec.n_pairs
    pipe = Pipeline(Settings(), rec.calibration)
    in_memory = list(rec.pairs())
    for p in in_memory[:3]:
        pipe.process(p)  # JIT caches

    def replay() -> None:
        for pair in Recording(path).pairs():
            pipe.process(pair)

    def fuse() -> None:
        for pair in in_memory:
            pipe.process(pair)

    timings = [
        per_pair("floor: blosc decode of the pair's chunks", n, lambda: floor(path)),
        per_pair(
            "read the pairs (Recording.pairs)", n, lambda: deque(Recording(path).pairs(), maxlen=0)
        ),
        per_pair("read + fuse (replay)", n, replay),
        per_pair("fuse alone, pairs in memory (peer)", n, fuse),
    ]
    floor_ms, read_ms, replay_ms = (t.median_ms for t in timings[:3])
    start = startup_s(path)
    hour_s = start + HOUR_PAIRS * replay_ms / 1000
    report(
        f"replay of a recording, --depth {mode}",
        timings,
        peer="fuse alone, pairs in memory (peer)",
        notes={
            "pairs": f"{n} ({rec.n_depth} depth, {rec.n_thermal} thermal frames)",
            "pairs per second (read + fuse)": f"{1000 / replay_ms:.0f}",
            "reading / floor": f"{read_ms / floor_ms:.2f} (target <= 2.5)",
            "start-up (fresh process, one pair), s": f"{start:.2f}",
            "an hour of the rig (31,320 pairs), s": f"{hour_s:.0f} (target <= 75)",
        },
    )


def main() -> None:
    events = live_events(N_DEPTH)
    tmp = Path(tempfile.mkdtemp(prefix="bench-replay-"))
    try:
        for mode, codec in (("paired", "lz4"), ("all", "lz4"), ("paired", "zstd")):
            write(tmp / f"{mode}-{codec}.zarr", events, mode, codec)
            replay_table(tmp / f"{mode}-{codec}.zarr", f"{mode} --codec {codec}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
