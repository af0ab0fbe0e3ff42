"""A rig's data from ROS bags (``rosbag:PATH``): bags written from the simulator in every
format (ROS 1, rosbag2 with db3 and mcap storage, standalone MCAP) replay into the same pairs,
bit for bit, as the simulator gave; the calibration from camera_info and /tf_static; topics
named as realsense-ros names them found by themselves; a wrong encoding, a missing
camera_info, a size that disagrees: one line."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("rosbags", reason="ROS bags need the ros extra (rosbags)")

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


def test_an_export_read_by_foxglove_s_reader_and_by_rosbags(tmp_path: Path) -> None:
    pytest.importorskip("mcap_ros2", reason="the second reader: mcap-ros2-support (dev extra)")
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    from thermodepth.app.run import RunOptions, run
    from thermodepth.io.pointcloud import read_ply, write_ply
    from thermodepth.sinks import CallbackSink
    from thermodepth.sinks.bag import TOPICS as FUSED
    from thermodepth.sinks.bag import BagSink

    settings = tmp_path / "s.yaml"
    settings.write_text("hotspots: {threshold_c: 50}\nalarms:\n  - {name: hot, above_c: 60}\n")
    fused: list[Any] = []
    pairs: list[Any] = []
    out = tmp_path / "run.mcap"
    result = run(
        RunOptions("sim", settings, frames=N),
        [BagSink(out, cloud_points=10**7), CallbackSink(fused.append)],
    )
    assert result.frames == N
    counts: dict[str, int] = {}
    clouds, infos = [], {}
    with out.open("rb") as f:
        for _, channel, _, msg in make_reader(
            f, decoder_factories=[DecoderFactory()]
        ).iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == FUSED["cloud"]:
                clouds.append(msg)
            if channel.topic.endswith("camera_info"):
                infos[channel.topic] = msg
    per_frame = [TOPICS[k] for k in ("depth", "depth_info", "thermal", "thermal_info", "vox")]
    per_frame += [FUSED[k] for k in ("temperature", "cloud", "markers", "measurements")]
    assert counts == {"/tf_static": 1, **{t: N for t in per_frame}, FUSED["alarms"]: 1}
    with AnyReader([out]) as reader:
        assert {c.topic: c.msgcount for c in reader.connections} == counts
    # the layout in the docs names these topics, and colours the cloud by one of its fields
    # with the settings Foxglove's 3D panel knows (colormap: turbo or rainbow, a min and max)
    layout = json.loads((Path(__file__).parents[1] / "examples/foxglove-layout.json").read_text())
    panels = layout["configById"]
    image, raw = panels["Image!thermodepth"], panels["RawMessages!thermodepth"]
    named = {
        *panels["3D!thermodepth"]["topics"],
        image["imageMode"]["imageTopic"],
        raw["topicPath"],
    }
    assert named <= set(counts)
    cloud_look = panels["3D!thermodepth"]["topics"][FUSED["cloud"]]
    assert cloud_look["colorMode"] == "colormap" and cloud_look["colorMap"] in ("turbo", "rainbow")
    assert (
        cloud_look["colorField"] == "temperature"
        and cloud_look["minValue"] < cloud_look["maxValue"]
    )
    assert panels["3D!thermodepth"]["followTf"] == "thermodepth_depth_optical_frame"
    cal = fused[0].calibration
    k = infos[TOPICS["thermal_info"]].k
    assert (k[0], k[2], k[4], k[5]) == (
        cal.thermal.fx,
        cal.thermal.cx,
        cal.thermal.fy,
        cal.thermal.cy,
    )
    assert list(infos[TOPICS["depth_info"]].d) == list(cal.depth.distortion)
    for frame, cloud in zip(fused, clouds, strict=True):
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
            wanted = {FUSED["cloud"], FUSED["markers"], TOPICS["thermal"]}
            while not wanted <= set(channels):  # each advertised when it first has a message
                msg = json.loads(await asyncio.wait_for(ws.recv(), 10))
                if msg["op"] == "advertise":
                    channels.update({c["topic"]: c for c in msg["channels"]})
            cloud = channels[FUSED["cloud"]]
            sub = {"op": "subscribe", "subscriptions": [{"id": 3, "channelId": cloud["id"]}]}
            await ws.send(json.dumps(sub))
            while True:
                data = await asyncio.wait_for(ws.recv(), 10)
                if isinstance(data, bytes) and data[0] == 1:  # a message's data
                    return channels, data

    try:
        assert fused.wait(60)
        channels, data = asyncio.run(listen())
    finally:
        done.set()
        runner.join(60)
    assert TOPICS["thermal"] in channels and FUSED["markers"] in channels
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


@pytest.mark.parametrize("fmt", ["rosbag2", "ros1"])
def test_an_export_as_a_rosbag2_or_ros1_bag(fmt: str, tmp_path: Path) -> None:
    """The writer thread holds the db3 bag's SQLite; a ROS 1 bag takes the same messages."""
    from rosbags.highlevel import AnyReader

    from thermodepth.app.run import RunOptions, run
    from thermodepth.sinks.bag import TOPICS as FUSED
    from thermodepth.sinks.bag import BagSink

    out = tmp_path / ("bag" if fmt == "rosbag2" else "run.bag")
    run(RunOptions("sim", None, frames=3), [BagSink(out, fmt)])
    with AnyReader([out]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts["/tf_static"] == 1 and counts[FUSED["cloud"]] == counts[TOPICS["depth"]] == 3
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
