"""Sources: specs, two cameras paired on threads, a device lost mid-stream, the Lepton over
UVC (a stand-in VideoCapture), device listing from sysfs."""

from __future__ import annotations

import itertools
import re
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from monitor_helpers import PATIENCE_S, wait_for
from test_telemetry import telemetry_bytes, words_of
from thermodepth.errors import FieldError, InputError, ThermodepthError
from thermodepth.frames import (
    DepthFrame,
    FfcState,
    FramePair,
    Telemetry,
    ThermalFrame,
    thermal_output,
)
from thermodepth.io.recording import Recording
from thermodepth.radiometry import ThermalOutput
from thermodepth.session import record_session
from thermodepth.sim import default_calibration
from thermodepth.sources import open_source, split_spec
from thermodepth.sources import realsense as realsense_mod
from thermodepth.sources import uvc as uvc_mod
from thermodepth.sources.base import DeviceLostError
from thermodepth.sources.lepton import LeptonCamera
from thermodepth.sources.paired import PairedSource
from thermodepth.sources.realsense import RealSenseCamera
from thermodepth.sources.sim import sim_device
from thermodepth.sources.uvc import device_index, list_purethermal, list_video_devices

TEL = Telemetry(frame_counter=0, fpa_temp_k=305.0, housing_temp_k=304.0)


class FakeCamera:
    """``n`` frames from ``frame(i)``, optionally losing the device after ``lose_after``."""

    name = "fake"
    live = True

    def __init__(self, n: int, lose_after: int | None = None) -> None:
        self.n, self.lose_after, self.closed = n, lose_after, False

    def frame(self, i: int) -> DepthFrame | ThermalFrame:
        raise NotImplementedError

    def __iter__(self) -> Iterator[DepthFrame | ThermalFrame]:
        for i in range(self.n):
            if self.lose_after is not None and i == self.lose_after:
                raise DeviceLostError(f"{self.name}: stopped delivering frames (unplugged?)")
            yield self.frame(i)

    def close(self) -> None:
        self.closed = True


class FakeDepth(FakeCamera):
    """30 fps depth frames."""

    name = "fake-depth"

    def frame(self, i: int) -> DepthFrame:
        return DepthFrame(np.full((6, 8), i, np.uint16), 0.004 + i / 30, i)


class FakeThermal(FakeCamera):
    """8.7 fps thermal frames."""

    name = "fake-lepton"

    def frame(self, i: int) -> ThermalFrame:
        return ThermalFrame(np.full((3, 4), 8000 + i, np.uint16), i / 8.7, i, TEL)


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


def telemetry_rows(k: int, ffc_state: int = 3) -> np.ndarray:
    """The two telemetry rows (2, 160) of frame ``k`` as the IDD lays them out (TLinear
    resolution word 0: 0.1 K)."""
    words = words_of(telemetry_bytes(frame_counter=k, ffc_state=ffc_state, tlinear_res=0))
    return words.reshape(2, 160)


def lepton_frame(k: int, ffc_state: int = 3) -> np.ndarray:
    return np.vstack([np.full((120, 160), 8000 + k, np.uint16), telemetry_rows(k, ffc_state)])


def use_capture(monkeypatch: pytest.MonkeyPatch, cap: FakeCapture) -> None:
    monkeypatch.setattr(uvc_mod.cv2, "VideoCapture", lambda *a, **k: cap)


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


def test_thermal_camera_lost_mid_stream_keeps_every_frame_recorded(tmp_path: Path) -> None:
    # 40 + 10 frames and 10 pairs: the stand-ins deliver at once, and the recorder's queue
    # (90 events) must not overflow
    src = PairedSource(FakeDepth(40), FakeThermal(26, lose_after=10), history_s=10.0)
    result = record_session(src, tmp_path / "lost.zarr")
    assert result.stopped == "device lost" and result.recorder.total_dropped == 0
    assert result.error == "fake-lepton: stopped delivering frames (unplugged?)"
    rec = Recording(tmp_path / "lost.zarr")
    assert rec.complete and rec.attrs["stopped"] == "device lost"
    assert rec.attrs["error"] == result.error
    assert rec.n_thermal == 10  # every thermal frame delivered before the loss ...
    assert rec.n_pairs == result.pairing.pairs == 10  # type: ignore[union-attr]
    assert [p.thermal[0, 0] for p in rec.pairs()] == [8000 + k for k in range(10)]  # ... paired
    assert rec.n_depth >= 32  # depth up to the last thermal frame's reach (1.034 s + 20 ms)


