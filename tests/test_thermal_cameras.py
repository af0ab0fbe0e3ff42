"""The thermal cameras people own, without the hardware: frames and command-channel bytes built
from their documented layouts (the P2 Pro's 256x384 YUYV with 1/64 K below, its vendor
channel; the Boson's Y16 and its FSLP serial frames; the Lepton 2.5's 80x63 with TLinear),
read through our sources with a stand-in VideoCapture and, for the Boson's channel, a real
pseudo-terminal."""

from __future__ import annotations

import binascii
import os
import struct
import threading

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from test_sources import FakeCapture, use_capture
from test_telemetry import telemetry_bytes, words_of
from thermodepth.errors import InputError
from thermodepth.frames import FfcState, thermal_output
from thermodepth.radiometry import ThermalOutput
from thermodepth.sources import infiray, uvc
from thermodepth.sources.base import DeviceLostError
from thermodepth.sources.boson import (
    FFC_STATE,
    FPA_TEMP_C_X10,
    BosonCamera,
    CommandChannel,
    frame_command,
    parse_reply,
)
from thermodepth.sources.infiray import P2ProCamera, VendorChannel, split_frame
from thermodepth.sources.lepton import LeptonCamera

# -- the P2 Pro's frame: 256x384 YUYV, its picture above, 1/64 K below -------------------------


