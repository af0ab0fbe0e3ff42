"""A rig's data from ROS bags (``rosbag:PATH``): bags written from the simulator in every
format (ROS 1, rosbag2 with db3 and mcap storage, standalone MCAP) replay into the same pairs,
bit for bit, as the simulator gave; the calibration from camera_info and /tf_static; topics
named as realsense-ros names them found by themselves; a wrong encoding, a missing
camera_info, a size that disagrees: one line."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pytest

pytest.importorskip("rosbags", reason="ROS bags need the ros extra (rosbags)")

from monitor_helpers import PATIENCE_S
from thermodepth.errors import InputError
from thermodepth.io.ros import (
    CAMERA_INFO,
    FORMATS,
    IMAGE,
    TOPICS,
    BagWriter,
    camera_info_msg,
    image_msg,
    write_rig,
)
from thermodepth.sim import Rig, camera_pose, plate_scene
from thermodepth.sources import open_source

N = 6


@pytest.fixture(scope="module")
def rig() -> tuple[Any, list[Any]]:
    sim = Rig(plate_scene(), camera_pose(1.0), seed=3)
    return sim.calibration, list(sim.frames(N))


def bag_of(path: Path, fmt: str, calibration: Any, pairs: list[Any]) -> Path:
    with BagWriter(path, fmt) as writer:
        for i, pair in enumerate(pairs):
            write_rig(writer, calibration, pair, with_tf=i == 0)
    return path


SUFFIX = {"mcap": ".mcap", "rosbag2": "", "rosbag2-mcap": "", "ros1": ".bag"}


@pytest.mark.parametrize("fmt", FORMATS)
def test_every_format_replays_the_simulators_pairs_bit_for_bit(
    fmt: str, rig: tuple[Any, list[Any]], tmp_path: Path
) -> None:
    calibration, pairs = rig
    path = bag_of(tmp_path / f"rig{SUFFIX[fmt]}", fmt, calibration, pairs)
    told: list[str] = []
    spec = f"rosbag:{path},vox={TOPICS['vox']}"
    with open_source(spec, warn=told.append) as source:
        got = list(source)
        cal = source.calibration
    assert told == [
        f"rosbag:{path}: depth {TOPICS['depth']}, thermal {TOPICS['thermal']}; depth intrinsics "
        "from its camera_info; thermal intrinsics from its camera_info; thermal_from_depth "
        "from /tf_static (thermodepth_depth_optical_frame -> thermodepth_thermal_optical_frame)"
    ]
    assert len(got) == N
    for a, b in zip(pairs, got, strict=True):
        assert np.array_equal(a.depth, b.depth) and a.depth.dtype == b.depth.dtype
        assert np.array_equal(a.thermal, b.thermal) and b.thermal.dtype == np.uint16
        assert abs(a.depth_time_s - b.depth_time_s) < 1e-9
        assert abs(a.thermal_time_s - b.thermal_time_s) < 1e-9
        assert abs(a.telemetry.fpa_temp_c - b.telemetry.fpa_temp_c) < 1e-9
    assert cal.depth == calibration.depth and cal.thermal == calibration.thermal
    assert cal.depth_scale_m == 0.001
    t, u = cal.thermal_from_depth, calibration.thermal_from_depth
    assert np.allclose(t.rotation, u.rotation, atol=1e-12)
    assert np.allclose(t.translation_m, u.translation_m, atol=1e-12)


def test_topics_as_realsense_ros_names_them_and_float_images(
    rig: tuple[Any, list[Any]], tmp_path: Path
) -> None:
    """realsense-ros 4's depth topic beside its infrared (mono8) and aligned depth, a thermal
    driver's 32FC1 kelvin; no /tf_static: thermal_from_depth from the calibration."""
    calibration, pairs = rig
    path = tmp_path / "rs.mcap"
    depth = "/camera/camera/depth/image_rect_raw"
    with BagWriter(path) as w:
        s = w.store
        for pair in pairs:
            t = pair.depth_time_s
            metres = pair.depth.astype(np.float32) * np.float32(calibration.depth_scale_m)
            w.write(depth, IMAGE, image_msg(s, metres, t, "depth_optical"), t)
            info = camera_info_msg(s, calibration.depth, t, "depth_optical")
            w.write("/camera/camera/depth/camera_info", CAMERA_INFO, info, t)
            aligned = image_msg(s, pair.depth, t, "color_optical")
            w.write("/camera/camera/aligned_depth_to_color/image_raw", IMAGE, aligned, t)
            ir = image_msg(s, np.zeros((4, 4), np.uint16), t, "ir", "16UC1")
            ir.encoding, ir.step, ir.data = "mono8", 4, np.zeros(16, np.uint8)
            w.write("/camera/camera/infra1/image_rect_raw", IMAGE, ir, t)
            kelvin = pair.thermal.astype(np.float32) / 64 + 200  # any temperatures
            t2 = pair.thermal_time_s
            w.write("/lepton/image_kelvin", IMAGE, image_msg(s, kelvin, t2, "lepton"), t2)
            info = camera_info_msg(s, calibration.thermal, t2, "lepton")
            w.write("/lepton/camera_info", CAMERA_INFO, info, t2)
    told: list[str] = []
    with open_source(f"rosbag:{path}", calibration, warn=told.append) as source:
        got = list(source)
        assert source.calibration.thermal_from_depth == calibration.thermal_from_depth
    assert told[0].endswith("thermal_from_depth from the calibration")
    assert f"depth {depth}, thermal /lepton/image_kelvin" in told[0]
    assert len(got) == N
    for a, b in zip(pairs, got, strict=True):
        assert np.array_equal(a.depth, b.depth)  # metres back to millimetres
        assert b.telemetry.tlinear and b.telemetry.tlinear_resolution_k == 1 / 64
        assert np.array_equal(b.thermal, a.thermal + 200 * 64)  # kelvin held at 1/64 K


