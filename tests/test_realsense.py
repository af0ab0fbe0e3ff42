"""RealSense files without hardware: a software_device fed with simulated frames is recorded
by pyrealsense2's own recorder, then played back through our source and compared bit for bit.
"""

from __future__ import annotations

import re
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from thermodepth.errors import InputError
from thermodepth.frames import DepthFrame
from thermodepth.io.recording import Recording
from thermodepth.session import record_session
from thermodepth.sim import Rig, camera_pose, plate_scene
from thermodepth.sim.rig import default_calibration
from thermodepth.sources import open_source

try:  # pyrealsense2 loads the system library libusb-1.0 on import: ImportError without it
    import pyrealsense2 as rs
except ImportError as exc:
    pytest.skip(
        f"pyrealsense2 cannot be imported ({exc}); it needs pip install 'thermodepth[realsense]' "
        "and the system library libusb-1.0-0 (Debian: apt-get install libusb-1.0-0)",
        allow_module_level=True,
    )
from thermodepth.sources.realsense import RealSenseCamera

DEPTH_UNIT_M = 0.0001  # not the D435's 1 mm, so that reading it back is a real check


def _intrinsics(w: int, h: int) -> object:
    cal = default_calibration().depth
    intr = rs.intrinsics()
    intr.width, intr.height = w, h
    intr.fx, intr.fy, intr.ppx, intr.ppy = cal.fx, cal.fy * 1.001, cal.cx - 1.25, cal.cy + 0.75
    intr.model = rs.distortion.brown_conrady
    intr.coeffs = [0.0, 0.0, 0.0, 0.0, 0.0]
    return intr


def _video_stream(kind: object, index: int, fmt: object, bpp: int, w: int, h: int) -> object:
    vs = rs.video_stream()
    vs.type, vs.index, vs.uid = kind, index, index
    vs.width, vs.height, vs.fps, vs.bpp, vs.fmt = w, h, 30, bpp, fmt
    vs.intrinsics = _intrinsics(w, h)
    return vs


def write_realsense_file(
    path: Path,
    frames: list[DepthFrame],
    *,
    depth: bool = True,
    ir: bool = False,
    size: tuple[int, int] = (1280, 720),
) -> Path:
    """Record ``frames`` through a software_device and pyrealsense2's recorder. Returns the
    file written: pyrealsense2 >= 2.57 writes rosbag2 ``.db3`` (and refuses ``.bag``), older
    versions ROS1 ``.bag``."""
    w, h = size
    dev = rs.software_device()
    sensor = dev.add_sensor("Stereo Module")
    dprof = iprof = None
    if depth:
        dprof = sensor.add_video_stream(
            _video_stream(rs.stream.depth, 0, rs.format.z16, 2, w, h), True
        )
        sensor.add_read_only_option(rs.option.depth_units, DEPTH_UNIT_M)
    if ir:
        iprof = sensor.add_video_stream(_video_stream(rs.stream.infrared, 1, rs.format.y8, 1, w, h))
    dev.register_info(rs.camera_info.name, "simulated D435")
    dev.register_info(rs.camera_info.serial_number, "000000000001")
    try:
        recorder = rs.recorder(str(path.with_suffix(".db3")), dev)
        path = path.with_suffix(".db3")
    except RuntimeError:
        recorder = rs.recorder(str(path.with_suffix(".bag")), dev)
        path = path.with_suffix(".bag")
    rsensor = recorder.query_sensors()[0]
    rsensor.open(rsensor.get_stream_profiles())
    arrived: list[int] = []
    rsensor.start(lambda f: arrived.append(1))

    def push(pixels: np.ndarray, bpp: int, prof: object, f: DepthFrame) -> None:
        sf = rs.software_video_frame()
        sf.pixels = np.ascontiguousarray(pixels)
        sf.bpp, sf.stride = bpp, bpp * w
        sf.timestamp = f.time_s * 1000.0
        sf.domain = rs.timestamp_domain.global_time
        sf.frame_number = f.index
        sf.profile = prof.as_video_stream_profile()  # type: ignore[attr-defined]
        if bpp == 2:
            sf.depth_units = DEPTH_UNIT_M
        sensor.on_video_frame(sf)

    for f in frames:
        if depth:
            push(f.depth, 2, dprof, f)
        if ir:
            push(f.ir if f.ir is not None else np.zeros((h, w), np.uint8), 1, iprof, f)
    expected = len(frames) * (int(depth) + int(ir))
    for _ in range(200):  # the recorder writes from its callback thread
        if len(arrived) >= expected:
            break
        time.sleep(0.01)
    rsensor.stop()
    rsensor.close()
    del rsensor, recorder  # the file is finished when the recorder is destroyed
    return path


