"""The frame type every source yields: a depth frame and a thermal frame paired in time.

The simulated rig, real cameras and recordings all produce :class:`FramePair`, so nothing
downstream knows where frames came from. Arrays are kept as the devices give them: depth in
the depth camera's integer units (0 = invalid), thermal as the camera's pixel values (raw
counts, or its own temperature at a scale: :func:`thermal_output` says which).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray

from .errors import FieldError
from .radiometry import ZERO_C_IN_K, ThermalOutput


class FfcState(IntEnum):
    """Flat-field correction (shutter) state, as the Lepton telemetry encodes it (IDD)."""

    NEVER_COMMANDED = 0
    IMMINENT = 1
    IN_PROGRESS = 2
    COMPLETE = 3


@dataclass(frozen=True)
class Telemetry:
    """Per-frame thermal camera telemetry (Lepton telemetry row A, SI units).

    frame_counter: the camera's frame count; fpa_temp_k: focal-plane (VOx) temperature, the
    paper's "VOx temperature" (NaN: the camera does not tell it); housing_temp_k: camera
    housing temperature; ffc_state: shutter state; time_since_ffc_s: time since the last FFC
    (None if unknown); ffc_desired: the camera asks for an FFC; tlinear /
    tlinear_resolution_k: the pixels are the camera's own temperature, kelvin x
    1 / resolution (a Lepton's TLinear at 0.01 or 0.1 K, an InfiRay P2 Pro's 1/64 K), not
    raw counts.
    """

    frame_counter: int
    fpa_temp_k: float
    housing_temp_k: float
    ffc_state: FfcState = FfcState.COMPLETE
    time_since_ffc_s: float | None = None
    ffc_desired: bool = False
    tlinear: bool = False
    tlinear_resolution_k: float | None = None

    @property
    def fpa_temp_c(self) -> float:
        return self.fpa_temp_k - ZERO_C_IN_K

    @property
    def in_ffc(self) -> bool:
        """True while the shutter is closed: the frame shows the shutter, not the scene."""
        return self.ffc_state == FfcState.IN_PROGRESS


@dataclass(frozen=True, eq=False)
class FramePair:
    """A depth frame and a thermal frame paired in time, with the thermal telemetry.

    depth: (H, W) uint16 depth-camera units (multiply by the calibration's depth_scale_m;
    0 = invalid); thermal: (h, w) uint16 pixel values (raw counts, or the camera's own
    temperature: :func:`thermal_output`); depth_time_s / thermal_time_s: capture
    times in seconds on one clock; index: the pair's sequence number in its stream;
    ir: optional (H, W) uint8 infrared image of the depth camera; thermal_preview: optional
    (h, w, 3) RGB picture the thermal camera made of the frame itself (a P2 Pro's false
    colour), not recorded.
    """

    depth: NDArray[np.uint16]
    thermal: NDArray[np.uint16]
    depth_time_s: float
    thermal_time_s: float
    telemetry: Telemetry
    index: int = 0
    ir: NDArray[np.uint8] | None = None
    thermal_preview: NDArray[np.uint8] | None = None

    @property
    def skew_s(self) -> float:
        """depth_time_s - thermal_time_s."""
        return self.depth_time_s - self.thermal_time_s


def thermal_output(telemetry: Telemetry, stated: ThermalOutput) -> ThermalOutput:
    """What a frame's thermal pixel values are: the camera's own temperature when its
    telemetry says so (``tlinear``: kelvin per value ``tlinear_resolution_k``, 0.01 if it does
    not say), else what the calibration states (``thermal.output``)."""
    if telemetry.tlinear:
        return ThermalOutput.kelvin_per(telemetry.tlinear_resolution_k or 0.01)
    return stated


@dataclass(frozen=True, eq=False)
class DepthFrame:
    """One frame of the depth camera's stream, before pairing.

    depth: (H, W) uint16 device units (0 = invalid); time_s: capture time in seconds on the
    clock the thermal stream shares; index: the frame's number in its stream (the device's
    frame counter where it has one); ir: optional (H, W) uint8 infrared image.
    """

    depth: NDArray[np.uint16]
    time_s: float
    index: int
    ir: NDArray[np.uint8] | None = None


@dataclass(frozen=True, eq=False)
class ThermalFrame:
    """One frame of the thermal camera's stream, before pairing.

    counts: (h, w) uint16 pixel values (raw counts, or the camera's own temperature:
    :func:`thermal_output`); time_s: capture time in seconds (same clock as the depth stream);
    index: the frame's number in its stream; telemetry: the frame's decoded telemetry;
    preview: the camera's own (h, w, 3) RGB picture of the frame, where it sends one.
    """

    counts: NDArray[np.uint16]
    time_s: float
    index: int
    telemetry: Telemetry
    preview: NDArray[np.uint8] | None = None


def pair_of(depth: DepthFrame, thermal: ThermalFrame, index: int) -> FramePair:
    """The FramePair of two stream frames, numbered ``index``."""
    return FramePair(
        depth.depth,
        thermal.counts,
        depth.time_s,
        thermal.time_s,
        thermal.telemetry,
        index,
        depth.ir,
        thermal.preview,
    )


@dataclass(frozen=True, eq=False)
class Match:
    """A pair and the two stream frames it was made of (what recorders store: the frames
    once, the pair as a reference to them)."""

    depth: DepthFrame
    thermal: ThermalFrame
    pair: FramePair


def match_of(pair: FramePair) -> Match:
    """A FramePair as a Match whose stream frames are numbered by the pair's index (the
    inverse of :func:`pair_of`)."""
    d = DepthFrame(pair.depth, pair.depth_time_s, pair.index, pair.ir)
    t = ThermalFrame(
        pair.thermal, pair.thermal_time_s, pair.index, pair.telemetry, pair.thermal_preview
    )
    return Match(d, t, pair)


StreamEvent = DepthFrame | ThermalFrame | Match
"""What a source emits, in order: stream frames as they arrive and pairs as they form."""


_DEPTH_MODE = re.compile(r"^\s*(\d+)x(\d+)(?:@(\d+(?:\.\d+)?))?\s*$")


def parse_depth_mode(text: str) -> tuple[int, int, float | None]:
    """``WxH`` or ``WxH@FPS`` -> (width, height, fps or None); FieldError (``depth_mode``)
    otherwise."""
    m = _DEPTH_MODE.match(text)
    if m is None:
        raise FieldError("depth_mode", f"{text!r}: expected WIDTHxHEIGHT[@FPS], e.g. 848x480@30")
    fps = float(m.group(3)) if m.group(3) else None
    if fps is not None and fps <= 0:
        raise FieldError("depth_mode", f"{text!r}: the frame rate must be > 0")
    return int(m.group(1)), int(m.group(2)), fps
