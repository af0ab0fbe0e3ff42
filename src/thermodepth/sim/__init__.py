"""The simulated rig: a physically based D435 + Lepton 3 + scene with exact ground truth.

The default source: everything (tests, demo, benchmarks) runs on it without hardware.
See docs/simulator.md for every modelled effect, its equation, default and source.
"""

from .d435 import DepthCameraModel
from .lepton import LeptonModel, constant_fpa, ramp_fpa, steps_fpa, warmup_fpa
from .rig import GroundTruth, Rig, default_calibration
from .scene import (
    Checkerboard,
    CircleGrid,
    Material,
    Rect,
    Scene,
    box,
    camera_pose,
    occlusion_scene,
    plate_scene,
    target_scene,
    wall_scene,
)

__all__ = [
    "Checkerboard",
    "CircleGrid",
    "DepthCameraModel",
    "GroundTruth",
    "LeptonModel",
    "Material",
    "Rect",
    "Rig",
    "Scene",
    "box",
    "camera_pose",
    "constant_fpa",
    "default_calibration",
    "occlusion_scene",
    "plate_scene",
    "ramp_fpa",
    "steps_fpa",
    "target_scene",
    "wall_scene",
    "warmup_fpa",
]
