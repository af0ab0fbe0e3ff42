"""Registration, depth 1280x720 <-> thermal 160x120: thermodepth against its peers, one run.

Contenders, on the same simulated frames (a hot box in front of a wall; thermal distortion
on, then off): thermodepth's depth_to_thermal, thermal_to_depth standalone (it builds its
z-buffer) and given the z-buffer (``nearest=`` the same frame's depth_to_thermal);
librealsense's rs.align both ways (on a software_device: feeding the frame pair, syncing,
aligning and copying the result out, which is what using it from numpy costs); OpenCV's
registerDepth (depth -> thermal only); the float64 numpy reference; and the memory floor,
one pass over the depth frame (uint16 in, float32 out, preallocated).

Two timings of the same contenders, on this machine (2 cores shared by several people):

- interleaved: each round calls every contender once, in an order that rotates from round to
  round; medians and p90s over the rounds. The others' load drifts over seconds; interleaving
  spreads that drift evenly over the contenders, so their ratios stay comparable, and no
  contender keeps the caches warm for itself (as in a pipeline, registration being one step
  among several).
- back to back: bench.common.measure, n calls of one contender in a row.

The 2-thread numba rows feel the machine's other load in both. OpenMP threads that spin-wait
between parallel regions made a call several times its 1-thread time when another process
held a core (thermal_to_depth 16-24 ms against 5.5 ms), so thermodepth sets
OMP_WAIT_POLICY=PASSIVE unless the environment sets it (``OMP_WAIT_POLICY=ACTIVE make bench``
shows the spinning layer: ~10 % faster on a quiet machine). The 1-thread rows
(numba.set_num_threads(1)) are stable from run to run and compare the same work per core:
rs.align, registerDepth and numpy run on one thread.

Also reported: the agreement between the contenders (tests/peers.py says what each computes)
and numba's compile time (first call in a fresh process, cache empty vs cached).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import numba
import numpy as np
from numpy.typing import NDArray
from rich.markup import escape
from tests.peers import (
    RsAlign,
    border_exclusions,
    depth_frame_z,
    depth_to_thermal_agreement,
    numpy_reference,
    reference_depth_to_thermal,
    reference_thermal_to_depth,
    register_depth_cv2,
    registration_tolerance,
    thermal_index_image,
    thermal_to_depth_agreement,
    without_thermal_distortion,
)

from thermodepth.camera import RigidTransform
from thermodepth.registration import Reason, Registration
from thermodepth.sim import Rig, default_calibration, occlusion_scene

from .common import Timing, counting, measure, report

N_FRAMES = 4
ROUNDS = 20
WARMUP = 2

OURS_D2T = "thermodepth d->t"
OURS_D2T_1 = "thermodepth d->t, 1 thread"
OURS_T2D = "thermodepth t->d standalone"
OURS_T2D_1 = "thermodepth t->d standalone, 1 thread"
OURS_T2D_GIVEN = "thermodepth t->d given z-buffer"
RS_D2T = "rs.align d->t (1 thread)"
RS_T2D = "rs.align t->d (1 thread)"
CV_D2T = "cv2.registerDepth d->t (1 thread)"
REF_D2T = "numpy reference d->t (float64)"
REF_T2D = "numpy reference t->d (float64)"
FLOOR = "memory floor"
SLOW = (CV_D2T, REF_D2T, REF_T2D)

Frame = tuple[NDArray[np.uint16], NDArray[np.uint16]]
T = TypeVar("T")


def interleaved(
    contenders: dict[str, Callable[[int], object]], rounds: int = ROUNDS, warmup: int = WARMUP
) -> list[Timing]:
    """Time every contender once per round, the order rotating; ``fn(i)`` gets the round
    number (to pick a frame). Medians and p90 over the rounds, after ``warmup`` rounds."""
    names = list(contenders)
    times: dict[str, list[float]] = {name: [] for name in names}
    for r in range(warmup + rounds):
        k = r % len(names)
        for name in names[k:] + names[:k]:
            t0 = time.perf_counter()
            contenders[name](r)
            dt = time.perf_counter() - t0
            if r >= warmup:
                times[name].append(dt)
    return [Timing.of(name, t) for name, t in times.items()]


def back_to_back(contenders: dict[str, Callable[[int], object]]) -> list[Timing]:
    """bench.common.measure on each contender in turn (fewer calls for the slow ones)."""
    timings = []
    for name, fn in contenders.items():
        n, warmup = (8, 1) if name in SLOW else (30, 3)
        timings.append(measure(name, counting(fn), n, warmup))
    return timings


def single_threaded(fn: Callable[[int], T]) -> Callable[[int], T]:
    """``fn`` run with numba's thread count set to 1 (restored after)."""

    def run(i: int) -> T:
        n = numba.get_num_threads()
        numba.set_num_threads(1)
        try:
            return fn(i)
        finally:
            numba.set_num_threads(n)

    return run


