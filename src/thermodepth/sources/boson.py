"""A FLIR Boson / Boson+ (320x256, 640x512) over UVC, with its serial command channel.

The camera (USB 09cb:4007) streams Y16 (``Y16 ``, RGB conversion off): radiometric output
(TLinear, kelvin x 100, on a radiometric Boson+ with it enabled) or raw counts, which the frame
does not say: the calibration's ``thermal.output`` states it, and the first frame whose values
cannot be of that kind (:meth:`~thermodepth.radiometry.ThermalOutput.problem`) stops the
camera with one line.

Its FPA (VOx) temperature is not in the frame: the Boson answers it on its serial command
channel (a CDC-ACM port, 921600 baud; FLIR's "FSLP" framing, :class:`CommandChannel`), read
every second when pyserial can open the port; otherwise one warning says so and the
compensation falls back to the model's reference VOx temperature (``no_vox``). While its
shutter is closed (FFC) the Boson repeats its last image: a frame equal to the one before is a
shutter frame (``in_ffc``), as the channel's FFC state says where it is read.
"""

from __future__ import annotations

import binascii
import struct
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from ..frames import FfcState, Telemetry, ThermalFrame
from ..radiometry import ZERO_C_IN_K, ThermalOutput
from .uvc import SYSFS_VIDEO, UvcCamera, frozen, opened_channel, rebuild

IMAGE_SHAPES = ((512, 640), (256, 320))
"""The Boson's images, rows x columns: the 640 and the 320."""
USB_ID = (0x09CB, 0x4007)
BAUD = 921_600

# FSLP framing (FLIR Boson SDK): a frame is START, the escaped payload and its CRC, END
START, END, ESCAPE = 0x8E, 0xAE, 0x9E
ESCAPED = {START: 0x81, END: 0xA1, ESCAPE: 0x91}
UNESCAPED = {v: k for k, v in ESCAPED.items()}
CRC_INIT = 0x1D0F  # CRC-16/CCITT (polynomial 0x1021) from this value, over the payload
COMMAND_STATUS = 0xFFFFFFFF  # the status word of a command (the reply's is its error code)

FPA_TEMP_C_X10 = 0x00050030  # bosonlookupFPATempDegCx10: FPA temperature, C x 10 (int16)
FFC_STATE = 0x0005000C  # bosonGetFFCStatus: 0 never, 1 imminent, 2 in progress, 3 complete


def frame_command(sequence: int, function: int, data: bytes = b"") -> bytes:
    """The bytes of a command frame: START, then channel 0, sequence and function ID (big
    endian u32), the command status 0xFFFFFFFF, the data, the CRC-16 of all of that (big
    endian), each of those bytes escaped, and END."""
    payload = struct.pack(">BIII", 0, sequence, function, COMMAND_STATUS) + data
    payload += struct.pack(">H", binascii.crc_hqx(payload, CRC_INIT))
    body = b"".join(bytes([ESCAPE, ESCAPED[b]]) if b in ESCAPED else bytes([b]) for b in payload)
    return bytes([START]) + body + bytes([END])


def parse_reply(frame: bytes) -> tuple[int, int, int, bytes]:
    """A reply frame (START .. END) -> (sequence, function, status, data); ValueError when it
    is not one (markers, escapes, length, CRC)."""
    if len(frame) < 2 or frame[0] != START or frame[-1] != END:
        raise ValueError("no frame markers")
    payload = bytearray()
    it = iter(frame[1:-1])
    for b in it:
        if b == ESCAPE:
            nxt = next(it, None)
            if nxt not in UNESCAPED:
                raise ValueError("a bad escape")
            payload.append(UNESCAPED[nxt])
        else:
            payload.append(b)
    if len(payload) < 15:
        raise ValueError(f"{len(payload)} bytes: too short")
    body, crc = bytes(payload[:-2]), struct.unpack(">H", payload[-2:])[0]
    if binascii.crc_hqx(body, CRC_INIT) != crc:
        raise ValueError("CRC mismatch")
    _channel, sequence, function, status = struct.unpack(">BIII", body[:13])
    return sequence, function, status, body[13:]


class CommandChannel:
    """The Boson's serial command channel: a command is a frame (:func:`frame_command`), the
    camera answers with a frame of the same sequence number. ``port``: a pyserial port (or
    anything with ``write``, ``read`` and a ``timeout``)."""

    def __init__(self, port: Any) -> None:
        self.port = port
        self.sequence = 0

    def call(self, function: int, data: bytes = b"") -> bytes:
        """The reply's data; OSError when no good reply comes, or its status is an error."""
        self.sequence = (self.sequence + 1) & 0xFFFFFFFF
        self.port.write(frame_command(self.sequence, function, data))
        buf = bytearray()
        while True:
            b = self.port.read(1)
            if not b:
                raise OSError(f"no reply to 0x{function:08x}")
            if b[0] == START:
                buf = bytearray(b)
            elif buf:
                buf += b
                if b[0] == END:
                    try:
                        seq, func, status, reply = parse_reply(bytes(buf))
                    except ValueError as exc:
                        raise OSError(f"a bad reply to 0x{function:08x}: {exc}") from None
                    if (seq, func) == (self.sequence, function):
                        if status:
                            raise OSError(f"0x{function:08x} answered error 0x{status:08x}")
                        return reply
                    buf = bytearray()

    def fpa_temp_k(self) -> float:
        """The FPA (VOx) temperature, kelvin."""
        (tenths,) = struct.unpack(">h", self.call(FPA_TEMP_C_X10)[:2])
        return tenths / 10.0 + ZERO_C_IN_K

    def ffc_state(self) -> FfcState:
        (state,) = struct.unpack(">H", self.call(FFC_STATE)[:2])
        return FfcState(state) if state <= 3 else FfcState.COMPLETE


