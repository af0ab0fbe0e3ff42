"""An InfiRay P2 Pro (or a Topdon TC001, the same module) over UVC.

The camera (USB 0bda:5830) offers a 256x384 YUYV stream at 25 fps whose upper half is its own
false-colour picture (256x192 YUYV) and whose lower half is its temperature: 256x192
little-endian uint16 in 1/64 K (P2Pro-Viewer's reverse engineering, LeoDJ; the TC001
community's). Only the camera's high-gain range (-20 .. 150 C) is in 1/64 K: in low gain
(150 .. 550 C) the values are not (P2Pro-Viewer issue 22 reports 310 C read where 280 C was
true). The gain is not in the frame: it is a camera setting, read here through the camera's
USB vendor channel (:class:`VendorChannel`) where pyusb can open the device; a frame taken in
low gain stops the camera with one line, never converted. Where the channel cannot be opened
(pyusb missing, no permission on the device), one warning says so and frames are taken as
high gain, the camera's power-on range.

The frames tell nothing else: no sensor (VOx) temperature (the compensation falls back to the
model's reference VOx temperature, flagged ``no_vox``) and no shutter state; while its
shutter is closed the camera repeats its last picture, which no live sensor's noise ever does,
so a frame equal to the one before is taken as a shutter frame (``in_ffc``). The pixels are
the camera's own temperature (``telemetry.tlinear``, 1/64 K per value), the calibration's
``thermal.output`` notwithstanding. The false-colour picture is kept as the frame's preview.
"""

from __future__ import annotations

import struct
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from ..frames import FfcState, Telemetry, ThermalFrame
from .uvc import SYSFS_VIDEO, UvcCamera, frozen, opened_channel, rebuild

STREAM_SIZE = (256, 384)
"""The stream thermodepth opens, width x height: picture above, temperature below."""
IMAGE_SHAPE = (192, 256)
"""The temperature image, rows x columns."""
KELVIN_PER_VALUE = 1 / 64
"""The lower half's unit in high gain."""
USB_ID = (0x0BDA, 0x5830)


def split_frame(
    raw: Any, name: str = "p2pro", high_gain: bool = True
) -> tuple[NDArray[np.uint16], NDArray[np.uint8]]:
    """A P2 Pro frame (what OpenCV's read returns of the 256x384 YUYV stream: the frame or its
    bytes) -> its temperature (192, 256) uint16 in 1/64 K and its picture (192, 256, 3) RGB.
    One InputError line naming ``name`` for a frame that is not 256x384 YUYV, and for a
    frame taken in low gain (``high_gain`` False), whose values are not 1/64 K."""
    rows, cols = IMAGE_SHAPE
    frame = rebuild(raw, [(2 * rows, 2 * cols)], np.uint8, name)  # 2 bytes a pixel
    if not high_gain:
        raise InputError(
            f"{name}: the camera is in low gain (its 150-550 C range), where its values are "
            "not 1/64 K: set it to high gain (-20-150 C) to measure with it"
        )
    temperature = np.ascontiguousarray(frame[rows:]).view("<u2").astype(np.uint16)
    yuyv = np.ascontiguousarray(frame[:rows]).reshape(rows, cols, 2)
    picture = cv2.cvtColor(yuyv, cv2.COLOR_YUV2RGB_YUY2)
    return temperature, np.asarray(picture, dtype=np.uint8)


