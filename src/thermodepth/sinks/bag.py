"""A session into a ROS bag for ROS tools and Foxglove (``thermodepth export``; the ``ros``
extra): ROS 2 messages in an MCAP file (or a rosbag2 folder, or a ROS 1 bag,
:data:`~thermodepth.io.ros.FORMATS`).

Topics (``/thermodepth/...``; frames ``thermodepth_depth_optical_frame`` and
``thermodepth_thermal_optical_frame``):

- ``depth/image_rect_raw`` (16UC1, the depth unit) and ``depth/camera_info``;
  ``thermal/image_raw`` (mono16, the camera's values) and ``thermal/camera_info``;
  ``thermal/sensor_temperature`` (sensor_msgs/Temperature, C); ``infra1/image_rect_raw``
  (mono8, where the source gives it); ``/tf_static`` (the depth frame's pose in the
  thermal's): every pair, as :func:`~thermodepth.io.ros.write_rig`;
- per fused frame, at its thermal capture time, the temperature on the depth grid as
  ``temperature_image`` asks (:data:`TEMPERATURE_IMAGES`): ``registered/temperature_c``
  (32FC1, C, NaN without a temperature: for ROS tools; Foxglove shows a float image as
  value x 255, white) and ``registered/temperature_centikelvin`` (16UC1, 0.01 K, 0 without
  one: what Foxglove's Image panel colours between a min and a max); ``cloud``
  (sensor_msgs/PointCloud2: x, y, z in m, depth frame, and a float32 ``temperature`` in C,
  every k-th point so that at most ``cloud_points`` remain); ``markers``
  (visualization_msgs/MarkerArray: each hotspot a sphere of its area with its reading as
  text); ``measurements`` and ``alarms`` (std_msgs/String, JSON as MQTT publishes them).
"""

from __future__ import annotations

import json
import math
import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..calibration import Calibration
from ..errors import InputError
from ..frames import Match, StreamEvent
from ..io.measurements import jsonable
from ..io.ros import (
    FRAMES,
    IMAGE,
    BagWriter,
    MessageOutput,
    centikelvin_image,
    header_msg,
    image_msg,
    write_rig,
)
from ..pipeline import FusedFrame
from .base import BaseSink, RunContext, SessionResult
from .mqtt import alarm_message, measurement_message

PREFIX = "/thermodepth"
TOPICS = {
    "temperature": f"{PREFIX}/registered/temperature_c",
    "temperature_ck": f"{PREFIX}/registered/temperature_centikelvin",
    "cloud": f"{PREFIX}/cloud",
    "markers": f"{PREFIX}/markers",
    "measurements": f"{PREFIX}/measurements",
    "alarms": f"{PREFIX}/alarms",
}
CLOUD = "sensor_msgs/msg/PointCloud2"
MARKERS = "visualization_msgs/msg/MarkerArray"
STRING = "std_msgs/msg/String"
CLOUD_FIELDS = ("x", "y", "z", "temperature")
TEMPERATURE_IMAGES = ("both", "32FC1", "16UC1")
"""Which images of the temperature on the depth grid go: ``32FC1`` (C, ``temperature_c``),
``16UC1`` (centikelvin, ``temperature_centikelvin``) or both."""


def cloud_msg(store: Any, points_m: Any, temp_c: Any, time_s: float, frame_id: str) -> Any:
    """A PointCloud2 of points (N, 3) m and temperatures (N,) C: four float32 a point."""
    t = store.types
    rec = np.empty(len(points_m), np.dtype([(f, "<f4") for f in CLOUD_FIELDS]))
    for i, name in enumerate(("x", "y", "z")):
        rec[name] = points_m[:, i]
    rec["temperature"] = temp_c
    field_type = t["sensor_msgs/msg/PointField"]
    fields = [field_type(name=f, offset=4 * i, datatype=field_type.FLOAT32, count=1)
              for i, f in enumerate(CLOUD_FIELDS)]  # fmt: skip
    return t[CLOUD](
        header=header_msg(store, time_s, frame_id), height=1, width=len(rec), fields=fields,
        is_bigendian=False, point_step=16, row_step=16 * len(rec),
        data=rec.view(np.uint8).reshape(-1), is_dense=False,
    )  # fmt: skip


