"""Sources: specs, two cameras paired on threads, a device lost mid-stream, the Lepton over
UVC (a stand-in VideoCapture), device listing from sysfs."""

from __future__ import annotations

import re
import struct
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from thermodepth.errors import InputError
from thermodepth.frames import DepthFrame, FfcState, Telemetry, ThermalFrame
from thermodepth.io.recording import Recording
from thermodepth.session import record_session
from thermodepth.sources import lepton as lepton_mod
from thermodepth.sources import open_source
from thermodepth.sources.base import DeviceLostError
from thermodepth.sources.lepton import LeptonCamera, list_purethermal, list_video_devices
from thermodepth.sources.paired import PairedSource
from thermodepth.sources.telemetry import parse_telemetry

TEL = Telemetry(frame_counter=0, fpa_temp_k=305.0, housing_temp_k=304.0)


class FakeDepth:
    """30 fps depth frames, optionally losing the device after ``lose_after`` frames."""

    name = "fake-depth"
    live = True

    def __init__(self, n: int, lose_after: int | None = None) -> None:
        self.n, self.lose_after, self.closed = n, lose_after, False

    def __iter__(self) -> Iterator[DepthFrame]:
        for i in range(self.n):
            if self.lose_after is not None and i == self.lose_after:
                raise DeviceLostError(f"{self.name}: stopped delivering frames (unplugged?)")
            yield DepthFrame(np.full((6, 8), i, np.uint16), 0.004 + i / 30, i)

    def close(self) -> None:
        self.closed = True


class FakeThermal:
    name = "fake-lepton"
    live = True

    def __init__(self, n: int) -> None:
        self.n, self.closed = n, False

    def __iter__(self) -> Iterator[ThermalFrame]:
        for k in range(self.n):
            yield ThermalFrame(np.full((3, 4), 8000 + k, np.uint16), k / 8.7, k, TEL)

    def close(self) -> None:
        self.closed = True


def test_paired_source_pairs_two_threaded_cameras() -> None:
    depth, thermal = FakeDepth(90), FakeThermal(26)  # 3 s of each
    # the stand-ins deliver instantly: all depth may arrive before any thermal frame
    src = PairedSource(depth, thermal, history_s=10.0)
    pairs = list(src)
    assert depth.closed and thermal.closed
    assert src.pairing is not None
    assert src.pairing.pairs == len(pairs) >= 24
    for p in pairs:
        assert abs(p.skew_s) <= 0.020
        assert p.depth[0, 0] == round((p.depth_time_s - 0.004) * 30)  # the right frame
    assert [p.index for p in pairs] == list(range(len(pairs)))


def test_device_lost_mid_stream_keeps_every_frame_recorded(tmp_path: Path) -> None:
    src = PairedSource(FakeDepth(90, lose_after=45), FakeThermal(26), history_s=10.0)
    result = record_session(src, tmp_path / "lost.zarr")
    assert result.stopped == "device lost"
    assert result.error == "fake-depth: stopped delivering frames (unplugged?)"
    rec = Recording(tmp_path / "lost.zarr")
    assert rec.complete
    assert rec.n_depth == 45  # every depth frame delivered before the loss
    assert rec.n_pairs == result.pairing.pairs > 0  # type: ignore[union-attr]
    last = list(rec.pairs())[-1]
    assert last.depth_time_s <= 0.004 + 44 / 30 + 1e-9
    assert rec.attrs["stopped"] == "device lost"


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("webcam", "--source: unknown 'webcam'; expected one of sim, realsense"),
        (
            "lepton+realsense",
            "--source: cannot combine 'lepton+realsense'; expected realsense+lepton",
        ),
        ("sim:3", "--source: 'sim' takes no argument"),
        ("recording:", "--source: recording:PATH needs a path"),
        ("lepton:abc", "lepton:abc: expected a video device number"),
    ],
)
def test_bad_specs(spec: str, message: str) -> None:
    with pytest.raises(InputError, match=re.escape(message)):
        open_source(spec)


def test_sim_spec_yields_frame_pairs() -> None:
    src = open_source("sim", frames=2)
    pairs = list(src)
    assert len(pairs) == 2
    assert pairs[0].depth.shape == (720, 1280) and pairs[0].thermal.shape == (120, 160)


# -- the Lepton over UVC ----------------------------------------------------------------------


def telemetry_words(frame_counter: int, ffc_state: int = 3) -> np.ndarray:
    words = np.zeros(320, np.uint16)
    words[0] = 0x0E0E
    words[3] = ffc_state << 4
    words[20], words[21] = frame_counter & 0xFFFF, frame_counter >> 16
    words[24] = 30815
    return words


class FakeCapture:
    """Stands in for cv2.VideoCapture on a PureThermal: ``frames`` are returned by read()."""

    def __init__(self, frames: list[np.ndarray | None]) -> None:
        self.frames = list(frames)
        self.props: dict[int, float] = {}
        self.released = False

    def isOpened(self) -> bool:  # noqa: N802 - OpenCV's name
        return True

    def set(self, prop: int, value: float) -> bool:
        self.props[prop] = value
        return True

    def read(self) -> tuple[bool, np.ndarray | None]:
        if not self.frames:
            return False, None
        f = self.frames.pop(0)
        return f is not None, f

    def release(self) -> None:
        self.released = True


