"""A rig's data from a ROS bag (``rosbag:PATH[,depth=TOPIC,thermal=TOPIC,ir=TOPIC,vox=TOPIC]``):
ROS 1 ``.bag``, a rosbag2 folder (``.db3`` or ``.mcap`` storage) or a standalone ``.mcap``,
read with rosbags (:mod:`thermodepth.io.ros`).

Topics are found by themselves where they are unambiguous: the depth stream is the one image
topic with the word ``depth`` in its name (realsense-ros: ``/camera/camera/depth/image_rect_raw``;
``aligned_depth_to_*`` set aside when there are others); the thermal stream the one other
image topic of 16-bit or float pixels, not a depth one (its first message says; of several,
the one with ``thermal`` in its name); each with its ``camera_info`` beside it
(``.../depth/camera_info``). Or they are named. ``vox`` names a topic of the thermal
camera's sensor (VOx / FPA) temperature in C (``sensor_msgs/Temperature`` or
``std_msgs/Float32``/``Float64``): each thermal frame takes the latest value. With the
infrared image asked for (``capture-board``, ``record --ir``), ``ir`` names its topic
(mono8, the depth camera's own: realsense-ros's ``.../infra1/image_rect_raw``, found by
itself as the one ``infra`` topic, ``infra1`` first); each depth frame takes the infrared
image of its stamp.

Depth ``16UC1`` is in the calibration's depth unit (mm without one), ``32FC1`` in metres
(held as mm); thermal ``mono16``/``16UC1`` is of the kind the calibration's
``thermal.output`` states (raw counts without one), ``32FC1`` kelvin (held as the folder
source holds float kelvin). Intrinsics come from camera_info, else the calibration;
``thermal_from_depth`` from ``/tf_static`` when it connects the two images' frames, else the
calibration; which was used is told in one line. Frames are paired by their header stamps
by the rule of live cameras. A missing topic, an unknown encoding, an image whose size
disagrees with its camera_info: one line naming the topic and the message's index.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..calibration import Calibration
from ..camera import Intrinsics, RigidTransform
from ..errors import FieldError, InputError
from ..frames import DepthFrame, StreamEvent, ThermalFrame
from ..io.folder import kelvin_values, telemetry_of
from ..io.ros import (
    CAMERA_INFO,
    DEPTH_ENCODINGS,
    IMAGE,
    INSTALL,
    TF,
    THERMAL_ENCODINGS,
    image_array,
    intrinsics_of,
    stamp_ns,
    stamp_s,
    stamped_transforms,
    tf_trajectory,
    transform_between,
    typestore,
)
from ..radiometry import RAW_COUNTS
from ..trajectory import Trajectory
from .base import Source
from .pairing import DEFAULT_MAX_SKEW_S, StreamPairer

KEYS = ("depth", "thermal", "ir", "vox")
IR_ENCODINGS = {"mono8": "u1", "8UC1": "u1"}
IR_WAIT_NS = 100_000_000  # a depth frame waits so long (bag time) for its infrared image
DEPTH_WORD = re.compile(r"(^|[/_])depth")  # .../depth/..., aligned_depth_to_color; not thermodepth
DEPTH_UNIT_M = 0.001  # 16UC1 depth without a calibration: millimetres (REP 118)


def parse_spec(arg: str) -> tuple[str, dict[str, str]]:
    """The path and the ``KEY=TOPIC`` options of a ``rosbag:`` spec's argument; FieldError
    (``source``) for a key it does not know."""
    path, *items = arg.split(",")
    options = {}
    for item in items:
        key, eq, topic = item.strip().partition("=")
        if not eq or key not in KEYS or not topic:
            raise FieldError(
                "source", f"rosbag:{arg}: expected PATH[,KEY=TOPIC] with KEY one of "
                f"{', '.join(KEYS)}"
            )  # fmt: skip
        options[key] = topic
    if not path:
        raise FieldError("source", "rosbag:PATH needs a path")
    return path, options


class RosbagSource(Source):
    """The pairs of a ROS bag (module docstring). ``calibration``: the user's, for what the
    bag does not tell; ``warn``: where the line saying what was used goes."""

    def __init__(
        self,
        arg: str,
        calibration: Calibration | None = None,
        warn: Callable[[str], None] | None = None,
        max_skew_s: float = DEFAULT_MAX_SKEW_S,
        with_ir: bool = False,
    ) -> None:
        self.with_ir = with_ir
        try:
            from rosbags.highlevel import AnyReader, AnyReaderError
        except ImportError:
            raise InputError(INSTALL) from None
        path, self.options = parse_spec(arg)
        self.path = Path(path)
        self.name = f"rosbag:{path}"
        self.files = (self.path,)
        if not self.path.exists():
            raise InputError(f"{self.path}: no such bag")
        try:
            self.reader = AnyReader([self.path], default_typestore=typestore())
            self.reader.open()
        except AnyReaderError as exc:
            raise InputError(f"{self.path}: not a ROS bag ({exc})") from None
        try:
            self._find_topics()
            self.calibration, self.told = self._calibration(calibration)
        except BaseException:
            self.reader.close()
            raise
        (warn or (lambda line: None))(f"{self.name}: {self.told}")
        self.pairer = StreamPairer(max_skew_s)
        self.pairing = self.pairer.stats

    # -- what the bag holds ------------------------------------------------------------------

    def _connections(self, topic: str) -> list[Any]:
        return [c for c in self.reader.connections if c.topic == topic]

    def _first(self, topic: str) -> Any:
        """The first message on ``topic`` (None: none; rosbags reads every topic when given
        no connection, so none is asked for then)."""
        conns = self._connections(topic)
        for conn, _, raw in self.reader.messages(connections=conns) if conns else ():
            return self.reader.deserialize(raw, conn.msgtype)
        return None

    def _find_topics(self) -> None:
        images = sorted({c.topic for c in self.reader.connections if c.msgtype == IMAGE})
        listed = ", ".join(images) or "none"
        for key in KEYS:
            topic = self.options.get(key)
            if topic is not None and not self._connections(topic):
                raise InputError(f"{self.name}: no topic {topic} ({key}=); image topics: {listed}")
        depth = self.options.get("depth")
        if depth is None:
            named = [t for t in images if DEPTH_WORD.search(t)]
            if len(named) > 1:
                named = [t for t in named if "aligned" not in t] or named
            if len(named) != 1:
                raise InputError(
                    f"{self.name}: {'no' if not named else 'more than one'} depth image topic "
                    f"(image topics: {listed}); name it: rosbag:PATH,depth=TOPIC"
                )
            depth = named[0]
        thermal = self.options.get("thermal")
        if thermal is None:
            wide = [t for t in images if t != depth and not DEPTH_WORD.search(t)
                    and getattr(self._first(t), "encoding", None) in THERMAL_ENCODINGS]  # fmt: skip
            if len(wide) > 1:  # ours: the temperature on the depth grid beside the raw stream
                wide = [t for t in wide if "thermal" in t.lower()] or wide
            if len(wide) != 1:
                raise InputError(
                    f"{self.name}: {'no' if not wide else 'more than one'} thermal image topic "
                    f"of 16-bit or float pixels (image topics: {listed}); name it: "
                    "rosbag:PATH,thermal=TOPIC"
                )
            thermal = wide[0]
        self.depth_topic, self.thermal_topic = depth, thermal
        self.vox_topic = self.options.get("vox")
        self.ir_topic = self.options.get("ir")
        if self.with_ir and self.ir_topic is None:
            infra = sorted((t for t in images if "infra" in t), key=lambda t: "infra1" not in t)
            if not infra:
                raise InputError(
                    f"{self.name}: no infrared image topic (image topics: {listed}); name it: "
                    "rosbag:PATH,ir=TOPIC"
                )
            self.ir_topic = infra[0]

    def _info(self, image_topic: str) -> Any:
        """The CameraInfo beside an image topic (None: none)."""
        topic = f"{image_topic.rsplit('/', 1)[0]}/camera_info"
        if any(c.msgtype == CAMERA_INFO for c in self._connections(topic)):
            return self._first(topic)
        return None

    def _calibration(self, given: Calibration | None) -> tuple[Calibration, str]:
        """The calibration from the bag where it tells, the user's for the rest; and one
        line saying which was used."""
        said = []
        first = {t: self._first(t) for t in (self.depth_topic, self.thermal_topic)}
        cams: dict[str, Intrinsics] = {}
        for what, topic in (("depth", self.depth_topic), ("thermal", self.thermal_topic)):
            info = self._info(topic)
            if info is not None:
                cams[what] = intrinsics_of(info, f"{self.name}: {topic}'s camera_info")
                said.append(f"{what} intrinsics from its camera_info")
            elif given is not None:
                cams[what] = getattr(given, what)
                said.append(f"{what} intrinsics from the calibration")
            else:
                raise InputError(
                    f"{self.name}: no camera_info beside {topic} and no calibration "
                    "(--calibration) to give its intrinsics"
                )
        depth_frame = first[self.depth_topic].header.frame_id.lstrip("/")
        thermal_frame = first[self.thermal_topic].header.frame_id.lstrip("/")
        between = transform_between(self._transforms("/tf_static"), thermal_frame, depth_frame)
        if between is not None:
            extrinsics = RigidTransform(between.rotation, between.translation_m, "thermal", "depth")
            said.append(f"thermal_from_depth from /tf_static ({depth_frame} -> {thermal_frame})")
        elif given is not None:
            extrinsics = given.thermal_from_depth
            said.append("thermal_from_depth from the calibration")
        else:
            raise InputError(
                f"{self.name}: /tf_static does not connect {depth_frame} and {thermal_frame}, "
                "and no calibration (--calibration) gives thermal_from_depth"
            )
        depth_float = first[self.depth_topic].encoding == "32FC1"
        scale = DEPTH_UNIT_M if depth_float or given is None else given.depth_scale_m
        output = given.thermal_output if given is not None else RAW_COUNTS
        calibration = Calibration(cams["depth"], cams["thermal"], scale, extrinsics, output)
        topics = f"depth {self.depth_topic}, thermal {self.thermal_topic}"
        return calibration, f"{topics}; {'; '.join(said)}"

    def _stamped(self, topic: str) -> list[tuple[float, RigidTransform]]:
        """Every transform on a TF topic, with its stamp."""
        conns = [c for c in self._connections(topic) if c.msgtype == TF]
        found = self.reader.messages(connections=conns) if conns else ()
        return stamped_transforms(self.reader.deserialize(raw, c.msgtype) for c, _, raw in found)

    def _transforms(self, topic: str) -> list[RigidTransform]:
        return [t for _, t in self._stamped(topic)]

    def trajectory(self) -> tuple[Trajectory, str] | None:
        """The depth camera's poses over time from ``/tf`` (with ``/tf_static``), in the root
        frame of the tree, and one line saying so; None when ``/tf`` does not move it."""
        frame = self._first(self.depth_topic).header.frame_id.lstrip("/")
        found = tf_trajectory(self._transforms("/tf_static"), self._stamped("/tf"), frame)
        if found is None:
            return None
        trajectory, root = found
        return trajectory, f"/tf ({root} -> {frame}, {len(trajectory)} poses)"

    # -- the frames ---------------------------------------------------------------------------

    def settings(self) -> dict[str, Any]:
        topics = {"depth": self.depth_topic, "thermal": self.thermal_topic,
                  "ir": self.ir_topic, "vox": self.vox_topic}  # fmt: skip
        return {"source": self.name, "topics": topics, "calibration": self.told}

    def events(self) -> Iterator[StreamEvent]:
        cal = self.calibration
        assert cal is not None
        ir_topic = self.ir_topic if self.with_ir else None
        topics = [self.depth_topic, self.thermal_topic, self.vox_topic, ir_topic]
        conns = [c for c in self.reader.connections if c.topic in topics]
        index = {self.depth_topic: 0, self.thermal_topic: 0, ir_topic: 0}
        vox_c = math.nan
        infrared: dict[int, Any] = {}  # stamp (ns) -> image, waiting for its depth frame
        waiting: list[tuple[int, DepthFrame]] = []  # depth frames waiting for their image

        def ready(now_ns: float) -> Iterator[StreamEvent]:
            """The waiting depth frames whose image came, or that waited long enough."""
            while waiting and (waiting[0][0] in infrared or now_ns - waiting[0][0] > IR_WAIT_NS):
                ns, frame = waiting.pop(0)
                frame = DepthFrame(frame.depth, frame.time_s, frame.index, infrared.pop(ns, None))
                for older in [k for k in infrared if k < ns]:
                    del infrared[older]
                yield frame
                yield from self.pairer.add_depth(frame)

        for conn, bag_ns, raw in self.reader.messages(connections=conns):
            msg: Any = self.reader.deserialize(raw, conn.msgtype)
            if conn.topic == self.vox_topic:
                vox_c = float(getattr(msg, "temperature", getattr(msg, "data", math.nan)))
                continue
            i = index[conn.topic]
            index[conn.topic] += 1
            where = f"{self.name}: {conn.topic} message {i}"
            ns = stamp_ns(msg.header.stamp)
            if conn.topic == ir_topic:
                infrared[ns] = self._pixels(msg, where, IR_ENCODINGS, cal.depth)
                yield from ready(bag_ns)
            elif conn.topic == self.depth_topic:
                depth = self._pixels(msg, where, DEPTH_ENCODINGS, cal.depth)
                if depth.dtype != np.uint16:  # metres
                    mm = np.where(np.isfinite(depth) & (depth > 0), depth / DEPTH_UNIT_M, 0.0)
                    depth = np.clip(np.rint(mm), 0, 65535).astype(np.uint16)
                waiting.append((ns, DepthFrame(depth, stamp_s(msg.header.stamp), i)))
                yield from ready(bag_ns if ir_topic is not None else math.inf)
            else:
                values = self._pixels(msg, where, THERMAL_ENCODINGS, cal.thermal)
                kelvin = values.dtype != np.uint16
                telemetry = telemetry_of(i, vox_c, False, kelvin)
                counts = kelvin_values(values) if kelvin else values
                thermal = ThermalFrame(counts, stamp_s(msg.header.stamp), i, telemetry)
                yield thermal
                yield from self.pairer.add_thermal(thermal)
        yield from ready(math.inf)
        yield from self.pairer.flush()

    @staticmethod
    def _pixels(msg: Any, where: str, encodings: dict[str, str], intr: Intrinsics) -> Any:
        image = image_array(msg, where, encodings)
        if image.shape != (intr.height, intr.width):
            raise InputError(
                f"{where}: {image.shape[1]}x{image.shape[0]} but its camera is "
                f"{intr.width}x{intr.height}"
            )
        return image

    def close(self) -> None:
        self.reader.close()
