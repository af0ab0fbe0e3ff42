"""The cameras the simulated rig can carry: thermal cameras people pair with depth cameras, each
a sensor model (resolution, field of view, frame rate, output and quantisation, noise, FFC
behaviour, what its frames tell), and the depth camera's modes.

Thermal cameras (:data:`THERMAL_CAMERAS`; figures from the makers' datasheets):

===========  =========  ======  ======  =====================  ===========================
name         pixels     HFOV    rate    output                 frames tell
===========  =========  ======  ======  =====================  ===========================
lepton3      160x120    56 deg  8.7 Hz  14-bit counts          FPA temperature, FFC state
lepton3.5    160x120    57 deg  8.7 Hz  TLinear, 0.01 K        FPA, FFC, TLinear flag
lepton2.5    80x60      51 deg  8.7 Hz  TLinear, 0.01 K        FPA, FFC, TLinear flag
p2pro        256x192    56 deg  25 Hz   kelvin, 1/64 K         nothing (frozen during FFC)
boson320     320x256    50 deg  60 Hz   16-bit counts          FPA (serial channel); frozen
boson640     640x512    50 deg  60 Hz   TLinear, 0.01 K        FPA (serial channel); frozen
===========  =========  ======  ======  =====================  ===========================

Every camera shares the VOx physics of :mod:`.lepton` (the paper's effect: a residual gain and
an interior emission that move with the sensor's temperature); the InfiRay's own firmware
takes out more of it (a stated choice: its residual effect is a third of the Lepton's), and
it tells no sensor temperature, so no compensation can take out the rest. Depth modes
(:data:`DEPTH_MODES`): the D435's 1280x720 (interpolated from its 1280x800 imagers), 848x480
(Intel's recommended mode for the D435/D455) and 640x480, all at the same field of view but
640x480's 4:3 crop.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..calibration import Calibration
from ..camera import Intrinsics, RigidTransform, rotation_from_euler
from ..errors import FieldError
from ..frames import parse_depth_mode
from ..radiometry import ThermalOutput
from .d435 import DepthCameraModel
from .lepton import LeptonModel

DISTORTION = (-0.08, 0.02, 0.0004, -0.0003, 0.0)
"""Mild barrel distortion of every simulated thermal lens, [k1, k2, p1, p2, k3]."""


@dataclass(frozen=True)
class ThermalCamera:
    """A simulated thermal camera: ``width`` x ``height`` pixels over ``hfov_deg`` (square
    pixels, fy 0.2 % above fx), its principal point ``offset_px`` from the image centre (in
    pixels of a 160-wide image, scaled to its own), and its sensor (:class:`LeptonModel`:
    rate, noise, VOx effect, FFC, output)."""

    name: str
    width: int
    height: int
    hfov_deg: float
    sensor: LeptonModel = field(default_factory=LeptonModel)
    offset_px: tuple[float, float] = (1.1, -0.7)

    def intrinsics(self) -> Intrinsics:
        fx = (self.width / 2) / np.tan(np.radians(self.hfov_deg / 2))
        k = self.width / 160
        return Intrinsics(
            self.width,
            self.height,
            fx,
            fx * 1.002,
            (self.width - 1) / 2 + self.offset_px[0] * k,
            (self.height - 1) / 2 + self.offset_px[1] * k,
            np.array(DISTORTION),
        )

    @property
    def output(self) -> ThermalOutput:
        return self.sensor.output


_TLINEAR = ThermalOutput.kelvin_per(0.01)
THERMAL_CAMERAS: dict[str, ThermalCamera] = {
    "lepton3": ThermalCamera("lepton3", 160, 120, 56.0),
    "lepton3.5": ThermalCamera("lepton3.5", 160, 120, 57.0, LeptonModel(output=_TLINEAR)),
    "lepton2.5": ThermalCamera("lepton2.5", 80, 60, 51.0, LeptonModel(output=_TLINEAR)),
    "p2pro": ThermalCamera(
        "p2pro",
        256,
        192,
        56.0,
        LeptonModel(
            output=ThermalOutput.kelvin_per(1 / 64),
            fps=25.0,
            netd_k=0.040,
            supersample=3,
            # a third of the Lepton's net VOx effect: its gain drifts 0.08 %/K where the
            # Lepton's drifts 0.25 %/K (TCR -2/T + c), and a third of its interior emission
            vox_gain_slope_per_k=0.0073,
            interior_emission=0.0033,
            ffc_interval_s=120.0,
            ffc_duration_s=0.4,
            reports_fpa=False,
            ffc_freeze=True,
        ),
    ),
    "boson320": ThermalCamera(
        "boson320",
        320,
        256,
        50.0,
        LeptonModel(
            output=ThermalOutput(bits=16),
            bits=16,
            fps=60.0,
            netd_k=0.040,
            supersample=2,
            ffc_duration_s=0.5,
            ffc_freeze=True,
        ),
    ),
    "boson640": ThermalCamera(
        "boson640",
        640,
        512,
        50.0,
        LeptonModel(
            output=_TLINEAR,
            tells_output=False,
            fps=60.0,
            netd_k=0.040,
            supersample=2,
            ffc_duration_s=0.5,
            ffc_freeze=True,
        ),
    ),
}
"""The simulated thermal cameras by name (module docstring)."""


@dataclass(frozen=True)
class DepthMode:
    """A depth camera mode: ``width`` x ``height`` at ``fps`` with focal length ``fx`` (px)."""

    width: int
    height: int
    fx: float
    fps: float = 30.0

    @property
    def name(self) -> str:
        return f"{self.width}x{self.height}@{self.fps:g}"

    def intrinsics(self) -> Intrinsics:
        return Intrinsics(
            self.width, self.height, self.fx, self.fx, (self.width - 1) / 2, (self.height - 1) / 2
        )


DEPTH_MODES: dict[str, DepthMode] = {
    "1280x720": DepthMode(1280, 720, 645.0),
    "848x480": DepthMode(848, 480, 645.0 * 848 / 1280),
    "640x480": DepthMode(640, 480, 383.0),
}
"""The simulated D435's depth modes by size (module docstring)."""


