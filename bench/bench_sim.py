"""The simulated rig: time to produce one 1280x720 depth + 160x120 thermal frame pair, and
its renders alone (each pixel the mean of its sub-rays, cast and shaded in one pass).

Peer: drawing the depth frame's Gaussian noise alone (numpy), a floor every frame pays.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np

from thermodepth.board import BoardSpec
from thermodepth.sim import Rig, camera_pose, plate_scene
from thermodepth.sim.lepton import radiance_table
from thermodepth.sim.scene import board_pattern, target_scene
from thermodepth.sim.shading import render_aperture, render_ir_albedo

from .common import measure, report


def main() -> None:
    scene = plate_scene(chip_temp_c=70.0)
    distances = itertools.cycle(np.linspace(0.6, 2.4, 7))

    def new_pose() -> None:  # ray casts of both cameras, then the frame
        Rig(scene, camera_pose(next(distances))).frame()

    rig = Rig(scene, camera_pose(1.0))
    rig.frame()
    rng = np.random.default_rng(0)
    cal = rig.calibration
    thermal_from_world = cal.thermal_from_depth @ rig.depth_from_world
    table = radiance_table()
    board = target_scene(board_pattern(BoardSpec.parse("checkerboard:9x6", 0.03)))
    near = camera_pose(0.5, 10.0, 5.0).inverse()

    def thermal(ss: int) -> Callable[[], object]:
        return lambda: render_aperture(scene, thermal_from_world, cal.thermal, ss, 0.6, table)

    timings = [
        measure("frame pair, new pose (ray cast + sensors)", new_pose, n=20),
        measure("frame pair, same pose (sensors only)", rig.frame, n=50),
        measure("ground truth (both grids, occlusion)", rig.truth, n=10),
        measure("thermal render, 160x120 at 4x4 sub-rays", thermal(4), n=20),
        measure("thermal render, 160x120 at 8x8 sub-rays", thermal(8), n=20),
        measure(
            "IR albedo render, 1280x720 at 3x3 sub-rays (a board)",
            lambda: render_ir_albedo(board, near, cal.depth, 3),
            n=10,
        ),
        measure(
            "numpy noise for one depth frame (peer)",
            lambda: rng.standard_normal((720, 1280), dtype=np.float32),
            n=50,
        ),
    ]
    report(
        "simulated rig",
        timings,
        peer="numpy noise for one depth frame (peer)",
        notes={"target": "a frame pair well under 50 ms"},
    )