@pytest.fixture(scope="module")
def sim_depth_frames() -> list[DepthFrame]:
    rig = Rig(plate_scene(chip_temp_c=70.0), camera_pose(1.2), with_ir=True)
    out = []
    for k, p in enumerate(rig.frames(4)):
        out.append(DepthFrame(p.depth, 1_700_000_000.0 + p.depth_time_s, 100 + k, p.ir))
    return out


@pytest.fixture(scope="module")
def depth_ir_file(tmp_path_factory: pytest.TempPathFactory, sim_depth_frames) -> Path:  # type: ignore[no-untyped-def]
    return write_realsense_file(
        tmp_path_factory.mktemp("rs") / "depth_ir", sim_depth_frames, ir=True
    )


def test_file_round_trip_bit_for_bit(depth_ir_file: Path, sim_depth_frames) -> None:  # type: ignore[no-untyped-def]
    cam = RealSenseCamera(path=depth_ir_file, with_ir=True)
    try:
        got = list(cam)
    finally:
        cam.close()
    assert len(got) == len(sim_depth_frames)
    for want, have in zip(sim_depth_frames, got, strict=True):
        assert np.array_equal(want.depth, have.depth) and have.depth.dtype == np.uint16
        assert have.ir is not None and np.array_equal(want.ir, have.ir)
        assert have.index == want.index
        assert have.time_s == pytest.approx(want.time_s, abs=1e-6)
    assert cam.depth_scale_m == pytest.approx(DEPTH_UNIT_M, rel=1e-6)
    cal = default_calibration().depth
    assert cam.intrinsics.fx == pytest.approx(cal.fx, rel=1e-6)
    assert cam.intrinsics.fy == pytest.approx(cal.fy * 1.001, rel=1e-6)
    assert cam.intrinsics.cx == pytest.approx(cal.cx - 1.25, abs=1e-4)
    assert cam.intrinsics.cy == pytest.approx(cal.cy + 0.75, abs=1e-4)
    assert cam.live is False


def test_file_source_puts_device_depth_into_the_calibration(depth_ir_file: Path) -> None:
    user = default_calibration()
    src = open_source(f"realsense:{depth_ir_file}", user)
    try:
        assert src.streams == {"depth"}
        assert src.calibration is not None
        assert src.calibration.depth_scale_m == pytest.approx(DEPTH_UNIT_M, rel=1e-6)
        assert src.calibration.depth.cx == pytest.approx(user.depth.cx - 1.25, abs=1e-4)
        assert src.calibration.thermal == user.thermal  # from the user's file
        np.testing.assert_array_equal(
            src.calibration.thermal_from_depth.matrix, user.thermal_from_depth.matrix
        )
        with pytest.raises(InputError, match="gives depth only; FramePairs need"):
            next(iter(src))
    finally:
        src.close()


def test_record_a_realsense_file_then_replay(
    tmp_path: Path, depth_ir_file: Path, sim_depth_frames
) -> None:  # type: ignore[no-untyped-def]
    src = open_source(f"realsense:{depth_ir_file}", default_calibration())
    result = record_session(src, tmp_path / "rs.zarr")
    assert result.stopped == "end" and result.counted == len(sim_depth_frames)
    rec = Recording(tmp_path / "rs.zarr")
    assert (rec.n_depth, rec.n_thermal, rec.n_pairs) == (len(sim_depth_frames), 0, 0)
    assert np.array_equal(rec.depth_frame(2).depth, sim_depth_frames[2].depth)
    assert rec.calibration is not None
    assert rec.calibration.depth_scale_m == pytest.approx(DEPTH_UNIT_M, rel=1e-6)