def depth_mode(text: str | None) -> DepthMode:
    """The simulated depth mode ``WxH[@FPS]`` names (None: 1280x720 at 30 fps); FieldError
    (``depth_mode``) naming the sizes there are."""
    if text is None:
        return DEPTH_MODES["1280x720"]
    w, h, fps = parse_depth_mode(text)
    mode = DEPTH_MODES.get(f"{w}x{h}")
    if mode is None:
        raise FieldError(
            "depth_mode", f"{text!r}: the simulated D435 offers {', '.join(DEPTH_MODES)}"
        )
    return mode if fps is None else replace(mode, fps=fps)


def thermal_camera(name: str | None) -> ThermalCamera:
    """The simulated thermal camera ``name`` (None: the Lepton 3); FieldError
    (``thermal_camera``) naming the cameras there are."""
    if name is None:
        return THERMAL_CAMERAS["lepton3"]
    if name not in THERMAL_CAMERAS:
        raise FieldError(
            "thermal_camera", f"unknown {name!r}; choose from {', '.join(THERMAL_CAMERAS)}"
        )
    return THERMAL_CAMERAS[name]


def rig_calibration(
    thermal: ThermalCamera | None = None, depth: DepthMode | None = None
) -> Calibration:
    """The simulated rig's true calibration for a thermal camera and a depth mode (default:
    the Lepton 3 beside a D435 at 1280x720).

    The thermal camera sits 40 mm left of, 6 mm below and 3 mm behind the depth origin (the
    D435's right imager is on the other side, so the band the thermal camera cannot see
    behind near objects keeps valid depth), turned by about a degree: parallax at 0.5 m is
    ~12 px of a 160-wide thermal image. Depth in 1 mm units.
    """
    thermal = thermal or THERMAL_CAMERAS["lepton3"]
    depth = depth or DEPTH_MODES["1280x720"]
    rot = rotation_from_euler(np.radians(0.4), np.radians(-0.6), np.radians(1.1))
    centre_in_depth = np.array([-0.040, 0.006, -0.003])
    t = RigidTransform(rot, -rot @ centre_in_depth, "thermal", "depth")
    return Calibration(depth.intrinsics(), thermal.intrinsics(), 0.001, t, thermal.output)


def depth_model(mode: DepthMode) -> DepthCameraModel:
    """The D435 noise and range model at ``mode``'s frame rate."""
    return DepthCameraModel(fps=mode.fps)
