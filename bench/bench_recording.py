"""Recording: can the Zarr recorder keep up with the rig on 2 cores?

Live run: a producer thread emits depth frames at 30 fps (1280x720 uint16, simulated with
the D435 noise model) and thermal frames at 8.7 fps (160x120 counts + telemetry), paired
online, into a non-blocking Recorder (a full queue drops frames, as with live cameras), for
``LIVE_S`` seconds, ``RUNS`` times: frames dropped, raw MB/s, MB/s on disk, writer busy time.
The same with ``--depth paired`` (only the depth frames that pair are written).
Capacity: frames written back to back (blocking) -- the headroom over 30 fps.
Per-frame costs as medians; peer: the recording's Blosc codec compressing one depth frame
alone (on one thread, as the recorder's writer thread does).
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
from numcodecs import Blosc, blosc

from thermodepth.frames import DepthFrame, ThermalFrame
from thermodepth.io.recording import Recorder, RecordingWriter, compressors, store_size_bytes
from thermodepth.sim import Rig, camera_pose, plate_scene
from thermodepth.sources.pairing import StreamPairer

from .common import console, counting, measure, report

LIVE_S = 10.0
RUNS = 3
DEPTH_FPS = 30.0
THERMAL_FPS = 8.7


def sample_frames(n: int = 8) -> tuple[list[np.ndarray], list[tuple[np.ndarray, object]]]:
    rig = Rig(plate_scene(chip_temp_c=70.0), camera_pose(1.0))
    pairs = list(rig.frames(n))
    return [p.depth for p in pairs], [(p.thermal, p.telemetry) for p in pairs]


def live_run(
    out: Path,
    depth: list[np.ndarray],  # type: ignore[type-arg]
    thermal: list,  # type: ignore[type-arg]
    depth_frames: str = "all",
) -> dict[str, float]:
    recorder = Recorder(RecordingWriter(out, depth_frames=depth_frames), block=False)
    pairer = StreamPairer()
    offered = {"depth": 0, "thermal": 0}

    # the cameras' frame times, in real time, from this thread (the recorder has its own)
    t0 = time.perf_counter()
    i = k = 0
    while True:
        t_d, t_t = i / DEPTH_FPS, k / THERMAL_FPS
        t_next = min(t_d, t_t)
        if t_next >= LIVE_S:
            break
        delay = t0 + t_next - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        if t_d <= t_t:
            ev = DepthFrame(depth[i % len(depth)], t_d, i)
            recorder.add(ev)
            offered["depth"] += 1
            for m in pairer.add_depth(ev):
                recorder.add(m)
            i += 1
        else:
            counts, tel = thermal[k % len(thermal)]
            th = ThermalFrame(counts, t_t, k, tel)  # type: ignore[arg-type]
            recorder.add(th)
            offered["thermal"] += 1
            for m in pairer.add_thermal(th):
                recorder.add(m)
            k += 1

    for m in pairer.flush():
        recorder.add(m)
    stats = recorder.close()
    disk = store_size_bytes(out)
    return {
        "depth_offered": offered["depth"],
        "thermal_offered": offered["thermal"],
        "dropped": stats.total_dropped,
        "raw_mb_s": stats.mb_per_s,
        "disk_mb_s": disk / 1e6 / stats.wall_s,
        "busy_frac": stats.busy_s / stats.wall_s,
        "pairs": stats.pairs,
    }


def capacity(out: Path, depth: list[np.ndarray], n: int = 60) -> float:
    """Depth frames per second written back to back (synchronous writer)."""
    w = RecordingWriter(out)
    t0 = time.perf_counter()
    for i in range(n):
        w.add_depth(DepthFrame(depth[i % len(depth)], i / 30, i))
    w.close()
    return n / (time.perf_counter() - t0)


def main() -> None:
    depth, thermal = sample_frames()
    tmp = Path(tempfile.mkdtemp(prefix="bench-recording-"))
    try:
        runs = [live_run(tmp / f"live{r}.zarr", depth, thermal) for r in range(RUNS)]
        paired = [live_run(tmp / f"paired{r}.zarr", depth, thermal, "paired") for r in range(RUNS)]
        cap = [capacity(tmp / f"cap{r}.zarr", depth) for r in range(RUNS)]

        w = RecordingWriter(tmp / "per-frame.zarr")

        def write_depth(i: int) -> None:
            w.add_depth(DepthFrame(depth[i % len(depth)], i / 30, i))

        def write_thermal(i: int) -> None:
            counts, tel = thermal[i % len(thermal)]
            w.add_thermal(ThermalFrame(counts, i / 8.7, i, tel))  # type: ignore[arg-type]

        codec = compressors()[0]
        name = f"{codec.cname.value}-{codec.clevel}"
        shuffle = {"noshuffle": Blosc.NOSHUFFLE, "shuffle": Blosc.SHUFFLE}
        nc = Blosc(
            codec.cname.value, codec.clevel, shuffle.get(codec.shuffle.value, Blosc.BITSHUFFLE)
        )
        blosc.use_threads = False  # as on the writer thread
        timings = [
            measure(
                f"write one depth frame ({name} + CRC, commit row)", counting(write_depth), n=40
            ),
            measure("write one thermal frame + telemetry", counting(write_thermal), n=40),
            measure(
                peer := f"Blosc {name} compress one depth frame (peer)", lambda: nc.encode(depth[0])
            ),
        ]
        blosc.use_threads = None
        w.close()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    def med(key: str, of: list[dict[str, float]] = runs) -> float:
        return float(np.median([r[key] for r in of]))

    report(
        "recording",
        timings,
        peer=peer,
        notes={
            "live runs": f"{RUNS} x {LIVE_S:g} s at 30 fps depth + 8.7 fps thermal, non-blocking",
            "frames offered per run": f"{runs[0]['depth_offered']} depth, "
            f"{runs[0]['thermal_offered']} thermal",
            "frames dropped per run": [int(r["dropped"]) for r in runs],
            "raw MB/s (median)": f"{med('raw_mb_s'):.1f}",
            "on disk MB/s (median)": f"{med('disk_mb_s'):.1f}",
            "writer busy fraction (median)": f"{med('busy_frac'):.2f}",
            "--depth paired: frames dropped per run": [int(r["dropped"]) for r in paired],
            "--depth paired: on disk MB/s (median)": f"{med('disk_mb_s', paired):.1f}",
            "--depth paired: writer busy fraction (median)": f"{med('busy_frac', paired):.2f}",
            "capacity, depth frames/s back to back (median)": f"{float(np.median(cap)):.0f}",
        },
    )
    console.print(f"  pairs per run: {[int(r['pairs']) for r in runs]}")