def _frames() -> list[Frame]:
    rig = Rig(occlusion_scene(), RigidTransform.identity("world", "depth"))
    return [(f.depth, f.thermal) for f in rig.frames(N_FRAMES)]


def _contenders(
    reg: Registration, frames: list[Frame], aligner: RsAlign | None, skipped: dict[str, str]
) -> dict[str, Callable[[int], object]]:
    cal = reg.calibration
    reg1 = single_threaded(lambda _: Registration(cal))(0)  # one chunk of rows: no merge
    nearest = [reg.depth_to_thermal(d) for d, _ in frames]
    tolerance = registration_tolerance(cal)
    out = np.empty(cal.depth.shape, dtype=np.float32)
    scale = np.float32(cal.depth_scale_m)

    def frame(i: int) -> Frame:
        return frames[i % len(frames)]

    c: dict[str, Callable[[int], object]] = {
        OURS_D2T: lambda i: reg.depth_to_thermal(frame(i)[0]),
        OURS_D2T_1: single_threaded(lambda i: reg1.depth_to_thermal(frame(i)[0])),
        OURS_T2D: lambda i: reg.thermal_to_depth(*frame(i)),
        OURS_T2D_1: single_threaded(lambda i: reg1.thermal_to_depth(*frame(i))),
        OURS_T2D_GIVEN: lambda i: reg.thermal_to_depth(*frame(i), nearest=nearest[i % len(frames)]),
    }
    if aligner is not None:
        c[RS_D2T] = lambda i: aligner.depth_to_thermal(frame(i)[0])
        c[RS_T2D] = lambda i: aligner.thermal_to_depth(*frame(i))
    try:
        register_depth_cv2(cal, frames[0][0])
        c[CV_D2T] = lambda i: register_depth_cv2(cal, frame(i)[0])
    except ImportError as exc:
        skipped[CV_D2T] = str(exc)
    c[REF_D2T] = lambda i: reference_depth_to_thermal(cal, frame(i)[0])
    c[REF_T2D] = lambda i: reference_thermal_to_depth(cal, *frame(i), tolerance)
    c[FLOOR] = lambda i: np.multiply(frame(i)[0], scale, out=out)
    return c


def _agreement(
    reg: Registration, depth: NDArray[np.uint16], aligner: RsAlign | None
) -> dict[str, str]:
    """How far the contenders agree on one frame (definitions in tests/peers.py)."""
    cal = reg.calibration
    index = thermal_index_image(cal)
    ours_d2t = reg.depth_to_thermal(depth)
    ours_t2d = reg.thermal_to_depth(depth, index)
    notes: dict[str, str] = {}

    projected = numpy_reference(cal, depth)
    tie, tie_thermal = border_exclusions(cal, projected)
    zbuf = reference_depth_to_thermal(cal, depth, projected)
    values, reason = reference_thermal_to_depth(
        cal, depth, index, registration_tolerance(cal), projected, zbuf
    )
    d2t = depth_to_thermal_agreement(ours_d2t.z_m, zbuf, tie_thermal)
    t2d = thermal_to_depth_agreement(ours_t2d.values, ours_t2d.reason, values, reason, tie)
    notes["ours vs numpy reference"] = (
        f"depth->thermal {d2t:.4%} of thermal pixels (Z within 1e-5), thermal->depth "
        f"{t2d:.4%} of depth pixels (same pixel and reason); pixels within 1e-3 px of a "
        f"border left out ({tie.mean():.2%} of depth, {tie_thermal.mean():.1%} of thermal)"
    )
    try:
        z_cv = register_depth_cv2(cal, depth)
        notes["ours vs cv2.registerDepth"] = (
            f"depth->thermal {depth_to_thermal_agreement(z_cv, ours_d2t.z_m, rtol=1e-4):.3%} "
            "of thermal pixels (Z within 1e-4, both NaN included)"
        )
    except ImportError:
        pass
    if aligner is not None:
        got = aligner.thermal_to_depth(depth, index)
        ok = ours_t2d.reason == Reason.OK
        both = ok & (got > 0)
        bleed = (got > 0) & (ours_t2d.reason == Reason.OCCLUDED)
        jac = cal.thermal.fx / cal.depth.fx
        notes["ours vs rs.align thermal->depth"] = (
            f"same thermal pixel on {(got[both] == ours_t2d.values[both]).mean():.2%} of the "
            f"depth pixels both map (corner vs centre, expected (1 - J/2)^2 = "
            f"{(1 - jac / 2) ** 2:.1%}); rs.align fills {bleed.sum()} pixels ours finds "
            f"occluded and {((got > 0) & ~ok).sum() - bleed.sum()} beyond the thermal edge"
        )
        z_rs = aligner.depth_to_thermal(depth) * cal.depth_scale_m
        z_d = depth_frame_z(cal, ours_d2t.z_m)
        both = np.isfinite(z_d) & (z_rs > 0)
        dz = np.abs(z_rs[both] - z_d[both])
        notes["ours vs rs.align depth->thermal"] = (
            f"within 1 % on {(dz <= 0.01 * z_d[both]).mean():.2%}, within one depth unit on "
            f"{(dz <= cal.depth_scale_m).mean():.1%} of the thermal pixels both fill (ours in "
            f"the depth frame; rs.align keeps raw depth at corners); fill: ours "
            f"{np.isfinite(z_d).mean():.1%}, rs.align {(z_rs > 0).mean():.1%}"
        )
    return notes