class LiveDepth:
    """Depth frames every 33 ms on the host clock, until closed; notes on which thread it was
    closed and whether that happened during a (simulated) blocking read."""

    name = "live-depth"
    live = True

    def __init__(self) -> None:
        self.closed = self.reading = self.closed_during_read = False
        self.closed_on: threading.Thread | None = None

    def __iter__(self) -> Iterator[DepthFrame]:
        i = 0
        while not self.closed:
            self.reading = True
            time.sleep(0.033)
            self.reading = False
            yield DepthFrame(np.zeros((6, 8), np.uint16), time.time(), i)
            i += 1

    def close(self) -> None:
        self.closed_during_read |= self.reading
        self.closed_on = threading.current_thread()
        self.closed = True


class BlockingCapture(FakeCapture):
    """A PureThermal whose read() blocks 20 ms waiting for the next frame (OpenCV releases the
    GIL there); notes whether it was released under a read, and on which thread."""

    def __init__(self) -> None:
        super().__init__([])
        self.k = 0
        self.reading = self.released_during_read = False
        self.reads_after_release = 0
        self.released_on: threading.Thread | None = None

    def read(self) -> tuple[bool, np.ndarray | None]:
        if self.released:
            self.reads_after_release += 1
            return False, None
        self.reading = True
        time.sleep(0.02)
        self.reading = False
        self.k += 1
        return True, lepton_frame(self.k)

    def release(self) -> None:
        self.released_during_read |= self.reading
        self.released_on = threading.current_thread()
        super().release()


def test_ctrl_c_closes_each_camera_on_its_reader_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    cap = BlockingCapture()
    use_capture(monkeypatch, cap)
    depth = LiveDepth()
    src = PairedSource(depth, LeptonCamera(index=0), max_skew_s=0.05, history_s=10.0)
    seen = 0
    with pytest.raises(KeyboardInterrupt):  # Ctrl-C lands in the consumer
        try:
            for _pair in src:
                seen += 1
                if seen == 3:
                    raise KeyboardInterrupt
        finally:
            src.close()  # what the sessions do on Ctrl-C
    assert seen == 3
    assert not any(t.is_alive() for t in src._threads)  # joined
    main = threading.current_thread()
    assert cap.released and cap.released_on not in (None, main)  # by the thermal reader
    assert not cap.released_during_read and cap.reads_after_release == 0
    assert depth.closed and depth.closed_on not in (None, main)  # by the depth reader
    assert not depth.closed_during_read


def test_cameras_never_read_are_closed_by_close() -> None:
    depth, thermal = FakeDepth(3), FakeThermal(3)
    PairedSource(depth, thermal).close()
    assert depth.closed and thermal.closed