def _marker(store: Any, **given: Any) -> Any:
    """A Marker of ``given`` fields, the rest empty (ROS 2's Marker has more than ROS 1's)."""
    t = store.types
    marker = t["visualization_msgs/msg/Marker"]
    empty: dict[str, Any] = {
        "ns": "thermodepth", "id": 0, "type": marker.SPHERE, "action": marker.ADD,
        "pose": t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
            orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)),
        "scale": t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
        "color": t["std_msgs/msg/ColorRGBA"](r=0.0, g=0.0, b=0.0, a=0.0),
        "lifetime": t["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
        "frame_locked": False, "points": [], "colors": [], "text": "", "mesh_resource": "",
        "mesh_use_embedded_materials": False, "texture_resource": "", "uv_coordinates": [],
    }  # fmt: skip
    fields = marker.__dataclass_fields__
    if "texture" in fields:
        empty["texture"] = t["sensor_msgs/msg/CompressedImage"](
            header=given["header"], format="", data=np.zeros(0, np.uint8)
        )
        empty["mesh_file"] = t["visualization_msgs/msg/MeshFile"](
            filename="", data=np.zeros(0, np.uint8)
        )
    return marker(**{k: v for k, v in {**empty, **given}.items() if k in fields})


def markers_msg(store: Any, fused: FusedFrame, frame_id: str) -> Any:
    """Each hotspot a sphere of its area (cyan: resolvable; yellow: too small to read true)
    with its reading above it, after a DELETEALL of the frame before's."""
    t = store.types
    kind = t["visualization_msgs/msg/Marker"]
    header = header_msg(store, fused.thermal_time_s, frame_id)
    out = [_marker(store, header=header, action=kind.DELETEALL)]
    for i, hs in enumerate(fused.hotspots):
        x, y, z = (float(c) for c in hs.centroid_m)
        size = max(0.01, math.sqrt(hs.area_m2))
        r, g, b = (0.0, 1.0, 1.0) if hs.resolvable else (1.0, 1.0, 0.0)
        where = t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=x, y=y, z=z),
            orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        )
        above = t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=x, y=y - size, z=z),
            orientation=where.orientation,
        )
        color = t["std_msgs/msg/ColorRGBA"](r=r, g=g, b=b, a=0.8)
        scale = t["geometry_msgs/msg/Vector3"](x=size, y=size, z=size)
        out.append(_marker(store, header=header, id=2 * i, pose=where, color=color, scale=scale))
        out.append(_marker(
            store, header=header, id=2 * i + 1, type=kind.TEXT_VIEW_FACING, pose=above,
            color=color, scale=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.03),
            text=f"{hs.max_c:.1f} C, {hs.distance_m:.2f} m",
        ))  # fmt: skip
    return t[MARKERS](markers=out)


QUEUED = 64  # messages waiting for the writer thread, at most (then fusing waits: none lost)


class QueuedWriter:
    """What :func:`~thermodepth.io.ros.write_rig` writes to: the sink's queue."""

    def __init__(self, sink: BagSink) -> None:
        self.sink = sink

    @property
    def store(self) -> Any:
        assert self.sink.writer is not None
        return self.sink.writer.store

    def write(
        self, topic: str, msgtype: str, msg: Any, time_s: float, latched: bool = False
    ) -> None:
        self.sink._put(topic, msgtype, msg, time_s, latched)