def p2pro_bytes(kelvin: np.ndarray, y: int = 200, u: int = 128, v: int = 128) -> bytes:
    """A P2 Pro frame as the camera sends it: 192 rows of YUYV (Y0 U Y1 V per two pixels) in
    one colour, then 192 rows of little-endian uint16 temperature in 1/64 K."""
    picture = bytes([y, u, y, v]) * (256 * 192 // 2)
    values = np.rint(np.asarray(kelvin) * 64).astype("<u2")
    return picture + values.tobytes()


KELVIN = 293.15 + np.arange(192 * 256).reshape(192, 256) % 97 / 10.0  # 20.0 .. 29.6 C


@pytest.mark.parametrize(
    "shape",
    [(1, 196608), (196608, 1), (196608,), (384, 512), (384, 256, 2)],
    ids=["1xN", "Nx1", "flat", "rows", "pairs"],
)
def test_p2pro_frame_from_any_opencv_build(shape: tuple[int, ...]) -> None:
    raw = np.frombuffer(p2pro_bytes(KELVIN), np.uint8).reshape(shape)
    values, picture = split_frame(raw, "p2pro:2")
    assert values.dtype == np.uint16 and values.shape == (192, 256)
    assert np.array_equal(values, np.rint(KELVIN * 64).astype(np.uint16))  # exact
    assert np.allclose(values / 64.0, KELVIN, atol=1 / 128)  # 1/64 K, rounded
    assert picture.shape == (192, 256, 3) and picture.dtype == np.uint8
    assert np.all(picture == picture[0, 0])  # one colour: grey Y 200
    assert abs(int(picture[0, 0, 0]) - int(picture[0, 0, 2])) <= 1


def test_p2pro_frame_in_low_gain_or_converted_is_one_line() -> None:
    raw = np.frombuffer(p2pro_bytes(KELVIN), np.uint8).reshape(1, -1)
    with pytest.raises(InputError) as info:
        split_frame(raw, "p2pro:2", high_gain=False)
    assert str(info.value) == (
        "p2pro:2: the camera is in low gain (its 150-550 C range), where its values are not "
        "1/64 K: set it to high gain (-20-150 C) to measure with it"
    )
    bgr = np.zeros((384, 256, 3), np.uint8)  # an OpenCV build that converted it to colour
    with pytest.raises(InputError, match=r"^p2pro:2: OpenCV [\d.]+ returned a frame of shape"):
        split_frame(bgr, "p2pro:2")


class FakeUsb:
    """A P2 Pro's vendor channel as the protocol has it: a two-part command (8 bytes to
    0x9d00, 8 bytes to 0x1d08), a status byte at 0x200 (bits 0-1 busy), the reading at
    0x1d10. ``gains`` are the gain readings it gives, one per command; ``writes`` keeps what
    it was sent."""

    def __init__(self, gains: list[int], busy_polls: int = 2) -> None:
        self.gains, self.busy_polls = list(gains), busy_polls
        self.writes: list[tuple[int, bytes]] = []
        self.polls = 0

    def ctrl_transfer(self, request_type: int, request: int, value: int, index: int, data):  # type: ignore[no-untyped-def]
        assert value == 0x78
        if request_type == 0x41:  # a write
            assert request == 0x45
            self.writes.append((index, bytes(data)))
            self.polls = 0
            return len(data)
        assert (request_type, request) == (0xC1, 0x44)
        if index == 0x200:  # status: busy for a few polls, then ready
            self.polls += 1
            return [0x01 if self.polls <= self.busy_polls else 0x00]
        assert index == 0x1D10 and data == 2
        return list(struct.pack(">H", self.gains.pop(0)))


def test_p2pro_vendor_channel_reads_the_gain_with_the_documented_bytes() -> None:
    usb = FakeUsb([1, 0])
    channel = VendorChannel(usb)
    assert channel.high_gain() is True
    assert channel.high_gain() is False
    # command 0x8514 little-endian, then parameter 5 (gain) and 0 big-endian; then 0 and the
    # length 2 big-endian
    head, tail = usb.writes[:2]
    assert head == (0x9D00, bytes.fromhex("1485 0005 00000000"))
    assert tail == (0x1D08, bytes.fromhex("00000000 00000002"))


def test_p2pro_camera_frames_gain_and_shutter(monkeypatch: pytest.MonkeyPatch) -> None:
    frame = np.frombuffer(p2pro_bytes(KELVIN), np.uint8).reshape(1, -1)
    warmer = np.frombuffer(p2pro_bytes(KELVIN + 1.0), np.uint8).reshape(1, -1)
    use_capture(monkeypatch, FakeCapture([frame, warmer, warmer, frame]))
    usb = FakeUsb([1, 1, 1, 0])
    cam = P2ProCamera(index=2, timeout_s=0.05, channel=lambda: VendorChannel(usb), gain_every_s=0)
    got = []
    with pytest.raises(InputError, match=r"^p2pro:2: the camera is in low gain"):
        got.extend(cam)  # the fourth frame comes in low gain: stopped, not converted
    assert len(got) == 3
    assert [f.telemetry.in_ffc for f in got] == [False, False, True]  # the repeated image
    assert cam.counters() == {"thermal_frozen_frames": 1}
    for f in got:
        assert thermal_output(f.telemetry, ThermalOutput()) == ThermalOutput.kelvin_per(1 / 64)
        assert np.isnan(f.telemetry.fpa_temp_k)  # the camera tells no sensor temperature
        assert f.preview is not None and f.preview.shape == (192, 256, 3)
    assert got[1].counts[0, 0] == round((KELVIN[0, 0] + 1.0) * 64)


def test_p2pro_without_its_channel_says_so_once(monkeypatch: pytest.MonkeyPatch) -> None:
    frame = np.frombuffer(p2pro_bytes(KELVIN), np.uint8).reshape(1, -1)
    use_capture(monkeypatch, FakeCapture([frame]))
    told: list[str] = []
    cam = P2ProCamera(index=2, timeout_s=0.05, warn=told.append, channel=lambda: "no pyusb")
    with pytest.raises(DeviceLostError):
        list(cam)
    assert told == [
        "p2pro:2: its gain cannot be read (no pyusb): frames are taken as high gain, the "
        "camera's power-on range (-20-150 C, 1/64 K); keep it there"
    ]
    assert cam.settings["gain_read"] is False


# -- the Boson's serial channel: FSLP frames -------------------------------------------------

# FPA temperature command and reply as a Boson's serial port carries them (ghostCommand's
# capture of a Boson): sequence 1, function 0x00050030, reply 0x017C = 38.0 C
FPA_COMMAND = bytes.fromhex("8E 00 00000001 00050030 FFFFFFFF 4966 AE")
FPA_REPLY = bytes.fromhex("8E 00 00000001 00050030 00000000 017C BDCE AE")


def test_boson_frames_match_the_documented_bytes() -> None:
    assert frame_command(1, FPA_TEMP_C_X10) == FPA_COMMAND
    assert parse_reply(FPA_REPLY) == (1, FPA_TEMP_C_X10, 0, bytes.fromhex("017C"))
    # sysctrlSetUsbVideoIR16Mode (TLinear on), as FLIR's support gave it
    tlinear = bytes.fromhex("8E 00 000000C2 000E000D FFFFFFFF 00000002 C4F2 AE")
    assert frame_command(0xC2, 0x000E000D, bytes.fromhex("00000002")) == tlinear
    with pytest.raises(ValueError, match="CRC mismatch"):
        parse_reply(FPA_REPLY[:-3] + b"\x00\x00\xae")


@given(st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1), st.binary(max_size=40))
def test_boson_escaping_round_trips(sequence: int, function: int, data: bytes) -> None:
    # the frame markers never appear inside a frame, whatever the bytes (0x8E, 0x9E, 0xAE
    # are escaped as 0x9E 0x81, 0x91, 0xA1)
    frame = frame_command(sequence, function, data)
    assert frame[0] == 0x8E and frame[-1] == 0xAE
    assert 0x8E not in frame[1:-1] and 0xAE not in frame[1:-1]
    got = parse_reply(frame)
    assert got == (sequence, function, 0xFFFFFFFF, data)