def test_paired_source_counters_merge_both_cameras(monkeypatch: pytest.MonkeyPatch) -> None:
    use_capture(monkeypatch, FakeCapture([np.zeros((122, 160), np.uint16), lepton_frame(1)]))
    src = PairedSource(FakeDepth(3), LeptonCamera(index=0, timeout_s=0.05))
    list(src)
    assert src.counters() == {"thermal_bad_telemetry": 1}


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("webcam", "source: unknown 'webcam'; expected one of sim[:thermal=CAMERA,depth=WxH,"),
        (
            "lepton+realsense",
            "source: cannot combine 'lepton+realsense'; expected a depth camera and a thermal "
            "camera, DEPTH+THERMAL with DEPTH one of realsense and THERMAL one of lepton, "
            "p2pro, boson",
        ),
        ("realsense+lepton+boson", "source: cannot combine 'realsense+lepton+boson'"),
        ("sim:3", "source: sim:3: expected KEY=VALUE with KEY one of thermal, depth, pace, faults"),
        ("sim:pace=slow", "source: sim:pace=slow: pace: expected real"),
        ("sim:faults=melt@2s", "source: faults: 'melt@2s': expected KIND@Ts or KIND@Ts+Ds"),
        ("sim:faults=unplug@2s", "source: faults: 'unplug@2s': unplug needs a duration"),
        ("sim:thermal=flir", "thermal_camera: unknown 'flir'; choose from lepton3, lepton3.5"),
        ("sim:depth=1280x800", "depth_mode: '1280x800': the simulated D435 offers 1280x720"),
        ("sim:depth=wide", "depth_mode: 'wide': expected WIDTHxHEIGHT[@FPS], e.g. 848x480@30"),
        ("recording:", "source: recording:PATH needs a path"),
        ("folder:", "source: folder:PATH needs a path"),
        ("folder:{tmp}/none", "{tmp}/none: no such folder"),
        ("lepton:abc", "lepton:abc: expected a video device, N or /dev/videoN"),
        ("boson:/dev/cam", "boson:/dev/cam: expected a video device, N or /dev/videoN"),
        (
            "realsense:take.db3+lepton",
            "source: realsense:take.db3+lepton: a RealSense file cannot be paired with a live "
            "thermal camera (the file's times are not the live clock)",
        ),
        ("realsense:{tmp}/take+1.db3", "{tmp}/take+1.db3: no such file"),  # '+' in a path
        ("realsense:{tmp}/a+lepton.bag", "{tmp}/a+lepton.bag: no such file"),
    ],
)
def test_bad_specs(tmp_path: Path, spec: str, message: str) -> None:
    with pytest.raises(InputError, match=re.escape(message.format(tmp=tmp_path))):
        open_source(spec.format(tmp=tmp_path))


@pytest.mark.parametrize(
    ("spec", "parts"),
    [
        ("realsense:123+lepton:2", [("realsense", "123"), ("lepton", "2")]),
        ("realsense+lepton", [("realsense", ""), ("lepton", "")]),
        ("realsense:/data/take+1.db3", [("realsense", "/data/take+1.db3")]),
        ("realsense:/data/a+lepton.db3", [("realsense", "/data/a+lepton.db3")]),
        ("realsense:/data/a+b.db3+lepton:0", [("realsense", "/data/a+b.db3"), ("lepton", "0")]),
        ("recording:/x/a+lepton:2", [("recording", "/x/a+lepton:2")]),
    ],
)
def test_split_spec_splits_only_before_a_source_name(spec: str, parts: list) -> None:  # type: ignore[type-arg]
    assert split_spec(spec) == parts


def test_realsense_plus_lepton_names_every_missing_device(tmp_path: Path) -> None:
    from thermodepth.sources import list_devices

    found = list_devices()
    if found["realsense"] or Path("/dev/video57").exists():
        pytest.skip("a RealSense device or /dev/video57 is attached")
    if found["realsense_unavailable"]:  # no libusb: one line naming the library instead
        with pytest.raises(ThermodepthError) as lost:
            open_source("realsense+lepton:57")
        assert "\n" not in str(lost.value)
        assert "the system library libusb-1.0-0" in str(lost.value)
        return
    with pytest.raises(FieldError) as info:
        open_source("realsense+lepton:57")
    assert info.value.field == "source"  # the CLI names it --source
    assert str(info.value) == (
        "source: realsense+lepton:57: no RealSense device found (is it plugged in?); "
        "/dev/video57: cannot open (no such device)"
    )


def test_sim_spec_yields_frame_pairs() -> None:
    src = open_source("sim", frames=2)
    pairs = list(src)
    assert len(pairs) == 2
    assert pairs[0].depth.shape == (720, 1280) and pairs[0].thermal.shape == (120, 160)


def test_sim_spec_says_once_that_a_given_calibration_is_not_used() -> None:
    lines: list[str] = []
    open_source("sim", frames=1, warn=lines.append).close()
    assert lines == []
    truth = default_calibration()
    mine = replace(truth, depth_scale_m=0.0005)
    src = open_source("sim", mine, frames=1, warn=lines.append)
    assert lines == ["sim: the simulated rig keeps its own calibration; the one given is not used"]
    assert src.calibration is not None
    assert src.calibration.to_dict() == truth.to_dict()  # the rig's truth, not the user's
    src.close()