def test_device_depth_is_recorded_without_a_calibration(
    tmp_path: Path, depth_ir_file: Path
) -> None:
    result = record_session(open_source(f"realsense:{depth_ir_file}"), tmp_path / "nc.zarr")
    assert result.counters == {"depth_restarts": 0}
    rec = Recording(tmp_path / "nc.zarr")
    assert rec.calibration is None  # no --calibration: nothing to merge with ...
    device = rec.device_depth  # ... but the device's depth intrinsics and unit are kept
    assert device is not None
    cal = default_calibration().depth
    assert (device["width"], device["height"]) == (1280, 720)
    assert device["cx"] == pytest.approx(cal.cx - 1.25, abs=1e-4)
    assert device["fy"] == pytest.approx(cal.fy * 1.001, rel=1e-6)
    assert device["depth_scale_m"] == pytest.approx(DEPTH_UNIT_M, rel=1e-6)
    assert rec.attrs["source_counters"] == {"depth_restarts": 0}


def test_a_plus_in_the_file_name_is_part_of_the_path(
    tmp_path: Path, depth_ir_file: Path, sim_depth_frames
) -> None:  # type: ignore[no-untyped-def]
    path = tmp_path / f"take+lepton{depth_ir_file.suffix}"
    shutil.copy(depth_ir_file, path)
    src = open_source(f"realsense:{path}")
    try:
        assert src.name == f"realsense:{path}"
        assert len(list(src.events())) == len(sim_depth_frames)
    finally:
        src.close()


def test_file_without_depth_is_refused(tmp_path: Path, sim_depth_frames) -> None:  # type: ignore[no-untyped-def]
    path = write_realsense_file(tmp_path / "ir_only", sim_depth_frames[:2], depth=False, ir=True)
    with pytest.raises(
        InputError,
        match=re.escape(
            f"{path}: no depth stream in this recording (found Infrared 1 1280x720 Y8 at 30 fps)"
        ),
    ):
        RealSenseCamera(path=path)


def test_a_file_of_any_depth_mode_plays_in_its_own(tmp_path: Path) -> None:
    # 848x480, Intel's recommended mode, at 0.1 mm units (as a D405 counts): the mode and the
    # unit are the file's, never assumed
    frames = [
        DepthFrame(np.full((480, 848), 7000 + i, np.uint16), 1.0 + i / 30, i) for i in range(3)
    ]
    path = write_realsense_file(tmp_path / "d405", frames, size=(848, 480))
    cam = RealSenseCamera(path=path)
    try:
        got = list(cam)
    finally:
        cam.close()
    assert cam.mode == (848, 480, 30) and cam.settings["depth"] == "848x480 Z16 at 30 fps"
    assert cam.depth_scale_m == pytest.approx(DEPTH_UNIT_M)
    assert (cam.device_depth["width"], cam.device_depth["height"]) == (848, 480)
    assert [int(f.depth[0, 0]) for f in got] == [7000, 7001, 7002]
    # a mode asked for that the file does not hold is refused, naming both
    with pytest.raises(
        InputError,
        match=re.escape(f"{path}: expected depth 1280x720 Z16, found Depth 848x480 Z16 at 30 fps"),
    ):
        RealSenseCamera(path=path, mode=(1280, 720, 30))


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("realsense:{tmp}/missing.bag", "{tmp}/missing.bag: no such file"),
        ("realsense:{tmp}/notes.txt", "realsense:{tmp}/notes.txt: expected a serial number"),
    ],
)
def test_bad_file_specs(tmp_path: Path, spec: str, message: str) -> None:
    with pytest.raises(InputError, match=re.escape(message.format(tmp=tmp_path))):
        open_source(spec.format(tmp=tmp_path))


def test_no_realsense_attached_is_one_clear_line() -> None:
    if len(rs.context().query_devices()):
        pytest.skip("a RealSense device is attached")
    with pytest.raises(InputError, match=r"^no RealSense device found \(is it plugged in\?\)$"):
        open_source("realsense")


@pytest.mark.hardware
def test_live_realsense_streams_depth() -> None:
    if not len(rs.context().query_devices()):
        pytest.skip("no RealSense device attached")
    cam = RealSenseCamera()
    try:
        frame = next(iter(cam))
    finally:
        cam.close()
    assert frame.depth.shape == (720, 1280) and frame.depth.dtype == np.uint16
    assert 0.0001 <= cam.depth_scale_m <= 0.01