def one_line(spec: str, calibration: Any = None) -> str:
    with pytest.raises(InputError) as info, open_source(spec, calibration) as source:
        list(source)
    assert "\n" not in str(info.value)
    return str(info.value)


def test_bad_bags_are_one_line(rig: tuple[Any, list[Any]], tmp_path: Path) -> None:
    calibration, pairs = rig
    good = bag_of(tmp_path / "good.mcap", "mcap", calibration, pairs[:2])
    assert one_line(f"rosbag:{tmp_path / 'none.bag'}") == f"{tmp_path / 'none.bag'}: no such bag"
    assert one_line(f"rosbag:{good},thermal=/nowhere").startswith(
        f"rosbag:{good}: no topic /nowhere (thermal=); image topics: "
    )
    wrong = tmp_path / "wrong.mcap"
    with BagWriter(wrong) as w:  # an 8-bit "thermal" image and no camera_info
        for pair in pairs[:2]:
            t = pair.depth_time_s
            w.write(TOPICS["depth"], IMAGE, image_msg(w.store, pair.depth, t, "d"), t)
            w.write(TOPICS["thermal"], IMAGE, image_msg(w.store, pair.thermal, t, "t"), t)
    assert one_line(f"rosbag:{wrong}") == (
        f"rosbag:{wrong}: no camera_info beside {TOPICS['depth']} and no calibration "
        "(--calibration) to give its intrinsics"
    )
    small = tmp_path / "small.mcap"
    with BagWriter(small) as w:  # the thermal camera's images smaller than its camera_info
        for pair in pairs[:2]:
            t = pair.thermal_time_s
            w.write(TOPICS["depth"], IMAGE, image_msg(w.store, pair.depth, t, "d"), t)
            w.write(TOPICS["thermal"], IMAGE, image_msg(w.store, pair.thermal[:60], t, "t"), t)
    message = one_line(f"rosbag:{small}", calibration)
    assert message == (
        f"rosbag:{small}: {TOPICS['thermal']} message 0: 160x60 but its camera is 160x120"
    )
    rgb = tmp_path / "rgb.mcap"
    with BagWriter(rgb) as w:
        for pair in pairs[:2]:
            t = pair.thermal_time_s
            w.write(TOPICS["depth"], IMAGE, image_msg(w.store, pair.depth, t, "d"), t)
            msg = image_msg(w.store, pair.thermal, t, "t")
            msg.encoding = "rgb8"
            w.write(TOPICS["thermal"], IMAGE, msg, t)
    assert one_line(f"rosbag:{rgb},thermal={TOPICS['thermal']}", calibration) == (
        f"rosbag:{rgb}: {TOPICS['thermal']} message 0: encoding 'rgb8'; expected one of "
        "16UC1, mono16, 32FC1"
    )