def device_times(spec: str, pairs: Iterable[FramePair]) -> list[float]:
    """The pairs' thermal times as seconds of the simulated device's own time (a paced
    simulator stamps them in Unix time, as a live camera does)."""
    t0 = sim_device(spec).t0_unix
    return [p.thermal_time_s - t0 for p in pairs]


def test_sim_unplug_loses_the_device_until_its_time_is_up() -> None:
    spec = "sim:pace=real,faults=unplug@0.3s+2s"
    src = open_source(spec)
    pairs: list[FramePair] = []
    with pytest.raises(DeviceLostError, match=r"sim: unplugged at 0.3 s \(for 2 s\)"):
        pairs.extend(src)
    times = device_times(spec, pairs)
    assert times and max(times) < 0.3
    assert abs(pairs[-1].thermal_time_s - time.time()) < 3600  # Unix time, as live cameras
    with pytest.raises(InputError, match="no simulated device"):
        open_source(spec)  # still unplugged: the device's time goes on across openings

    def plugged_again() -> Any:
        try:
            return open_source(spec, frames=2)
        except InputError:
            return None

    again = device_times(spec, wait_for(plugged_again))
    assert [t >= 2.3 for t in again] == [True, True]


def test_sim_stall_sends_nothing_until_closed_then_goes_on() -> None:
    spec = "sim:pace=real,faults=stall@0.2s"
    src = open_source(spec)
    got: list[FramePair] = []
    reader = threading.Thread(target=lambda: got.extend(src))
    reader.start()
    wait_for(lambda: got)
    device = sim_device(spec)
    wait_for(lambda: device.now_s() > 0.6)  # three frames' time past the stall
    assert reader.is_alive() and max(device_times(spec, got)) < 0.2  # stalled
    src.close()
    reader.join(1.0)
    assert not reader.is_alive()  # close() unblocks a stalled camera
    assert len(list(open_source(spec, frames=3))) == 3  # it stalls once


def test_sim_corrupt_ffc_storm_and_vox_ramp_change_the_frames() -> None:
    spec = "sim:pace=real,faults=corrupt@0.25s+0.25s;ffc-storm@0s+0.2s,vox-ramp@0s"
    src = open_source(spec)
    pairs = list(itertools.islice(src, 6))
    src.close()
    times = device_times(spec, pairs)
    clean = [p for p, t in zip(pairs, times, strict=True) if not 0.25 <= t < 0.5]
    bad = [p for p, t in zip(pairs, times, strict=True) if 0.25 <= t < 0.5]
    assert bad and clean
    assert all(p.thermal.std() > 10 * c.thermal.std() for p in bad for c in clean)
    storm = [p.telemetry.ffc_state for p, t in zip(pairs, times, strict=True) if t < 0.18]
    assert storm and set(storm) == {FfcState.IN_PROGRESS}
    fpa = [p.telemetry.fpa_temp_k for p in pairs]
    assert fpa[-1] - fpa[0] == pytest.approx(times[-1] - times[0], rel=0.05)  # 1 K/s


# -- the Lepton over UVC ----------------------------------------------------------------------


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
    assert cap.props[uvc_mod.cv2.CAP_PROP_CONVERT_RGB] == 0
    assert [f.telemetry.frame_counter for f in got] == [0, 1, 2]
    assert [f.telemetry.in_ffc for f in got] == [False, True, False]
    assert all(f.counts.shape == (120, 160) for f in got)
    assert got[2].counts[0, 0] == 8002
    assert cam.bad_frames == 1