def lepton_frame(k: int, ffc_state: int = 3) -> np.ndarray:
    image = np.full((120, 160), 8000 + k, np.uint16)
    return np.vstack([image, telemetry_words(k, ffc_state).reshape(2, 160)])


def use_capture(monkeypatch: pytest.MonkeyPatch, cap: FakeCapture) -> None:
    monkeypatch.setattr(lepton_mod.cv2, "VideoCapture", lambda *a, **k: cap)


def test_lepton_frames_with_telemetry_and_ffc_flag(monkeypatch: pytest.MonkeyPatch) -> None:
    raw_bytes = lepton_frame(2).astype("<u2").tobytes()
    frames = [
        lepton_frame(0),
        lepton_frame(1, ffc_state=int(FfcState.IN_PROGRESS)),
        np.frombuffer(raw_bytes, np.uint8).reshape(1, -1),  # OpenCV builds that give bytes
        np.zeros((122, 160), np.uint16),  # telemetry all zeros: skipped, counted
    ]
    cap = FakeCapture(frames)
    use_capture(monkeypatch, cap)
    cam = LeptonCamera(index=3, timeout_s=0.05)
    got = []
    with pytest.raises(DeviceLostError, match=r"^lepton:3: stopped delivering frames"):
        for f in cam:
            got.append(f)
    cam.close()
    assert cap.released
    assert cap.props[lepton_mod.cv2.CAP_PROP_CONVERT_RGB] == 0
    assert [f.telemetry.frame_counter for f in got] == [0, 1, 2]
    assert [f.telemetry.in_ffc for f in got] == [False, True, False]
    assert all(f.counts.shape == (120, 160) for f in got)
    assert got[2].counts[0, 0] == 8002
    assert cam.bad_frames == 1


def test_lepton_without_telemetry_rows_says_what_was_expected(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    use_capture(monkeypatch, FakeCapture([np.zeros((120, 160), np.uint16)]))
    cam = LeptonCamera(index=0)
    with pytest.raises(
        InputError,
        match=re.escape(
            "Lepton frame: expected 160x122 Y16 (160x120 image + 2 telemetry rows), got "
            "160x120 (no telemetry rows: enable the Lepton's telemetry)"
        ),
    ):
        next(iter(cam))


def test_lepton_rgb_frames_say_what_was_expected(monkeypatch: pytest.MonkeyPatch) -> None:
    use_capture(monkeypatch, FakeCapture([np.zeros((120, 160, 3), np.uint8)]))
    with pytest.raises(InputError, match=re.escape("got shape (120, 160, 3)")):
        next(iter(LeptonCamera(index=0)))


def fake_sysfs(root: Path, devices: list[tuple[int, str, str | None, int]]) -> Path:
    """/sys/class/video4linux with nodes (N, name, usb vendor:product, index)."""
    for n, name, usb, index in devices:
        node = root / f"video{n}"
        node.mkdir(parents=True)
        (node / "name").write_text(name + "\n")
        (node / "index").write_text(f"{index}\n")
        if usb:
            vendor, product = usb.split(":")
            (node / "device").mkdir()
            (node / "device" / "idVendor").write_text(vendor + "\n")
            (node / "device" / "idProduct").write_text(product + "\n")
    return root


def test_sysfs_listing_finds_purethermal(tmp_path: Path) -> None:
    sysfs = fake_sysfs(
        tmp_path,
        [
            (0, "Integrated Camera", "04f2:b6dd", 0),
            (1, "Integrated Camera", "04f2:b6dd", 1),  # metadata node: left out
            (2, "PureThermal (fw:v1.3.0)", None, 0),
            (4, "UVC Camera", "1e4e:0100", 0),  # found by USB id
        ],
    )
    (sysfs / "video9").mkdir()  # unreadable/empty node: no crash
    assert [d["index"] for d in list_video_devices(sysfs)] == [0, 2, 4, 9]
    assert [d["index"] for d in list_purethermal(sysfs)] == [2, 4]


def test_no_purethermal_lists_what_was_found(tmp_path: Path) -> None:
    sysfs = fake_sysfs(tmp_path, [(0, "Integrated Camera", "04f2:b6dd", 0)])
    with pytest.raises(
        InputError,
        match=re.escape(
            "no PureThermal (Lepton) found; video devices: /dev/video0 (Integrated Camera)"
        ),
    ):
        LeptonCamera(sysfs=sysfs)
    with pytest.raises(
        InputError, match=re.escape("no PureThermal (Lepton) found; no video devices at all")
    ):
        LeptonCamera(sysfs=tmp_path / "none")


def test_lepton_telemetry_words_builder_matches_parser() -> None:
    assert parse_telemetry(telemetry_words(70000)).frame_counter == 70000
    assert struct.pack("<H", 1) == b"\x01\x00"


@pytest.mark.hardware
def test_live_lepton_frame() -> None:
    if not list_purethermal():
        pytest.skip("no PureThermal (Lepton) attached")
    cam = LeptonCamera()
    try:
        frame = next(iter(cam))
    finally:
        cam.close()
    assert frame.counts.shape == (120, 160)
    assert 250 < frame.telemetry.fpa_temp_k < 350