class Export(NamedTuple):
    """A simulated run exported to MCAP: its path, its fused frames, and its messages as
    Foxglove's own reader (mcap with mcap-ros2-support) decodes them, by topic."""

    path: Path
    fused: list[Any]
    messages: dict[str, list[Any]]


@pytest.fixture(scope="module")
def export(tmp_path_factory: pytest.TempPathFactory) -> Export:
    pytest.importorskip("mcap_ros2", reason="the second reader: mcap-ros2-support (dev extra)")
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from thermodepth.app.run import RunOptions, run
    from thermodepth.sinks import CallbackSink
    from thermodepth.sinks.bag import BagSink

    folder = tmp_path_factory.mktemp("export")
    settings = folder / "s.yaml"
    settings.write_text("hotspots: {threshold_c: 50}\nalarms:\n  - {name: hot, above_c: 60}\n")
    fused: list[Any] = []
    out = folder / "run.mcap"
    result = run(
        RunOptions("sim", settings, frames=N),
        [BagSink(out, cloud_points=10**7), CallbackSink(fused.append)],
    )
    assert result.frames == N
    messages: dict[str, list[Any]] = {}
    with out.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages():
            messages.setdefault(channel.topic, []).append(msg)
    return Export(out, fused, messages)


def test_an_export_read_by_foxglove_s_reader_and_by_rosbags(export: Export) -> None:
    from rosbags.highlevel import AnyReader

    from thermodepth.io.pointcloud import read_ply, write_ply
    from thermodepth.sinks.bag import TOPICS as FUSED

    out, fused = export.path, export.fused
    tmp_path = out.parent
    counts = {topic: len(msgs) for topic, msgs in export.messages.items()}
    per_frame = [TOPICS[k] for k in ("depth", "depth_info", "thermal", "thermal_info", "vox")]
    per_frame += [FUSED[k] for k in ("temperature", "temperature_ck", "cloud", "markers")]
    per_frame += [FUSED["measurements"]]
    assert counts == {"/tf_static": 1, **{t: N for t in per_frame}, FUSED["alarms"]: 1}
    with AnyReader([out]) as reader:
        assert {c.topic: c.msgcount for c in reader.connections} == counts
    infos = {t: export.messages[t][0] for t in (TOPICS["thermal_info"], TOPICS["depth_info"])}
    cal = fused[0].calibration
    k = infos[TOPICS["thermal_info"]].k
    assert (k[0], k[2], k[4], k[5]) == (
        cal.thermal.fx,
        cal.thermal.cx,
        cal.thermal.fy,
        cal.thermal.cy,
    )
    assert list(infos[TOPICS["depth_info"]].d) == list(cal.depth.distortion)
    for frame, cloud in zip(fused, export.messages[FUSED["cloud"]], strict=True):
        points, temps = frame.points()
        ply = write_ply(tmp_path / f"f{frame.index}.ply", points, temps, 20.0, 80.0)
        ply_points, ply_temps = read_ply(ply)
        got = np.frombuffer(bytes(cloud.data), np.dtype([(f, "<f4") for f in "xyzt"]))
        assert cloud.width == len(ply_temps) and [f.name for f in cloud.fields] == [
            "x",
            "y",
            "z",
            "temperature",
        ]
        assert np.array_equal(got["t"], ply_temps, equal_nan=True)  # NaN: the shutter closed
        assert np.array_equal(np.stack([got["x"], got["y"], got["z"]], -1), ply_points)
    # and the export replays as a rig: its raw streams found among its own topics
    with open_source(f"rosbag:{out}") as source:
        pairs = list(source)
    assert [p.index for p in pairs] == list(range(N))
    assert all(np.array_equal(p.depth, f.depth) for p, f in zip(pairs, fused, strict=True))


def pixels(msg: Any, dtype: str) -> np.ndarray:
    """An Image's pixels as its rows (``step`` bytes each) hold them, little-endian."""
    rows = np.frombuffer(bytes(msg.data), np.uint8).reshape(msg.height, msg.step)
    return rows[:, : msg.width * np.dtype(dtype).itemsize].copy().view(dtype)