def boson_reply(sequence: int, function: int, data: bytes) -> bytes:
    """A Boson's reply frame, built from FLIR's framing rules (status 0: no error; CRC-16
    CCITT from 0x1D0F over channel .. data; 0x8E, 0xAE, 0x9E escaped as 0x9E and 0x81, 0xA1,
    0x91)."""
    payload = struct.pack(">BIII", 0, sequence, function, 0) + data
    body = payload + struct.pack(">H", binascii.crc_hqx(payload, 0x1D0F))
    escaped = {0x8E: b"\x9e\x81", 0xAE: b"\x9e\xa1", 0x9E: b"\x9e\x91"}
    return b"\x8e" + b"".join(escaped.get(b, bytes([b])) for b in body) + b"\xae"


def fake_boson(fd: int, fpa_c_x10: int, stop: threading.Event) -> None:
    """Answers FPA and FFC commands on the master side of a pseudo-terminal, as a Boson."""
    buf = bytearray()
    while not stop.is_set():
        try:
            chunk = os.read(fd, 64)
        except OSError:
            return
        buf += chunk
        while 0xAE in buf:
            end = buf.index(0xAE) + 1
            frame, buf = bytes(buf[:end]), buf[end:]
            seq, func, _, _ = parse_reply(frame)
            data = struct.pack(">h", fpa_c_x10) if func == FPA_TEMP_C_X10 else b"\x00\x03"
            os.write(fd, boson_reply(seq, func, data))


@pytest.mark.parametrize("fpa_c_x10", [380, 142, 174])  # 174 = 0xAE, 142 = 0x8E: escaped
def test_boson_channel_over_a_serial_port(fpa_c_x10: int) -> None:
    serial = pytest.importorskip("serial", reason="pyserial (thermodepth[boson]) not installed")
    master, slave = os.openpty()
    stop = threading.Event()
    thread = threading.Thread(target=fake_boson, args=(master, fpa_c_x10, stop), daemon=True)
    thread.start()
    port = serial.Serial(os.ttyname(slave), 921_600, timeout=0.5)
    try:
        channel = CommandChannel(port)
        assert channel.fpa_temp_k() == pytest.approx(fpa_c_x10 / 10 + 273.15)
        assert channel.ffc_state() == FfcState.COMPLETE
        assert channel.sequence == 2
    finally:
        stop.set()
        port.close()
        os.close(master)
        os.close(slave)


class StubChannel(CommandChannel):
    """A command channel whose camera answers from lists (None: no answer)."""

    def __init__(self, fpa_k: list[float | None]) -> None:
        super().__init__(port=None)
        self.fpa = list(fpa_k)

    def call(self, function: int, data: bytes = b"") -> bytes:
        if function == FFC_STATE:
            return b"\x00\x03"
        value = self.fpa.pop(0)
        if value is None:
            raise OSError("no reply")
        return struct.pack(">h", round((value - 273.15) * 10))