def _ratio(timings: list[Timing], a: str, b: str) -> str:
    m = {t.name: t.median_ms for t in timings}
    return f"{m[a] / m[b]:.2f}" if a in m and b in m else "n/a"


JIT_PROBE = """
import json, time
import numpy as np
from thermodepth.registration import Registration
from thermodepth.sim import default_calibration
cal = default_calibration()
reg = Registration(cal)
depth = np.full(cal.depth.shape, 1500, np.uint16)
thermal = np.zeros(cal.thermal.shape, np.uint16)
out = {}
for key, fn in (("depth_to_thermal", lambda: reg.depth_to_thermal(depth)),
                ("thermal_to_depth", lambda: reg.thermal_to_depth(depth, thermal))):
    t0 = time.perf_counter(); fn(); t1 = time.perf_counter(); fn(); t2 = time.perf_counter()
    out[key] = [(t1 - t0) * 1e3, (t2 - t1) * 1e3]
print(json.dumps(out))
"""


def jit_compile_ms() -> str:
    """First calls in fresh processes: numba's on-disk cache empty (compiles), then filled."""
    with tempfile.TemporaryDirectory(prefix="numba-cache-") as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        runs = []
        for _ in range(2):
            done = subprocess.run(
                [sys.executable, "-c", JIT_PROBE],
                env=env,
                capture_output=True,
                text=True,
                check=True,
                cwd=Path(__file__).resolve().parent.parent,
            )
            runs.append(json.loads(done.stdout.strip().splitlines()[-1]))
    cold, warm = runs
    return (
        "; ".join(
            f"{key}: first call {cold[key][0]:.0f} ms with the cache empty, {warm[key][0]:.0f} ms "
            f"cached, then {warm[key][1]:.1f} ms"
            for key in ("depth_to_thermal", "thermal_to_depth")
        )
        + " (each compiles its own kernel; thermal_to_depth standalone builds its z-buffer inside"
        " its sampling kernel)"
    )


def _ratios(timings: list[Timing]) -> dict[str, object]:
    r = _ratio
    return {
        "d->t, ours / rs.align": f"{r(timings, OURS_D2T, RS_D2T)} "
        f"(1 thread: {r(timings, OURS_D2T_1, RS_D2T)})",
        "t->d, ours standalone / rs.align (ours also builds the z-buffer and tests occlusion, "
        "rs.align does neither)": f"{r(timings, OURS_T2D, RS_T2D)} "
        f"(1 thread: {r(timings, OURS_T2D_1, RS_T2D)})",
        "t->d, ours given the z-buffer / rs.align": r(timings, OURS_T2D_GIVEN, RS_T2D),
        "t->d / memory floor": f"standalone {r(timings, OURS_T2D, FLOOR)}, given the z-buffer "
        f"{r(timings, OURS_T2D_GIVEN, FLOOR)}",
        "d->t, ours / cv2.registerDepth": f"{r(timings, OURS_D2T, CV_D2T)} "
        f"(1 thread: {r(timings, OURS_D2T_1, CV_D2T)})",
        "d->t, ours / numpy reference": r(timings, OURS_D2T, REF_D2T),
    }


def main() -> None:
    jit = jit_compile_ms()  # first, while nothing else of ours runs
    frames = _frames()
    base = default_calibration()
    for label, cal in (
        ("k1/k2 thermal distortion", base),
        ("no distortion", without_thermal_distortion(base)),
    ):
        skipped: dict[str, str] = {}
        aligner: RsAlign | None = None
        try:
            aligner = RsAlign(cal)
        except ImportError as exc:
            skipped["rs.align"] = str(exc)
        try:
            reg = Registration(cal)
            contenders = _contenders(reg, frames, aligner, skipped)
            inter = interleaved(contenders)
            hot = back_to_back(contenders)
            agreement = _agreement(reg, frames[0][0], aligner)
        finally:
            if aligner is not None:
                aligner.close()
        title = f"registration 1280x720 <-> 160x120, {label}"
        report(
            f"{title}, interleaved",
            inter,
            peer=FLOOR,
            notes={
                **_ratios(inter),
                **agreement,
                **{f"skipped {k}": escape(v) for k, v in skipped.items()},
            },
        )
        report(
            f"{title}, back to back",
            hot,
            peer=FLOOR,
            notes={**_ratios(hot), "numba JIT": jit},
        )
