"""Depth odometry (``thermodepth.mapping.odometry``): milliseconds per depth frame against the
camera's 33 ms, at 1280x720 and 848x480, and how far the trajectory is from the truth.

The walk: once round a 0.5 m circle in 4 s in the furnished room of tests/test_odometry.py
(a 4 x 4 x 2.5 m box room with nine boxes), the simulated D435 with its noise at 30 fps, 121
frames, so that the last comes back to the first and loop closure has a loop to close. Each
frame is rendered, then :meth:`DepthOdometry.track` is timed on it alone (pyramid, ICP,
keyframes, loop closure and pose graph when they happen); the rows are the medians and p90s
over the frames, with the default threads (numba's, 2 here) and with one. Two untimed frames
of another tracker first (numba's compile or cache load).

Also reported: the slowest frame (a loop closure's registration and pose graph), the ATE
and end-point drift with loop closure and without (the same frames, a second tracker).
"""

from __future__ import annotations

import time

import numba
import numpy as np
from tests.test_odometry import FPS, circle, depth_frame, depth_rig, relative_error, truth_of

from thermodepth.mapping.odometry import DepthOdometry, OdometryOptions
from thermodepth.trajectory import absolute_trajectory_error

from .common import Timing, report

MODES = ("1280x720", "848x480")
FRAMES = 121  # 4 s at 30 fps: frame 120 is back at the start


def walk_timing(mode: str, threads: int) -> tuple[Timing, dict[str, object]]:
    """The per-frame times of a walk at ``mode`` on ``threads`` threads, and notes."""
    rig = depth_rig(mode)
    cal = rig.calibration
    path = circle(0.5, (FRAMES - 1) / FPS)
    warm = DepthOdometry(cal.depth, cal.depth_scale_m)
    for k in range(2):
        warm.track(k / FPS, depth_frame(rig, path(k / FPS)))
    trackers = {
        lc: DepthOdometry(cal.depth, cal.depth_scale_m, OdometryOptions(loop_closure=lc))
        for lc in (True, False)
    }
    seconds = np.empty(FRAMES)
    before = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        for k in range(FRAMES):
            t = k / FPS
            depth = depth_frame(rig, path(t))
            t0 = time.perf_counter()
            trackers[True].track(t, depth)
            seconds[k] = time.perf_counter() - t0
            trackers[False].track(t, depth)
    finally:
        numba.set_num_threads(before)
    timing = Timing.of(f"{mode}, {threads} thread{'s' * (threads > 1)}", seconds)
    truth = truth_of(path, FRAMES)
    notes: dict[str, object] = {"slowest ms": f"{seconds.max() * 1e3:.0f}"}
    for lc, odo in trackers.items():
        result = odo.result()
        ate = absolute_trajectory_error(result.trajectory, truth)
        drift_m, drift_deg = relative_error(
            result.trajectory.pose(FRAMES - 1), result.trajectory.pose(0)
        )
        notes[f"loop closure {'on' if lc else 'off'}"] = (
            f"ATE {ate['rmse_m'] * 1e3:.2f} mm (max {ate['max_m'] * 1e3:.2f}, rotation "
            f"{ate['rotation_rmse_deg']:.3f} deg), end-point drift {drift_m * 1e3:.2f} mm "
            f"{drift_deg:.3f} deg, {len(result.keyframes)} keyframes, "
            f"{len(result.accepted_loops)}/{len(result.loops)} loops accepted"
        )
    return timing, notes


def main() -> None:
    threads = numba.get_num_threads()
    timings, notes = [], {}
    for mode in MODES:
        for n in sorted({threads, 1}, reverse=True):
            timing, walk_notes = walk_timing(mode, n)
            timings.append(timing)
            notes.update({f"{timing.name}: {k}": v for k, v in walk_notes.items()})
    notes["real time"] = f"{1e3 / FPS:.1f} ms a frame"
    report(f"depth odometry, ms per frame ({FRAMES}-frame loop)", timings, notes=notes)


if __name__ == "__main__":
    main()