def test_boson_camera_in_tlinear(monkeypatch: pytest.MonkeyPatch) -> None:
    image = np.full((512, 640), 30315, np.uint16)  # 303.15 K at 0.01 K
    image[0, 0] = 30415
    frames = [image, image.copy(), image.tobytes(), image + 20]
    use_capture(monkeypatch, FakeCapture(frames))
    cam = BosonCamera(
        index=4,
        output=ThermalOutput.kelvin_per(0.01),
        timeout_s=0.05,
        channel=lambda: StubChannel([310.15, None, 311.15, 311.15]),
        fpa_every_s=0,
    )
    got = []
    with pytest.raises(DeviceLostError):
        got.extend(cam)
    assert [f.counts.shape for f in got] == [(512, 640)] * 4
    assert [f.telemetry.in_ffc for f in got] == [False, True, True, False]  # frozen image
    # the FPA read each frame; a reply that does not come keeps the last (counted)
    assert [round(f.telemetry.fpa_temp_k, 2) for f in got] == [310.15, 310.15, 311.15, 311.15]
    assert cam.counters() == {"thermal_frozen_frames": 2, "thermal_channel_errors": 1}


def test_boson_stated_kind_that_the_frames_are_not(monkeypatch: pytest.MonkeyPatch) -> None:
    counts = np.full((256, 320), 8000, np.uint16)  # counts, where the calibration says TLinear
    use_capture(monkeypatch, FakeCapture([counts]))
    told: list[str] = []
    cam = BosonCamera(
        index=4,
        output=ThermalOutput.kelvin_per(0.01),
        warn=told.append,
        channel=lambda: "pyserial is not installed",
    )
    with pytest.raises(InputError) as info:
        next(iter(cam))
    assert str(info.value).startswith(
        "boson:4: the thermal values read as kelvin x 100 give a median of 80.0 K, which is no "
        "temperature"
    )
    assert told == [
        "boson:4: its command channel cannot be opened (pyserial is not installed): the FPA "
        "(VOx) temperature is unknown (compensated at the model's reference VOx, flagged "
        "no_vox)"
    ]


# -- the Lepton 2.5: 80x63 with TLinear ------------------------------------------------------


def test_lepton_2_5_tlinear_frames(monkeypatch: pytest.MonkeyPatch) -> None:
    words = words_of(telemetry_bytes(frame_counter=9, tlinear=1, tlinear_res=1))[:240]
    image = np.full((60, 80), 31215, np.uint16)  # 312.15 K = 39 C at 0.01 K
    frame = np.vstack([image, words.reshape(3, 80)])
    use_capture(monkeypatch, FakeCapture([frame, frame.astype("<u2").tobytes()]))
    cam = LeptonCamera(index=1, timeout_s=0.05)
    got = []
    with pytest.raises(DeviceLostError):
        got.extend(cam)
    assert [f.counts.shape for f in got] == [(60, 80)] * 2
    t = got[0].telemetry
    assert t.frame_counter == 9 and t.fpa_temp_k == pytest.approx(308.15)
    assert thermal_output(t, ThermalOutput()) == ThermalOutput.kelvin_per(0.01)


@given(st.sampled_from([(122, 160), (120, 160), (63, 80), (60, 80)]), st.integers(0, 3))
def test_y16_frames_rebuilt_from_any_layout(shape: tuple[int, int], layout: int) -> None:
    image = (np.arange(shape[0] * shape[1]) % 16384).astype(np.uint16).reshape(shape)
    raw = image.astype("<u2").tobytes()
    given_as = [
        image,
        np.frombuffer(raw, np.uint8).reshape(1, -1),
        np.frombuffer(raw, np.uint8).reshape(-1, 1),
        image.reshape(1, -1),
    ][layout]
    got = uvc.rebuild(given_as, [(122, 160), (120, 160), (63, 80), (60, 80)], np.uint16, "cam")
    assert got.shape == shape and np.array_equal(got, image)


def test_without_a_p2pro_its_channel_says_why_in_one_line() -> None:
    why = infiray.open_vendor_channel()  # pyusb missing, or no device 0bda:5830 here
    assert isinstance(why, str) and "\n" not in why
