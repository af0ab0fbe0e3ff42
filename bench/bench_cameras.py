"""The whole fused frame for the rigs people own: a D435 at 848x480 (Intel's recommended mode)
beside an InfiRay P2 Pro (256x192, its own kelvin at 1/64 K), and a D435 at 1280x720 beside a
FLIR Boson 640 (640x512, TLinear), whose pixels are finer than the depth camera's (the
z-buffer is dilated). Each ``Pipeline.process`` (radiometry of the camera's own temperature,
our compensation fitted on that camera's sweep, both registrations, hotspots) against one
librealsense ``rs.align`` thermal -> depth call on the same sizes, in the same run.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from tests.peers import RsAlign

from thermodepth.compensation import RadianceModel, save_model
from thermodepth.evaluation import TRAIN_VOX_STEPS_C
from thermodepth.pipeline import HotspotSettings, Pipeline, Settings
from thermodepth.sim import Rig, camera_pose, plate_scene
from thermodepth.sim.protocols import SweepConfig, simulate_sweep

from .common import Timing, counting, measure, report

RIGS = (("848x480", "p2pro"), ("1280x720", "boson640"))


def main() -> None:
    for depth, thermal in RIGS:
        bench_rig(depth, thermal)


def bench_rig(depth: str, thermal: str) -> None:
    """The fused frame of one rig, and one rs.align call on its sizes."""
    with tempfile.TemporaryDirectory() as tmp:
        model = Path(tmp) / "model.json"
        sweep = simulate_sweep(
            SweepConfig(
                plate_temps_c=(35.0, 50.0),
                samples=100,
                vox_steps_c=TRAIN_VOX_STEPS_C,
                thermal_camera=thermal,
            )
        )
        save_model(RadianceModel.fit(sweep), model)
        settings = Settings(compensation=model, hotspots=HotspotSettings(threshold_c=50.0))
        rig = Rig.of_cameras(
            plate_scene(chip_temp_c=70.0), camera_pose(1.0), thermal, depth, start_s=1.0
        )
        pipe = Pipeline(settings, rig.calibration)
    pairs = list(rig.frames(8))
    timings: list[Timing] = [
        measure(
            f"whole fused frame, {depth} + {thermal} (depth grid asked for)",
            counting(lambda i: pipe.process(pairs[i % len(pairs)]).on_depth),
            n=100,
        ),
        measure(
            f"measurements only, {depth} + {thermal} (depth grid not asked for)",
            counting(lambda i: pipe.process(pairs[i % len(pairs)])),
            n=100,
        ),
    ]
    peer = "rs.align thermal -> depth, one call (1 thread)"
    try:
        aligner = RsAlign(rig.calibration)
    except ImportError:
        aligner = None
    if aligner is not None:
        pair = pairs[0]
        timings.append(
            measure(peer, lambda: aligner.thermal_to_depth(pair.depth, pair.thermal), n=50)
        )
    whole = timings[0]
    versus = (
        f"{timings[-1].median_ms / whole.median_ms:.2f}x"
        if aligner is not None
        else "rs.align not available"
    )
    h, w = rig.calibration.thermal.shape
    report(
        f"fused frame, {depth} depth + {w}x{h} {thermal}",
        timings,
        peer=peer if aligner is not None else None,
        notes={
            "frames per second (whole, median)": f"{1000 / whole.median_ms:.0f}",
            "whole frame faster than one rs.align thermal -> depth call": versus,
            "z-buffer dilation (thermal px)": str(
                getattr(pipe.registration.strategy, "dilation", 0)
            ),
        },
    )
