"""A FLIR Lepton (2.5, 3.0, 3.1R, 3.5) on a GroupGets PureThermal board, over UVC, with telemetry.

The PureThermal delivers Y16 frames: with the Lepton's telemetry enabled, the image and its
telemetry rows, which it places last (footer): 160x122 for a Lepton 3 / 3.5 (160x120 image),
80x63 for a Lepton 2.x (80x60). The pixels are raw 14-bit counts, or with TLinear on (the
radiometric Lepton 2.5 / 3.5's default on PureThermal firmware) the camera's own temperature,
kelvin x 100 (or x 10): the telemetry of each frame says which, and at what resolution
(:mod:`.telemetry`, row C), as it says the FPA (VOx) temperature and the shutter (FFC) state.
Frames are read through :class:`~.uvc.UvcCapture` (``Y16 ``, RGB conversion off, a one-frame
buffer) and rebuilt from their bytes when the OpenCV build hands those over.

Timestamps: each frame is stamped with ``time.time()`` when ``read()`` returns it (the host
clock librealsense's global time uses), minus ``latency_s``: the time from exposure to
arrival (sensor readout, the PureThermal's USB transfer, driver buffering). It defaults to 0
because it has not been measured; a measured value moves every thermal time by that much.

Telemetry is decoded per frame. A frame whose telemetry rows cannot be decoded is skipped and
counted (``bad_frames``); when none decodes for ``telemetry_timeout_s`` (2 s) the camera stops
with one line naming the likely cause (telemetry in the other location, or disabled). Frames of
the image alone (telemetry disabled) are taken, with one warning: their FPA temperature is
unknown (the compensation falls back to the model's reference VOx temperature), the shutter
(FFC) cannot be told (its frames would be measured) and their kind is the calibration's
``thermal.output``. Frames taken while the shutter is closed (FFC in progress) keep
``telemetry.in_ffc`` set: they are recorded, and a measuring pipeline leaves them out.

Devices are found through sysfs (:func:`~.uvc.list_purethermal`): a capture node whose name
says PureThermal or whose USB vendor:product is GroupGets' 1e4e:0100.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..frames import Telemetry, ThermalFrame
from .telemetry import (
    FRAME_SHAPE,
    FRAME_SHAPES,
    TelemetryError,
    TelemetryLocation,
    parse_telemetry,
    split_frame,
)
from .uvc import SYSFS_VIDEO, UvcCamera, rebuild


def no_telemetry(frame_counter: int) -> Telemetry:
    """What a frame without telemetry tells: its number, nothing more (FPA temperature NaN,
    shutter state not known: taken as open)."""
    nan = float("nan")
    return Telemetry(frame_counter=frame_counter, fpa_temp_k=nan, housing_temp_k=nan)


class LeptonCamera(UvcCamera):
    """Thermal frames from a Lepton on a PureThermal board (module docstring).

    index: the /dev/videoN number (default: the first PureThermal found); location: where the
    telemetry rows sit (PureThermal: ``"footer"``); timeout_s: silence that counts as
    unplugged; telemetry_timeout_s: how long frames may come whose telemetry does not decode
    before the camera stops (InputError); latency_s: subtracted from each frame's arrival
    time (0 = not calibrated); warn: where the one line about frames without telemetry goes.
    Raises InputError when no device is found (naming the video devices there are), when the
    device cannot be opened, and, while iterating, when a frame is no Lepton frame.
    ``close()`` may be called from any thread (see :class:`~.base.DeviceGuard`).
    """

    kind = "lepton"

    def __init__(
        self,
        index: int | None = None,
        location: TelemetryLocation = "footer",
        timeout_s: float = 3.0,
        sysfs: Path = SYSFS_VIDEO,
        telemetry_timeout_s: float = 2.0,
        latency_s: float = 0.0,
        warn: Callable[[str], None] | None = None,
    ) -> None:
        # the Lepton 3's size with telemetry asked for; a Lepton 2.x's board gives its own
        super().__init__(index, "Y16 ", FRAME_SHAPE[::-1], timeout_s, latency_s, warn, sysfs)
        self.location = location
        self.telemetry_timeout_s = telemetry_timeout_s
        self.bad_frames = 0
        self.settings = {
            "device": self.capture.device,
            "telemetry_location": location,
            "latency_s": latency_s,
        }

    def counters(self) -> dict[str, int]:
        return {"thermal_bad_telemetry": self.bad_frames}

    def __iter__(self) -> Iterator[ThermalFrame]:
        """The camera's frames until it is closed; the camera is released when this ends."""
        n = 0
        bad_since: float | None = None
        told = False
        for raw, now in self.capture.frames():
            frame = rebuild(raw, FRAME_SHAPES, np.uint16, self.name)
            image, words = split_frame(frame, self.location)
            if words is None:
                telemetry = no_telemetry(n)
                if not told:
                    told = True
                    self.warn(
                        f"{self.name}: frames without telemetry ({frame.shape[1]}x"
                        f"{frame.shape[0]}): the VOx temperature is unknown (compensated at the "
                        "model's reference VOx, flagged no_vox), shutter (FFC) frames cannot be "
                        "told, and the pixels are what the calibration's thermal.output says; "
                        "enable the Lepton's telemetry"
                    )
            else:
                try:
                    telemetry = parse_telemetry(words)
                except TelemetryError as exc:
                    self.bad_frames += 1
                    bad_since = now if bad_since is None else bad_since
                    if now - bad_since > self.telemetry_timeout_s:
                        raise InputError(self._no_telemetry(frame, exc)) from None
                    continue
                bad_since = None
            yield ThermalFrame(np.ascontiguousarray(image), now, n, telemetry)
            n += 1

    def _no_telemetry(self, frame: np.ndarray, exc: TelemetryError) -> str:
        """The one line for frames whose telemetry never decodes: where it is, or what to
        check."""
        other: TelemetryLocation = "header" if self.location == "footer" else "footer"
        try:
            words = split_frame(frame, other)[1]
            parse_telemetry(words if words is not None else np.zeros(0, np.uint16))
        except TelemetryError:
            return (
                f"{self.name}: no frame with valid telemetry for {self.telemetry_timeout_s:g} s "
                f"({self.bad_frames} frames; last: {exc}); enable the Lepton's telemetry, as a "
                f"{self.location}"
            )
        return (
            f"{self.name}: the telemetry rows are in the {other}, not the {self.location}: "
            f"open the camera with location={other!r}"
        )
