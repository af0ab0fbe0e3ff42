"""The simulated rig: time to produce one 1280x720 depth + 160x120 thermal frame pair.

Peer: drawing the depth frame's Gaussian noise alone (numpy), a floor every frame pays.
"""

from __future__ import annotations

import itertools

import numpy as np

from thermodepth.sim import Rig, camera_pose, plate_scene

from .common import measure, report


def main() -> None:
    scene = plate_scene(chip_temp_c=70.0)
    distances = itertools.cycle(np.linspace(0.6, 2.4, 7))

    def new_pose() -> None:  # ray casts of both cameras, then the frame
        Rig(scene, camera_pose(next(distances))).frame()

    rig = Rig(scene, camera_pose(1.0))
    rig.frame()
    rng = np.random.default_rng(0)
    timings = [
        measure("frame pair, new pose (ray cast + sensors)", new_pose, n=20),
        measure("frame pair, same pose (sensors only)", rig.frame, n=50),
        measure("ground truth (both grids, occlusion)", rig.truth, n=10),
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