class BagSink(BaseSink):
    """A session as ROS messages (module docstring) into a new bag at ``path`` (``fmt`` and
    ``compression`` as :class:`~thermodepth.io.ros.BagWriter`), or to what ``open_writer()``
    opens (a live server); ``cloud_points``: the most points a cloud keeps; ``max_hz``: a
    live server's, at most so many pairs and fused frames a second (the others are not
    built at all) and ``/tf_static`` each second for the clients that come later (None:
    everything, ``/tf_static`` once); ``temperature_image``: which images of the temperature
    on the depth grid go (:data:`TEMPERATURE_IMAGES`)."""

    def __init__(
        self,
        path: Path | None,
        fmt: str = "mcap",
        compression: str = "none",
        cloud_points: int = 100_000,
        open_writer: Callable[[], MessageOutput] | None = None,
        max_hz: float | None = None,
        temperature_image: str = "both",
    ) -> None:
        if temperature_image not in TEMPERATURE_IMAGES:
            raise ValueError(f"temperature_image {temperature_image!r}")
        self.temperature_image = temperature_image
        self.path = None if path is None else Path(path)
        self.fmt, self.compression, self.cloud_points = fmt, compression, cloud_points
        self.open_writer, self.max_hz = open_writer, max_hz
        self._last = {"pair": -math.inf, "frame": -math.inf, "tf": -math.inf}
        self.writer: MessageOutput | None = None
        self.calibration: Calibration | None = None
        self.pairs = self.frames = 0
        self._queue: queue.Queue[tuple[str, str, Any, float, bool] | None] = queue.Queue(QUEUED)
        self._failed: Exception | None = None
        self._thread: threading.Thread | None = None
        self._queued = QueuedWriter(self)

    def check(self) -> None:
        if self.path is not None and self.path.exists():
            raise InputError(f"{self.path}: exists already; give a new path")

    def open(self, context: RunContext) -> None:
        self.calibration = context.calibration or context.source.calibration
        if self.calibration is None:
            raise InputError("ROS messages need the rig's calibration (--settings)")
        opened = threading.Event()
        self._thread = threading.Thread(
            target=self._write, args=(opened,), name="ros messages", daemon=True
        )
        self._thread.start()
        opened.wait()
        if self._failed is not None:
            self._thread.join()
            self._thread = None
            raise self._failed

    def _write(self, opened: threading.Event) -> None:
        """Open the writer, then serialise and write on this thread of its own (a db3 bag's
        SQLite wants one thread; CDR copies, CRCs and the disk release the GIL, so the next
        frame is fused meanwhile), and close it at the end."""
        try:
            if self.open_writer is not None:
                self.writer = self.open_writer()
            else:
                assert self.path is not None
                self.writer = BagWriter(self.path, self.fmt, self.compression)
        except Exception as exc:
            self._failed = exc
            return
        finally:
            opened.set()
        try:
            while (item := self._queue.get()) is not None:
                if self._failed is None:
                    try:
                        self.writer.write(*item)
                    except Exception as exc:  # said at the next frame and at the end
                        self._failed = exc
        finally:
            self.writer.close()

    def _put(
        self, topic: str, msgtype: str, msg: Any, time_s: float, latched: bool = False
    ) -> None:
        self._raise_failure()
        self._queue.put((topic, msgtype, msg, time_s, latched))

    def _raise_failure(self) -> None:
        if self._failed is not None:
            raise InputError(f"{self.path or 'Foxglove'}: cannot write ({self._failed})")

    def _due(self, what: str, every_s: float) -> bool:
        """Whether ``what`` goes now, ``every_s`` after it last went (wall clock)."""
        now = time.monotonic()
        if now - self._last[what] < every_s:
            return False
        self._last[what] = now
        return True

    def _live_due(self, what: str) -> bool:
        return self.max_hz is None or self._due(what, 1.0 / self.max_hz)

    def event(self, event: StreamEvent) -> None:
        if isinstance(event, Match) and self.writer is not None and self._live_due("pair"):
            assert self.calibration is not None
            with_tf = self._due("tf", math.inf if self.max_hz is None else 1.0)
            write_rig(self._queued, self.calibration, event.pair, with_tf)
            self.pairs += 1

    def frame(self, fused: FusedFrame) -> None:
        if self.writer is None or not self._live_due("frame"):
            return
        s, t, depth_frame = self.writer.store, fused.thermal_time_s, FRAMES["depth"]
        temp = np.asarray(fused.temp_depth_c, np.float32)
        if self.temperature_image in ("both", "32FC1"):
            self._put(TOPICS["temperature"], IMAGE, image_msg(s, temp, t, depth_frame), t)
        if self.temperature_image in ("both", "16UC1"):
            image = image_msg(s, centikelvin_image(temp), t, depth_frame, "16UC1")
            self._put(TOPICS["temperature_ck"], IMAGE, image, t)
        every = max(1, math.ceil(len(fused.with_temperature) / self.cloud_points))
        points, temps = fused.points(every)
        self._put(TOPICS["cloud"], CLOUD, cloud_msg(s, points, temps, t, depth_frame), t)
        self._put(TOPICS["markers"], MARKERS, markers_msg(s, fused, depth_frame), t)
        text = json.dumps(jsonable(measurement_message(fused)))
        self._put(TOPICS["measurements"], STRING, s.types[STRING](data=text), t)
        for event in fused.events:
            text = json.dumps(jsonable(alarm_message(event, fused)))
            self._put(TOPICS["alarms"], STRING, s.types[STRING](data=text), t)
        self.frames += 1

    def close(self, result: SessionResult) -> None:
        if self._thread is None:
            return
        self._queue.put(None)
        self._thread.join()
        self._thread = None
        self._raise_failure()

    def summary(self) -> str | None:
        where = self.path if self.path is not None else "Foxglove"
        return f"{where}: {self.pairs} pairs and {self.frames} fused frames as ROS messages"