class VendorChannel:
    """The P2 Pro's USB vendor commands (control transfers; the protocol P2Pro-Viewer
    reverse-engineered): a command is written to the camera in two transfers, the camera is
    polled until it is ready, and a reading's bytes are read back. Only readings are sent
    here (its high / low gain), never a setting. ``device``: a pyusb device, or any object
    with its ``ctrl_transfer``."""

    WRITE = (0x41, 0x45, 0x78)  # bmRequestType, bRequest, wValue of a write
    READ = (0xC1, 0x44, 0x78)
    STATUS_INDEX = 0x200
    COMMAND_INDEX, PARAMS_INDEX, DATA_INDEX = 0x9D00, 0x1D08, 0x1D10
    TPD_PARAMS = 0x8514  # the radiometry's parameters; parameter 5: gain (0 low, 1 high)
    GAIN = 5

    def __init__(self, device: Any, timeout_s: float = 1.0) -> None:
        self.device = device
        self.timeout_s = timeout_s

    def _ready(self) -> None:
        """Wait until the camera has taken the last command (status bits 0, 1 clear); an
        error status or a camera that never gets ready raises OSError."""
        end = time.monotonic() + self.timeout_s
        while True:
            status = int(self.device.ctrl_transfer(*self.READ, self.STATUS_INDEX, 1)[0])
            if status & 0xFC:
                raise OSError(f"the camera's status says error (0x{status:02x})")
            if not status & 0x03:
                return
            if time.monotonic() > end:
                raise OSError("the camera never got ready")
            time.sleep(0.001)

    def read(self, command: int, param: int, length: int = 2) -> bytes:
        """The ``length`` bytes a reading command answers with."""
        head = struct.pack("<H", command) + struct.pack(">HI", param, 0)
        tail = struct.pack(">II", 0, length)
        self.device.ctrl_transfer(*self.WRITE, self.COMMAND_INDEX, head)
        self.device.ctrl_transfer(*self.WRITE, self.PARAMS_INDEX, tail)
        self._ready()
        return bytes(self.device.ctrl_transfer(*self.READ, self.DATA_INDEX, length))

    def high_gain(self) -> bool:
        """True when the camera is in high gain (its -20 .. 150 C range)."""
        (gain,) = struct.unpack(">H", self.read(self.TPD_PARAMS, self.GAIN))
        return bool(gain)


def open_vendor_channel() -> VendorChannel | str:
    """The first P2 Pro's vendor channel through pyusb, or why it cannot be opened."""
    try:
        import usb.core
    except ImportError:
        return "pyusb is not installed (pip install thermodepth[infiray])"
    try:
        device = usb.core.find(idVendor=USB_ID[0], idProduct=USB_ID[1])
    except Exception as exc:  # no libusb backend, ...
        return f"pyusb cannot search the USB bus ({exc})"
    if device is None:
        return "pyusb finds no device 0bda:5830"
    channel = VendorChannel(device)
    try:
        channel.high_gain()
    except Exception as exc:  # no permission (udev), the kernel's driver holds it, ...
        return f"the device does not answer ({exc}; a udev rule may be needed)"
    return channel


class P2ProCamera(UvcCamera):
    """Thermal frames from an InfiRay P2 Pro / Topdon TC001 (module docstring).

    index: the /dev/videoN number (default: the first found by USB id); timeout_s: silence
    that counts as unplugged; latency_s: subtracted from each frame's arrival time; warn:
    where the one line about an unreadable gain goes; channel: how to open the vendor
    channel (:func:`open_vendor_channel`); gain_every_s: how often the gain is read.
    """

    kind = "p2pro"

    def __init__(
        self,
        index: int | None = None,
        timeout_s: float = 3.0,
        latency_s: float = 0.0,
        warn: Callable[[str], None] | None = None,
        sysfs: Path = SYSFS_VIDEO,
        channel: Callable[[], VendorChannel | str] = open_vendor_channel,
        gain_every_s: float = 2.0,
    ) -> None:
        super().__init__(index, "YUYV", STREAM_SIZE, timeout_s, latency_s, warn, sysfs)
        self.gain_every_s = gain_every_s
        self.channel: VendorChannel | None = opened_channel(
            channel(),
            VendorChannel,
            self.warn,
            f"{self.name}: its gain cannot be read ({{reason}}): frames are taken as high "
            "gain, the camera's power-on range (-20-150 C, 1/64 K); keep it there",
        )
        self.frozen_frames = 0
        self.settings = {
            "device": self.capture.device,
            "gain_read": self.channel is not None,
            "latency_s": latency_s,
        }

    def counters(self) -> dict[str, int]:
        return {"thermal_frozen_frames": self.frozen_frames}

    def __iter__(self) -> Iterator[ThermalFrame]:
        """The camera's frames until it is closed; the camera is released when this ends."""
        high, read_at = True, -np.inf
        previous: NDArray[np.uint16] | None = None
        for n, (raw, now) in enumerate(self.capture.frames()):
            if self.channel is not None and time.monotonic() - read_at >= self.gain_every_s:
                high, read_at = self.channel.high_gain(), time.monotonic()
            temperature, picture = split_frame(raw, self.name, high)
            shutter = frozen(temperature, previous)
            self.frozen_frames += shutter
            previous = temperature
            telemetry = Telemetry(
                frame_counter=n,
                fpa_temp_k=float("nan"),
                housing_temp_k=float("nan"),
                ffc_state=FfcState.IN_PROGRESS if shutter else FfcState.COMPLETE,
                tlinear=True,
                tlinear_resolution_k=KELVIN_PER_VALUE,
            )
            yield ThermalFrame(temperature, now, n, telemetry, preview=picture)