def open_command_channel(port: str | None = None) -> CommandChannel | str:
    """The Boson's command channel on ``port`` (None: the first port of USB 09cb:4007),
    through pyserial, or why it cannot be opened."""
    try:
        import serial
        from serial.tools import list_ports
    except ImportError:
        return "pyserial is not installed (pip install thermodepth[boson])"
    if port is None:
        found = [p.device for p in list_ports.comports() if (p.vid, p.pid) == USB_ID]
        if not found:
            return "no serial port of USB 09cb:4007"
        port = found[0]
    try:
        channel = CommandChannel(serial.Serial(port, BAUD, timeout=0.2))
        channel.fpa_temp_k()
    except Exception as exc:  # no permission (dialout), no answer, ...
        return f"{port} does not answer ({exc})"
    return channel


class BosonCamera(UvcCamera):
    """Thermal frames from a FLIR Boson (module docstring).

    index: the /dev/videoN number (default: the first found by USB id); output: what its
    pixels are, as the user states (the calibration's ``thermal.output``; a radiometric Boson+
    in TLinear: kelvin, 0.01); timeout_s, latency_s: as the other cameras; warn: where the
    one line about an unopened command channel goes; channel: how to open it
    (:func:`open_command_channel`); fpa_every_s: how often the FPA temperature is read.
    """

    kind = "boson"

    def __init__(
        self,
        index: int | None = None,
        output: ThermalOutput | None = None,
        timeout_s: float = 3.0,
        latency_s: float = 0.0,
        warn: Callable[[str], None] | None = None,
        sysfs: Path = SYSFS_VIDEO,
        channel: Callable[[], CommandChannel | str] = open_command_channel,
        fpa_every_s: float = 1.0,
    ) -> None:
        super().__init__(index, "Y16 ", None, timeout_s, latency_s, warn, sysfs)
        self.output = output or ThermalOutput(bits=16)
        self.fpa_every_s = fpa_every_s
        self.channel: CommandChannel | None = opened_channel(
            channel(),
            CommandChannel,
            self.warn,
            f"{self.name}: its command channel cannot be opened ({{reason}}): the FPA (VOx) "
            "temperature is unknown (compensated at the model's reference VOx, flagged "
            "no_vox)",
        )
        self.frozen_frames = 0
        self.channel_errors = 0
        self.settings = {
            "device": self.capture.device,
            "output": self.output.as_dict(),
            "fpa_read": self.channel is not None,
            "latency_s": latency_s,
        }

    def counters(self) -> dict[str, int]:
        return {
            "thermal_frozen_frames": self.frozen_frames,
            "thermal_channel_errors": self.channel_errors,
        }

    def _state(self, state: tuple[float, FfcState]) -> tuple[float, FfcState]:
        """The FPA temperature (K) and FFC state from the channel, the last ones when it does
        not answer (counted)."""
        assert self.channel is not None
        try:
            return self.channel.fpa_temp_k(), self.channel.ffc_state()
        except OSError:
            self.channel_errors += 1
            return state

    def __iter__(self) -> Iterator[ThermalFrame]:
        """The camera's frames until it is closed; the camera is released when this ends."""
        state, read_at = (float("nan"), FfcState.COMPLETE), -np.inf
        previous: NDArray[np.uint16] | None = None
        for n, (raw, now) in enumerate(self.capture.frames()):
            image = rebuild(raw, IMAGE_SHAPES, np.uint16, self.name)
            if n == 0:
                why = self.output.problem(image)
                if why is not None:
                    raise InputError(f"{self.name}: {why}")
            if self.channel is not None and time.monotonic() - read_at >= self.fpa_every_s:
                state, read_at = self._state(state), time.monotonic()
            fpa_k, ffc = state
            shutter = frozen(image, previous) or ffc == FfcState.IN_PROGRESS
            self.frozen_frames += frozen(image, previous)
            previous = image
            telemetry = Telemetry(
                frame_counter=n,
                fpa_temp_k=fpa_k,
                housing_temp_k=float("nan"),
                ffc_state=FfcState.IN_PROGRESS if shutter else ffc,
            )
            yield ThermalFrame(np.ascontiguousarray(image), now, n, telemetry)