def test_the_temperature_as_a_16uc1_image_of_centikelvin(export: Export) -> None:
    """Foxglove colours a 16UC1 image between a min and a max (a 32FC1 one it shows as
    value x 255: white): the same temperatures in 0.01 K, 0 where there is none."""
    from thermodepth.sinks.bag import TOPICS as FUSED

    floats, ck = export.messages[FUSED["temperature"]], export.messages[FUSED["temperature_ck"]]
    none = some = 0
    for f, c, frame in zip(floats, ck, export.fused, strict=True):
        assert (c.encoding, c.is_bigendian, c.step) == ("16UC1", 0, 2 * c.width)
        assert (c.width, c.height) == (f.width, f.height) == frame.temp_depth_c.shape[::-1]
        stamps = [(m.header.stamp.sec, m.header.stamp.nanosec, m.header.frame_id) for m in (c, f)]
        assert stamps[0] == stamps[1]  # the same stamp, in the depth camera's frame
        assert c.header.frame_id == "thermodepth_depth_optical_frame"
        temp_c = pixels(f, "<f4").astype(np.float64)
        got = pixels(c, "<u2")
        finite = np.isfinite(temp_c)
        assert np.array_equal(got[finite], np.round(100 * (temp_c[finite] + 273.15)))
        assert np.all(np.abs(got[finite] / 100 - 273.15 - temp_c[finite]) <= 0.005 + 1e-9)
        assert np.all(got[~finite] == 0) and np.all(got[finite] > 0)
        none, some = none + int((~finite).sum()), some + int(finite.sum())
    assert none > 0 and some > 0  # both kinds of pixel were there to check


def test_centikelvin_at_its_edges() -> None:
    """0.01 K a step, rounded; NaN 0; beyond 655.35 K held at 65535, below 0 K at 1."""
    from thermodepth.io.ros import CENTIKELVIN_MAX_C, centikelvin_image

    temp_c = np.array([[np.nan, -273.15, -300.0, 0.0, 0.004, 0.006, 36.6],
                       [382.2, 382.21, 1000.0, np.inf, -np.inf, -273.14, 20.0]])  # fmt: skip
    assert centikelvin_image(temp_c).tolist() == [
        [0, 1, 1, 27315, 27315, 27316, 30975],
        [65535, 65535, 65535, 65535, 1, 1, 29315],
    ]
    assert centikelvin_image(temp_c).dtype == np.uint16
    assert abs(CENTIKELVIN_MAX_C - 382.2) < 1e-9