def test_lepton_without_telemetry_rows_is_taken_with_one_warning(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    image = np.full((60, 80), 8100, np.uint16)  # a Lepton 2.x, telemetry disabled
    use_capture(monkeypatch, FakeCapture([image, image.tobytes()]))
    told: list[str] = []
    cam = LeptonCamera(index=0, timeout_s=0.05, warn=told.append)
    got = []
    with pytest.raises(DeviceLostError):
        got.extend(cam)
    assert [f.counts.shape for f in got] == [(60, 80), (60, 80)]
    assert all(np.isnan(f.telemetry.fpa_temp_k) and not f.telemetry.tlinear for f in got)
    assert told == [
        "lepton:0: frames without telemetry (80x60): the VOx temperature is unknown "
        "(compensated at the model's reference VOx, flagged no_vox), shutter (FFC) frames "
        "cannot be told, and the pixels are what the calibration's thermal.output says; enable "
        "the Lepton's telemetry"
    ]


def test_lepton_rgb_frames_say_what_was_expected(monkeypatch: pytest.MonkeyPatch) -> None:
    # an OpenCV build that converts the stream to 8-bit RGB: no temperature can come from it
    use_capture(monkeypatch, FakeCapture([np.zeros((120, 160, 3), np.uint8)]))
    with pytest.raises(InputError) as info:
        next(iter(LeptonCamera(index=0)))
    assert str(info.value).startswith(
        f"lepton:0: OpenCV {uvc_mod.cv2.__version__} returned a frame of shape (120, 160, 3) "
        "uint8, not a 160x122 or 160x120 or 80x63 or 80x60 uint16 frame nor its bytes"
    )


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


def test_sysfs_listing_finds_every_thermal_camera(tmp_path: Path) -> None:
    sysfs = fake_sysfs(
        tmp_path,
        [
            (0, "Integrated Camera", "04f2:b6dd", 0),
            (1, "Integrated Camera", "04f2:b6dd", 1),  # metadata node: left out
            (2, "PureThermal (fw:v1.3.0)", None, 0),
            (4, "UVC Camera", "1e4e:0100", 0),  # found by USB id
            (6, "USB Camera", "0bda:5830", 0),  # an InfiRay P2 Pro
            (8, "Boson: FLIR Video", "09cb:4007", 0),
        ],
    )
    (sysfs / "video9").mkdir()  # unreadable/empty node: no crash
    assert [d["index"] for d in list_video_devices(sysfs)] == [0, 2, 4, 6, 8, 9]
    assert [d["kind"] for d in list_video_devices(sysfs)] == [
        None, "lepton", "lepton", "p2pro", "boson", None,
    ]  # fmt: skip
    assert [d["index"] for d in list_purethermal(sysfs)] == [2, 4]
    assert device_index("p2pro", "", sysfs) == 6
    assert device_index("boson", "/dev/video3", sysfs) == 3
    with pytest.raises(InputError, match=r"^no FLIR Boson found; video devices: /dev/video0"):
        device_index("boson", "", fake_sysfs(tmp_path / "b", [(0, "Integrated Camera", None, 0)]))


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


def usb_tree(root: Path, index: int, bus: int, dev: int) -> tuple[Path, Path]:
    """A sysfs video node /dev/videoN under a USB interface of device BUS-DEV, as the kernel
    lays it out (busnum and devnum on the device, above the interface), and its usbfs node."""
    usb = root / "devices" / "usb1" / "1-1"
    (usb / "1-1:1.0").mkdir(parents=True)
    (usb / "busnum").write_text(f"{bus}\n")
    (usb / "devnum").write_text(f"{dev}\n")
    node = root / "class" / f"video{index}"
    node.mkdir(parents=True)
    (node / "device").symlink_to(usb / "1-1:1.0")
    devfs = root / "bus" / "usb"
    (devfs / f"{bus:03d}").mkdir(parents=True)
    (devfs / f"{bus:03d}" / f"{dev:03d}").write_bytes(b"")
    return root / "class", devfs


def test_usb_reset_of_a_stalled_camera(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    sysfs, devfs = usb_tree(tmp_path, 2, bus=1, dev=5)
    assert uvc_mod.usb_device_node(2, sysfs, devfs) == devfs / "001" / "005"
    calls = []
    monkeypatch.setattr(uvc_mod.fcntl, "ioctl", lambda fd, request, arg: calls.append(request))
    line = uvc_mod.usb_reset(2, "lepton:2", sysfs, devfs)
    assert line == f"lepton:2: USB reset of {devfs / '001' / '005'}"
    assert calls == [0x5514]  # USBDEVFS_RESET, _IO('U', 20) of linux/usbdevice_fs.h
    monkeypatch.undo()
    # a node that is not usbfs refuses the ioctl: said, not raised
    assert uvc_mod.usb_reset(2, "lepton:2", sysfs, devfs).startswith(
        f"lepton:2: USB reset of {devfs / '001' / '005'} failed ("
    )


def test_usb_reset_says_where_it_may_not(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    sysfs, devfs = usb_tree(tmp_path, 2, bus=3, dev=9)

    def refused(path: object, flags: int) -> int:
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(uvc_mod.os, "open", refused)
    assert uvc_mod.usb_reset(2, "lepton:2", sysfs, devfs) == (
        f"lepton:2: no USB reset of {devfs / '003' / '009'}: this process may not write it "
        "(run as root, or grant it with a udev rule)"
    )
    monkeypatch.undo()
    assert uvc_mod.usb_reset(7, "boson:7", sysfs, devfs) == (
        "boson:7: no USB reset: /dev/video7 is not a USB device here"
    )


def test_a_paired_source_recovers_through_its_thermal_camera(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    use_capture(monkeypatch, FakeCapture([lepton_frame(1)]))
    src = PairedSource(FakeDepth(1), LeptonCamera(index=4, timeout_s=0.05, sysfs=tmp_path))
    src.close()
    asked = []
    monkeypatch.setattr(
        uvc_mod, "usb_reset", lambda *a: asked.append(a) or f"{a[1]}: USB reset of BBB/DDD"
    )
    assert src.recover() == "lepton:4: USB reset of BBB/DDD"
    assert asked == [(4, "lepton:4", tmp_path)]
    assert open_source("sim", frames=1).recover() is None  # nothing to reset


class EndlessCapture(FakeCapture):
    """read() returns ``make(k)`` forever, one frame per 5 ms; fails the test after 60 s (a
    camera that never gives up)."""

    def __init__(self, make: Callable[[int], np.ndarray]) -> None:
        super().__init__([])
        self.make, self.k, self.t0 = make, 0, time.monotonic()

    def read(self) -> tuple[bool, np.ndarray | None]:
        assert time.monotonic() - self.t0 < 60.0, "the camera kept reading frames it cannot use"
        time.sleep(0.005)
        self.k += 1
        return True, self.make(self.k)


def test_lepton_without_telemetry_stops_with_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    use_capture(monkeypatch, EndlessCapture(lambda k: np.zeros((122, 160), np.uint16)))
    cam = LeptonCamera(index=0, telemetry_timeout_s=0.2)
    with pytest.raises(InputError) as info:
        list(cam)
    message = str(info.value)
    assert message.startswith("lepton:0: no frame with valid telemetry for 0.2 s (")
    assert message.endswith(
        "last: telemetry: row A is all zeros (is telemetry enabled? expected 160x122 or 80x63 "
        "frames)); enable the Lepton's telemetry, as a footer"
    )
    assert cam.bad_frames >= 10


def test_lepton_telemetry_in_the_header_is_named(monkeypatch: pytest.MonkeyPatch) -> None:
    def header_frame(k: int) -> np.ndarray:
        return np.vstack([telemetry_rows(k), np.full((120, 160), 8000, np.uint16)])

    use_capture(monkeypatch, EndlessCapture(header_frame))
    with pytest.raises(
        InputError,
        match=re.escape(
            "lepton:0: the telemetry rows are in the header, not the footer: open the camera "
            "with location='header'"
        ),
    ):
        list(LeptonCamera(index=0, telemetry_timeout_s=0.1))


def test_lepton_tlinear_frames_say_so(monkeypatch: pytest.MonkeyPatch) -> None:
    frame = lepton_frame(0)
    frame[:120] = 3122  # 312.2 K at 0.1 K per value
    frame[121, 48] = 1  # row C word 48: TLinear on; word 49 = 0: 0.1 K per count
    use_capture(monkeypatch, FakeCapture([frame]))
    got = next(iter(LeptonCamera(index=0)))
    assert got.telemetry.tlinear and got.telemetry.tlinear_resolution_k == 0.1
    assert thermal_output(got.telemetry, ThermalOutput()) == ThermalOutput.kelvin_per(0.1)


def test_lepton_one_frame_buffer_and_latency(monkeypatch: pytest.MonkeyPatch) -> None:
    cap = FakeCapture([lepton_frame(0)])
    use_capture(monkeypatch, cap)
    cam = LeptonCamera(index=0, latency_s=0.25)
    before = time.time()
    frame = next(iter(cam))
    assert cap.props[uvc_mod.cv2.CAP_PROP_BUFFERSIZE] == 1
    assert before - 0.25 <= frame.time_s <= time.time() - 0.25
    assert cam.settings["latency_s"] == 0.25


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


# -- RealSense over a stand-in pyrealsense2 ---------------------------------------------------


class RsFrame:
    def __init__(self, number: int, pixels: np.ndarray) -> None:
        self.number, self.pixels = number, pixels

    def __bool__(self) -> bool:
        return True

    def get_frame_number(self) -> int:
        return self.number

    def get_data(self) -> np.ndarray:
        return self.pixels

    def get_timestamp(self) -> float:
        return 1_700_000_000_000.0 + self.number * 1000 / 30

    def get_frame_timestamp_domain(self) -> str:
        return "global_time"


class RsFrameset:
    def __init__(self, number: int, ir: bool = True) -> None:
        self.depth = RsFrame(number, np.full((2, 3), number, np.uint16))
        self.ir = RsFrame(number, np.full((2, 3), 7, np.uint8)) if ir else None

    def get_depth_frame(self) -> RsFrame:
        return self.depth

    def get_infrared_frame(self, index: int) -> RsFrame | None:
        return self.ir


class RsPipeline:
    """Stands in for rs.pipeline: framesets from ``script`` (None: a wait that times out), then
    ``then`` forever (default: timeouts). Each wait blocks ``wait_s``; notes on which thread it
    was stopped and whether a wait was in progress then. Fails the test after 3 s of waits (a
    camera that never gives up)."""

    def __init__(
        self,
        script: list[RsFrameset | None],
        then: RsFrameset | None = None,
        wait_s: float = 0.002,
        broken_sensor: bool = False,
        ppx: float = 1.0,
    ) -> None:
        self.script, self.then, self.wait_s = list(script), then, wait_s
        self.broken_sensor, self.ppx = broken_sensor, ppx
        self.t0 = time.monotonic()
        self.waiting = self.stopped_during_wait = False
        self.stops: list[threading.Thread] = []

    def start(self, config: object) -> object:
        return RsProfile(self.broken_sensor, self.ppx)

    def try_wait_for_frames(self, timeout_ms: int) -> tuple[bool, RsFrameset | None]:
        assert time.monotonic() - self.t0 < 60.0, "the camera kept waiting for a new frame"
        self.waiting = True
        time.sleep(self.wait_s)
        self.waiting = False
        fs = self.script.pop(0) if self.script else self.then
        return fs is not None, fs

    def stop(self) -> None:
        self.stopped_during_wait |= self.waiting
        self.stops.append(threading.current_thread())


class RsProfile:
    def __init__(self, broken_sensor: bool = False, ppx: float = 1.0) -> None:
        self.broken_sensor, self.ppx = broken_sensor, ppx

    def get_device(self) -> RsProfile:
        return self

    def get_info(self, key: object) -> str:
        return "000000000001"

    def supports(self, key: object) -> bool:
        return True

    def first_depth_sensor(self) -> RsProfile:
        if self.broken_sensor:
            raise RuntimeError("failed to query the depth sensor")
        return self

    def get_depth_scale(self) -> float:
        return 0.001

    def get_stream(self, kind: object) -> RsProfile:
        return self

    def as_video_stream_profile(self) -> RsProfile:
        return self

    def get_intrinsics(self) -> SimpleNamespace:
        return SimpleNamespace(
            width=3, height=2, fx=2.0, fy=2.0, ppx=self.ppx, ppy=0.5, coeffs=[0.0] * 5
        )


def fake_pyrealsense2(pipeline: RsPipeline) -> SimpleNamespace:
    """The part of pyrealsense2's API RealSenseCamera uses, over ``pipeline``, one device."""
    config = SimpleNamespace(enable_device=lambda s: None, enable_stream=lambda *a: None)
    return SimpleNamespace(
        pipeline=lambda: pipeline,
        config=lambda: config,
        context=lambda: SimpleNamespace(query_devices=lambda: [RsProfile()]),
        stream=SimpleNamespace(depth="depth", infrared="infrared"),
        format=SimpleNamespace(z16="z16", y8="y8"),
        timestamp_domain=SimpleNamespace(global_time="global_time", system_time="system_time"),
        camera_info=SimpleNamespace(
            name="name", serial_number="serial", firmware_version="fw", usb_type_descriptor="usb"
        ),
    )


def live_realsense(
    monkeypatch: pytest.MonkeyPatch, pipeline: RsPipeline, **kw: object
) -> RealSenseCamera:
    monkeypatch.setattr(realsense_mod, "import_realsense", lambda: fake_pyrealsense2(pipeline))
    return RealSenseCamera(**kw)  # type: ignore[arg-type]


def numbers_until_lost(cam: RealSenseCamera) -> list[int]:
    got = []
    with pytest.raises(DeviceLostError, match=r"^realsense: no new frame for 0\.1 s"):
        for frame in cam:
            got.append(frame.index)
    return got


def test_realsense_failure_after_start_stops_the_pipeline(monkeypatch: pytest.MonkeyPatch) -> None:
    pipeline = RsPipeline([], broken_sensor=True)
    with pytest.raises(InputError) as info:
        live_realsense(monkeypatch, pipeline)
    assert str(info.value) == (
        "realsense: cannot read the stream's profile (failed to query the depth sensor)"
    )
    assert len(pipeline.stops) == 1


def test_bad_device_intrinsics_stop_the_camera(monkeypatch: pytest.MonkeyPatch) -> None:
    from thermodepth.sim.rig import default_calibration

    pipeline = RsPipeline([], ppx=10.0)  # principal point outside the 3 px wide image
    monkeypatch.setattr(realsense_mod, "import_realsense", lambda: fake_pyrealsense2(pipeline))
    with pytest.raises(InputError, match=r"^realsense \(device depth intrinsics\): depth"):
        open_source("realsense", default_calibration())
    assert len(pipeline.stops) == 1


def test_realsense_skips_repeats_and_takes_a_restarted_stream(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    script = [RsFrameset(n) for n in (10, 10, 11, 12, 3, 4, 5, 2)]
    warned: list[str] = []
    cam = live_realsense(monkeypatch, RsPipeline(script), timeout_s=0.1, warn=warned.append)
    assert numbers_until_lost(cam) == [10, 11, 12, 3, 4, 5, 2]
    assert warned == [
        "realsense: frame number went back from 12 to 3: the stream restarted (as after a USB "
        "reconnect); going on (counted, warned once)"
    ]
    assert cam.counters() == {"depth_restarts": 2}


def test_realsense_repeating_one_frame_counts_as_lost(monkeypatch: pytest.MonkeyPatch) -> None:
    cam = live_realsense(
        monkeypatch, RsPipeline([RsFrameset(7)], then=RsFrameset(7)), timeout_s=0.1
    )
    assert numbers_until_lost(cam) == [7]


def test_realsense_frameset_without_ir_is_skipped_and_counted(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    script = [RsFrameset(1), RsFrameset(2, ir=False), RsFrameset(3), RsFrameset(3)]
    cam = live_realsense(monkeypatch, RsPipeline(script), timeout_s=0.1, with_ir=True)
    frames = []
    with pytest.raises(DeviceLostError):
        frames.extend(cam)
    assert [f.index for f in frames] == [1, 3]
    assert all(f.ir is not None for f in frames)
    assert cam.counters() == {"depth_restarts": 0, "depth_missing_ir": 1}


def test_realsense_close_from_another_thread_waits_for_the_read(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    pipeline = RsPipeline([], then=None, wait_s=0.05)
    cam = live_realsense(monkeypatch, pipeline, timeout_s=5.0)
    reader = threading.Thread(target=lambda: list(cam), name="reader")
    reader.start()
    wait_for(lambda: pipeline.waiting, every_s=0.001)  # inside a wait
    cam.close()
    reader.join(PATIENCE_S)
    assert not reader.is_alive()
    assert pipeline.stops == [reader]  # stopped once, by the reading thread ...
    assert not pipeline.stopped_during_wait  # ... after its wait returned