def test_the_foxglove_layout_fits_an_export(export: Export) -> None:
    """examples/foxglove-layout.json, with the keys Foxglove's (and Lichtblick's) 3D and
    Image panels read: every topic it names is in an export; the Image panel colours the
    16UC1 centikelvin image (colormap, min < max, the cloud's range in centikelvin) with
    the depth camera's camera_info; the 3D panel colours the cloud by its temperature and
    its camera, a few metres off, has the cloud in view."""
    from thermodepth.sinks.bag import TOPICS as FUSED

    layout = json.loads((Path(__file__).parents[1] / "examples/foxglove-layout.json").read_text())
    panels = layout["configById"]
    three_d, image = panels["3D!thermodepth"], panels["Image!thermodepth"]["imageMode"]
    named = {*three_d["topics"], image["imageTopic"], image["calibrationTopic"]}
    named.add(panels["RawMessages!thermodepth"]["topicPath"])
    assert named <= set(export.messages)
    cloud_look = three_d["topics"][FUSED["cloud"]]
    assert cloud_look["colorMode"] == "colormap" and cloud_look["colorMap"] in ("turbo", "rainbow")
    assert cloud_look["colorField"] == "temperature"
    assert cloud_look["minValue"] < cloud_look["maxValue"]
    assert three_d["followTf"] == "thermodepth_depth_optical_frame"

    shown = export.messages[image["imageTopic"]][0]
    info = export.messages[image["calibrationTopic"]][0]
    assert shown.encoding == "16UC1"  # the encoding whose colour map and min/max apply
    assert (info.width, info.height, info.header.frame_id) == (
        shown.width,
        shown.height,
        shown.header.frame_id,
    )
    assert image["colorMode"] == "colormap" and image["colorMap"] in ("turbo", "rainbow")
    assert image["minValue"] < image["maxValue"]
    for key in ("minValue", "maxValue"):  # the cloud's range, in centikelvin
        assert image[key] == round(100 * (cloud_look[key] + 273.15))

    # The 3D panel's camera (its CameraStateSettings): an orbit of `distance` about
    # `targetOffset` in the followed frame, Z up, `phi` degrees from +Z, `thetaOffset` about
    # Z; the eye at target + d (sin phi sin theta, -sin phi cos theta, cos phi), theta =
    # -thetaOffset, looking at the target.
    cam = three_d["cameraState"]
    assert cam["perspective"] and 0.5 <= cam["distance"] <= 5.0
    phi, theta = np.radians(cam["phi"]), -np.radians(cam["thetaOffset"])
    target = np.array(cam["targetOffset"], float)
    ray = np.array([np.sin(phi) * np.sin(theta), -np.sin(phi) * np.cos(theta), np.cos(phi)])
    eye = target + cam["distance"] * ray
    points, _ = export.fused[-1].points()
    assert len(points) > 1000
    seen = points - eye
    along = seen @ -ray  # in front of the eye, between the near and the far plane
    assert np.all(along > cam["near"]) and np.all(along < cam["far"])
    off_axis = np.degrees(np.arccos(np.clip(along / np.linalg.norm(seen, axis=1), -1, 1)))
    assert np.percentile(off_axis, 90) < cam["fovy"] / 2  # most of the cloud in the picture
    assert np.linalg.norm(np.median(points, axis=0) - target) < 1.0


def test_a_run_live_in_foxglove_read_as_its_websocket_client_reads_it() -> None:
    """run --foxglove: the server advertises every topic with its ROS 2 schema; a client
    subscribed to the cloud gets CDR that rosbags decodes into x, y, z and temperature."""
    pytest.importorskip("foxglove", reason="the live view needs the foxglove extra")
    websockets = pytest.importorskip("websockets", reason="the test's client (dev extra)")
    import asyncio
    import json
    import struct
    import threading

    from mqtt_broker import free_port
    from thermodepth.app.run import RunOptions, run
    from thermodepth.io.ros import typestore
    from thermodepth.sinks import CallbackSink
    from thermodepth.sinks.bag import TOPICS as FUSED

    fused, done = threading.Event(), threading.Event()

    def slowly(frame: Any) -> None:  # the run goes on, slowly, while the client listens
        fused.set()
        done.wait(0.3)

    url = f"ws://127.0.0.1:{(port := free_port())}"
    options = RunOptions("sim", None, frames=60, foxglove=f"127.0.0.1:{port}")
    runner = threading.Thread(target=run, args=(options, [CallbackSink(slowly)]))
    runner.start()

    async def listen() -> tuple[dict[str, Any], bytes]:
        async with websockets.connect(url, subprotocols=["foxglove.sdk.v1"]) as ws:
            channels: dict[str, Any] = {}
            wanted = {FUSED["cloud"], FUSED["markers"], FUSED["temperature_ck"], TOPICS["thermal"]}
            while not wanted <= set(channels):  # each advertised when it first has a message
                msg = json.loads(await asyncio.wait_for(ws.recv(), PATIENCE_S))
                if msg["op"] == "advertise":
                    channels.update({c["topic"]: c for c in msg["channels"]})
            cloud = channels[FUSED["cloud"]]
            sub = {"op": "subscribe", "subscriptions": [{"id": 3, "channelId": cloud["id"]}]}
            await ws.send(json.dumps(sub))
            while True:
                data = await asyncio.wait_for(ws.recv(), PATIENCE_S)
                if isinstance(data, bytes) and data[0] == 1:  # a message's data
                    return channels, data

    try:
        assert fused.wait(60)
        channels, data = asyncio.run(listen())
    finally:
        done.set()
        runner.join(60)
    assert TOPICS["thermal"] in channels and FUSED["markers"] in channels
    # the temperature as the 16UC1 image Foxglove colours; not the 32FC1 one it shows white
    # (written before the cloud, so it would have been advertised by now)
    assert FUSED["temperature_ck"] in channels and FUSED["temperature"] not in channels
    cloud = channels[FUSED["cloud"]]
    assert (cloud["encoding"], cloud["schemaEncoding"]) == ("cdr", "ros2msg")
    assert cloud["schemaName"] == "sensor_msgs/msg/PointCloud2"
    assert struct.unpack_from("<I", data, 1) == (3,)  # our subscription
    msg = typestore().deserialize_cdr(data[13:], "sensor_msgs/msg/PointCloud2")
    assert [f.name for f in msg.fields] == ["x", "y", "z", "temperature"]
    assert 0 < msg.width <= 50_000


def test_a_bag_recorded_replays_as_the_bag(rig: tuple[Any, list[Any]], tmp_path: Path) -> None:
    """record --source rosbag:PATH: the recording (for batch, view, ...) holds the bag's
    pairs and the calibration the bag told."""
    from thermodepth.app.record import RecordOptions, record

    calibration, pairs = rig
    bag = bag_of(tmp_path / "rig.bag", "ros1", calibration, pairs)
    record(RecordOptions(f"rosbag:{bag}", tmp_path / "take.zarr"))
    with open_source(f"recording:{tmp_path / 'take.zarr'}") as replay:
        got = list(replay)
        assert replay.calibration.thermal == calibration.thermal
    assert [np.array_equal(a.thermal, b.thermal) for a, b in zip(pairs, got, strict=True)] == [
        True
    ] * N


@pytest.mark.parametrize(("fmt", "temperature_image"), [("rosbag2", "32FC1"), ("ros1", "16UC1")])
def test_an_export_as_a_rosbag2_or_ros1_bag(
    fmt: str, temperature_image: str, tmp_path: Path
) -> None:
    """The writer thread holds the db3 bag's SQLite; a ROS 1 bag takes the same messages;
    the temperature on the depth grid as one image only, as asked."""
    from rosbags.highlevel import AnyReader

    from thermodepth.app.run import RunOptions, run
    from thermodepth.sinks.bag import TOPICS as FUSED
    from thermodepth.sinks.bag import BagSink

    out = tmp_path / ("bag" if fmt == "rosbag2" else "run.bag")
    run(RunOptions("sim", None, frames=3), [BagSink(out, fmt, temperature_image=temperature_image)])
    with AnyReader([out]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts["/tf_static"] == 1 and counts[FUSED["cloud"]] == counts[TOPICS["depth"]] == 3
    kept, left = ("temperature", "temperature_ck")[:: 1 if temperature_image == "32FC1" else -1]
    assert counts[FUSED[kept]] == 3 and FUSED[left] not in counts
    with pytest.raises(InputError, match="exists already"):
        run(RunOptions("sim", None, frames=1), [BagSink(out, fmt)])


def test_the_infrared_image_of_each_depth_frame(tmp_path: Path) -> None:
    """capture-board and record --ir from a bag: each depth frame with the infrared image of
    its stamp (realsense-ros's infra1 topic found by itself)."""
    sim = Rig(plate_scene(), camera_pose(1.0), seed=4)
    sim.with_ir = True
    pairs = list(sim.frames(4))
    assert all(p.ir is not None for p in pairs)
    bag = bag_of(tmp_path / "ir.mcap", "mcap", sim.calibration, pairs)
    with open_source(f"rosbag:{bag}", with_ir=True) as source:
        got = list(source)
        assert source.settings()["topics"]["ir"] == TOPICS["ir"]
    assert all(np.array_equal(a.ir, b.ir) for a, b in zip(pairs, got, strict=True))
    with open_source(f"rosbag:{bag}") as source:  # not asked for: none read
        assert all(p.ir is None for p in source)
    assert one_line(f"rosbag:{bag},ir=/camera/infra9").startswith(
        f"rosbag:{bag}: no topic /camera/infra9 (ir=)"
    )


def test_export_says_which_temperature_images_it_knows(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from thermodepth.cli import app

    out = tmp_path / "x.mcap"
    result = CliRunner().invoke(app, ["export", "sim", str(out), "--temperature-image", "8UC1"])
    assert result.exit_code != 0 and not out.exists()
    assert "--temperature-image 8UC1: expected one of both, 32FC1, 16UC1" in result.output
