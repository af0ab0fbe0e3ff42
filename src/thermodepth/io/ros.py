"""A rig's ROS messages, read from any bag and written for ROS tools and Foxglove, with the
rosbags library's type stores (the ``ros`` extra; no ROS install).

Reading (messages as rosbags deserialises them, ROS 1 or ROS 2): ``sensor_msgs/Image`` in
``16UC1``/``mono16`` (uint16) or ``32FC1`` (float32), with its row ``step`` and
``is_bigendian`` (sensor_msgs/Image.msg); ``sensor_msgs/CameraInfo`` as intrinsics (ROS 1's
``K``/``D``, ROS 2's ``k``/``d``; the plumb_bob model's five coefficients); ``/tf_static``
(``tf2_msgs/TFMessage``) as the transform between two frames, through the tree. A stamp is
``sec`` + ``nanosec`` (rosbags presents a ROS 1 time the same way).

Writing (ROS 2 Humble's definitions unless told the ROS 1 store): the same messages, and a
``sensor_msgs/PointCloud2`` of x, y, z and a float32 ``temperature`` (C), a
``visualization_msgs/MarkerArray`` and ``std_msgs/String`` (JSON); temperatures on an image
as ``32FC1`` C or as ``16UC1`` centikelvin (:func:`centikelvin_image`), the form Foxglove
colours.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from ..calibration import Calibration
from ..camera import Intrinsics, RigidTransform
from ..errors import InputError
from ..frames import FramePair
from ..radiometry import ZERO_C_IN_K
from ..trajectory import Trajectory

INSTALL = "ROS bags and MCAP need the ros extra: pip install 'thermodepth[ros]'"
DEPTH_ENCODINGS = {"16UC1": "u2", "mono16": "u2", "32FC1": "f4"}
THERMAL_ENCODINGS = DEPTH_ENCODINGS
IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
TF = "tf2_msgs/msg/TFMessage"


def typestore(ros1: bool = False) -> Any:
    """rosbags' ROS 2 Humble type store, or ROS 1 Noetic's with ``tf2_msgs/TFMessage`` added
    (Noetic's store lacks it)."""
    try:
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    except ImportError:
        raise InputError(INSTALL) from None
    if not ros1:
        return get_typestore(Stores.ROS2_HUMBLE)
    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms\n", TF))
    return store


# -- reading ------------------------------------------------------------------------------------


def stamp_ns(stamp: Any) -> int:
    """A ROS time (``sec``, ``nanosec``) in nanoseconds (exact: a key to match stamps by)."""
    return int(stamp.sec) * 10**9 + int(stamp.nanosec)


def stamp_s(stamp: Any) -> float:
    """A ROS time (``sec``, ``nanosec``) in seconds."""
    return int(stamp.sec) + int(stamp.nanosec) * 1e-9


def image_array(msg: Any, where: str, encodings: dict[str, str]) -> NDArray[Any]:
    """An Image's pixels, (height, width), native byte order; InputError naming ``where``
    for an encoding not in ``encodings`` or data shorter than its rows."""
    kind = encodings.get(msg.encoding)
    if kind is None:
        raise InputError(
            f"{where}: encoding {msg.encoding!r}; expected one of {', '.join(encodings)}"
        )
    dtype = np.dtype(kind).newbyteorder(">" if msg.is_bigendian else "<")
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, dtype=np.uint8)
    if step < w * dtype.itemsize or data.size < h * step:
        raise InputError(
            f"{where}: {data.size} bytes do not hold {w}x{h} {msg.encoding} rows of {step} bytes"
        )
    rows = data[: h * step].reshape(h, step)[:, : w * dtype.itemsize]
    return np.ascontiguousarray(rows).view(dtype).reshape(h, w).astype(dtype.newbyteorder("="))


def intrinsics_of(info: Any, where: str) -> Intrinsics:
    """A CameraInfo's intrinsics (its K and the first five of D, OpenCV's order)."""
    k = np.asarray(info.k if hasattr(info, "k") else info.K, dtype=float)  # ROS 2, ROS 1
    d = np.asarray(info.d if hasattr(info, "d") else info.D, dtype=float)
    distortion = np.zeros(5)
    distortion[: min(5, d.size)] = d[:5]
    try:
        return Intrinsics(int(info.width), int(info.height), k[0], k[4], k[2], k[5], distortion)
    except (ValueError, IndexError) as exc:
        raise InputError(f"{where}: not a camera's intrinsics ({exc})") from None


def quaternion_matrix(x: float, y: float, z: float, w: float) -> NDArray[np.float64]:
    """The rotation of a quaternion (normalised first; scipy's scalar-last order, as ROS's)."""
    return np.asarray(Rotation.from_quat([x, y, z, w]).as_matrix())


def matrix_quaternion(r: NDArray[np.float64]) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation matrix (w >= 0)."""
    x, y, z, w = Rotation.from_matrix(r).as_quat(canonical=True)
    return float(x), float(y), float(z), float(w)


def stamped_transforms(messages: Iterable[Any]) -> list[tuple[float, RigidTransform]]:
    """Every TransformStamped of TFMessages as its stamp (s) and ``parent_from_child`` (a
    child's pose in its parent: p_parent = R p_child + t)."""
    out = []
    for msg in messages:
        for t in msg.transforms:
            q, v = t.transform.rotation, t.transform.translation
            out.append((stamp_s(t.header.stamp), RigidTransform(
                quaternion_matrix(q.x, q.y, q.z, q.w), np.array([v.x, v.y, v.z]),
                t.header.frame_id.lstrip("/"), t.child_frame_id.lstrip("/"),
            )))  # fmt: skip
    return out


def static_transforms(messages: Iterable[Any]) -> list[RigidTransform]:
    """Every TransformStamped of TFMessages as ``parent_from_child``, stamps set aside."""
    return [t for _, t in stamped_transforms(messages)]


def tf_trajectory(
    statics: list[RigidTransform], moving: list[tuple[float, RigidTransform]], frame: str
) -> tuple[Trajectory, str] | None:
    """``frame``'s poses in the root of the transform tree over time, from the tree's
    ``statics`` and its ``moving`` transforms (stamped, /tf): at each stamp of the moving
    transforms on the way from the root down to ``frame``, each of them interpolated to it
    (slerp) and composed with the static ones; and the root's name. None when no moving
    transform lies on that way."""
    parent: dict[str, tuple[str, bool]] = {t.from_frame: (t.to_frame, False) for t in statics}
    series: dict[tuple[str, str], list[tuple[float, RigidTransform]]] = {}
    for stamp, t in moving:
        parent[t.from_frame] = (t.to_frame, True)
        series.setdefault((t.to_frame, t.from_frame), []).append((stamp, t))
    static_of = {(t.to_frame, t.from_frame): t for t in statics}
    path, at, seen = [], frame, {frame}
    while at in parent:  # up from the frame to the root
        up, moves = parent[at]
        path.append(((up, at), moves))
        if up in seen:
            return None  # a loop is no tree
        seen.add(up)
        at = up
    edges = {key: _edge_trajectory(series[key]) for key, moves in path if moves}
    if not edges:
        return None
    times = np.unique(np.concatenate([e.times_s for e in edges.values()]))
    rot = np.repeat(np.eye(3)[None], len(times), 0)
    pos = np.zeros((len(times), 3))
    for key, moves in path:  # frame's pose in each parent in turn, up to the root
        if moves:
            r, p = edges[key].poses_at(times)
        else:
            t = static_of[key]
            r, p = t.rotation[None], t.translation_m[None]
        pos = np.einsum("nij,nj->ni", r, pos) + p
        rot = r @ rot
    return Trajectory(times, rot, pos), at


def _edge_trajectory(samples: list[tuple[float, RigidTransform]]) -> Trajectory:
    """One moving transform's samples as a trajectory (a stamp given twice: the last)."""
    by_time = {stamp: t for stamp, t in sorted(samples, key=lambda s: s[0])}
    times = np.array(list(by_time))
    return Trajectory.of_poses(times, list(by_time.values()))


def transform_between(
    transforms: list[RigidTransform], to_frame: str, from_frame: str
) -> RigidTransform | None:
    """``to_frame``_from_``from_frame`` through the tree of ``transforms`` (None: the two
    frames are not connected)."""
    edges: dict[str, list[RigidTransform]] = {}
    for t in transforms:
        edges.setdefault(t.from_frame, []).append(t)
        edges.setdefault(t.to_frame, []).append(t.inverse())
    found = {from_frame: RigidTransform.identity(from_frame, from_frame)}
    todo = deque([from_frame])
    while todo:
        frame = todo.popleft()
        for step in edges.get(frame, []):  # step: to_frame <- frame
            if step.to_frame not in found:
                found[step.to_frame] = step @ found[frame]
                todo.append(step.to_frame)
    return found.get(to_frame)


# -- writing ------------------------------------------------------------------------------------


def header_msg(store: Any, time_s: float, frame_id: str) -> Any:
    """A std_msgs/Header stamped ``time_s`` (s) in ``frame_id`` (ROS 1: seq 0)."""
    t = store.types
    ns = round(time_s * 1e9)
    stamp = t["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
    if "seq" in t["std_msgs/msg/Header"].__dataclass_fields__:  # ROS 1
        return t["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame_id)
    return t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)


def image_msg(
    store: Any, image: NDArray[Any], time_s: float, frame_id: str, encoding: str | None = None
) -> Any:
    """An Image of a uint8 (``mono8``), uint16 (``16UC1``, or ``mono16`` when told) or
    float32 (``32FC1``) array, little-endian."""
    kind = {np.dtype(np.uint8): ("mono8", "u1"), np.dtype(np.uint16): ("16UC1", "<u2")}
    default, dtype = kind.get(image.dtype, ("32FC1", "<f4"))
    encoding = encoding or default
    pixels = np.ascontiguousarray(image, dtype=dtype)
    return store.types[IMAGE](
        header=header_msg(store, time_s, frame_id),
        height=pixels.shape[0], width=pixels.shape[1], encoding=encoding, is_bigendian=0,
        step=pixels.strides[0], data=pixels.reshape(-1).view(np.uint8),
    )  # fmt: skip


CENTIKELVIN_MAX_C = 65535 / 100 - ZERO_C_IN_K  # 382.2 C, the most a uint16 of 0.01 K holds


def centikelvin_image(temp_c: NDArray[Any]) -> NDArray[np.uint16]:
    """Temperatures as a ``16UC1`` image of centikelvin, the 16-bit form Foxglove colours
    with a colour map between a min and a max (it shows a ``32FC1`` image as value x 255).

    Args:
        temp_c: (H, W) temperatures, C; NaN where there is none.

    Returns:
        (H, W) uint16, round(100 * (T_C + 273.15)): 0.01 K a step; 0 where there is no
        temperature; readings above :data:`CENTIKELVIN_MAX_C` held at 65535, and any
        at or below absolute zero at 1 (so that 0 keeps meaning none).
    """
    kelvin_100 = np.array(temp_c, np.float64)  # in place from here: a frame is a megapixel
    kelvin_100 += ZERO_C_IN_K
    kelvin_100 *= 100.0
    np.rint(kelvin_100, out=kelvin_100)
    none = np.isnan(kelvin_100)
    np.clip(kelvin_100, 1.0, 65535.0, out=kelvin_100)  # +-inf held too
    kelvin_100[none] = 0.0
    return kelvin_100.astype(np.uint16)


def camera_info_msg(store: Any, intr: Intrinsics, time_s: float, frame_id: str) -> Any:
    """A CameraInfo of intrinsics (plumb_bob; R identity; P = [K | 0])."""
    t = store.types
    k = np.array([intr.fx, 0, intr.cx, 0, intr.fy, intr.cy, 0, 0, 1], dtype=np.float64)
    p = np.array([intr.fx, 0, intr.cx, 0, 0, intr.fy, intr.cy, 0, 0, 0, 1, 0], np.float64)
    r = np.eye(3).reshape(-1)
    d = np.asarray(intr.distortion, dtype=np.float64)
    ros1 = "K" in t[CAMERA_INFO].__dataclass_fields__
    arrays = {"D": d, "K": k, "R": r, "P": p} if ros1 else {"d": d, "k": k, "r": r, "p": p}
    roi = t["sensor_msgs/msg/RegionOfInterest"](
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
    )
    return t[CAMERA_INFO](
        header=header_msg(store, time_s, frame_id), height=intr.height, width=intr.width,
        distortion_model="plumb_bob", **arrays, binning_x=0, binning_y=0, roi=roi,
    )  # fmt: skip


def tf_msg(store: Any, transforms: list[RigidTransform], time_s: float) -> Any:
    """A TFMessage of ``parent_from_child`` transforms (frames as their names)."""
    t = store.types
    out = []
    for tr in transforms:
        x, y, z, w = matrix_quaternion(tr.rotation)
        out.append(t["geometry_msgs/msg/TransformStamped"](
            header=header_msg(store, time_s, tr.to_frame), child_frame_id=tr.from_frame,
            transform=t["geometry_msgs/msg/Transform"](
                translation=t["geometry_msgs/msg/Vector3"](*map(float, tr.translation_m)),
                rotation=t["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
            ),
        ))  # fmt: skip
    return t[TF](transforms=out)


# -- bags ---------------------------------------------------------------------------------------


class MessageWriter(Protocol):
    """What takes ROS messages built with its type store (:func:`write_rig` writes to one)."""

    @property
    def store(self) -> Any: ...

    def write(
        self, topic: str, msgtype: str, msg: Any, time_s: float, latched: bool = False
    ) -> None: ...


class MessageOutput(MessageWriter, Protocol):
    """Where ROS messages go: a bag (:class:`BagWriter`) or a live Foxglove server
    (:class:`~thermodepth.sinks.foxglove.FoxgloveWriter`)."""

    def close(self) -> None: ...


FORMATS = ("mcap", "rosbag2", "rosbag2-mcap", "ros1")
"""What :class:`BagWriter` writes: a standalone MCAP of ROS 2 messages (profile ``ros2``,
``ros2msg`` schemas, CDR), a rosbag2 folder with ``.db3`` or ``.mcap`` storage (metadata
version 8, which ROS 2 Humble reads), a ROS 1 bag."""
COMPRESSIONS = ("none", "lz4", "zstd")
BAG_COMPRESSIONS = {"mcap": COMPRESSIONS, "rosbag2": ("none",), "rosbag2-mcap": ("none", "zstd"),
                    "ros1": ("none", "lz4")}  # fmt: skip
"""What each format can compress with (its chunks: MCAP's, a ROS 1 bag's)."""


class BagWriter:
    """ROS messages into a new bag at ``path`` of ``fmt`` (:data:`FORMATS`), compressed as
    :data:`BAG_COMPRESSIONS` allows. Messages are built with :attr:`store`
    (:func:`typestore`). Use it as a context manager."""

    def __init__(self, path: str | Path, fmt: str = "mcap", compression: str = "none") -> None:
        if fmt not in FORMATS or compression not in COMPRESSIONS:
            raise ValueError(f"format {fmt!r}, compression {compression!r}")
        if compression not in BAG_COMPRESSIONS[fmt]:
            raise InputError(
                f"{fmt}: compression {compression} cannot be; "
                f"one of {', '.join(BAG_COMPRESSIONS[fmt])}"
            )
        self.path, self.fmt = Path(path), fmt
        if self.path.exists():
            raise InputError(f"{self.path}: exists already; give a new path")
        self.store = typestore(ros1=fmt == "ros1")
        self._topics: dict[str, Any] = {}
        self._bag: Any = None
        if fmt == "mcap":
            from mcap.writer import CompressionType, Writer

            from .. import __version__

            self._file = self.path.open("wb")
            kind = {"none": CompressionType.NONE, "lz4": CompressionType.LZ4,
                    "zstd": CompressionType.ZSTD}[compression]  # fmt: skip
            self._mcap = Writer(self._file, compression=kind)
            self._mcap.start(profile="ros2", library=f"thermodepth {__version__}")
        elif fmt == "ros1":
            from rosbags.rosbag1 import Writer as Ros1Writer

            self._bag = Ros1Writer(self.path)
            if compression != "none":
                self._bag.set_compression(Ros1Writer.CompressionFormat.LZ4)
            self._bag.open()
        else:
            from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin
            from rosbags.rosbag2 import Writer as Ros2Writer

            plugin = StoragePlugin.MCAP if fmt == "rosbag2-mcap" else StoragePlugin.SQLITE3
            self._bag = Ros2Writer(self.path, version=8, storage_plugin=plugin)
            if compression == "zstd":
                self._bag.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
            self._bag.open()

    def _topic(self, topic: str, msgtype: str, latched: bool) -> Any:
        if self.fmt == "mcap":
            text = self.store.generate_msgdef(msgtype, ros_version=2)[0]
            schema = self._mcap.register_schema(msgtype, "ros2msg", text.encode())
            return self._mcap.register_channel(topic, "cdr", schema)
        if self.fmt == "ros1":
            return self._bag.add_connection(topic, msgtype, typestore=self.store,
                                            latching=int(latched))  # fmt: skip
        qos = []
        if latched:
            from rosbags.interfaces import (
                Qos,
                QosDurability,
                QosHistory,
                QosLiveliness,
                QosReliability,
                QosTime,
            )  # fmt: skip

            zero = QosTime(0, 0)
            qos = [Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE,
                       QosDurability.TRANSIENT_LOCAL, zero, zero, QosLiveliness.AUTOMATIC,
                       zero, False)]  # fmt: skip
        return self._bag.add_connection(
            topic, msgtype, typestore=self.store, offered_qos_profiles=qos
        )

    def write(
        self, topic: str, msgtype: str, msg: Any, time_s: float, latched: bool = False
    ) -> None:
        """One message on ``topic`` at ``time_s`` (the bag's time; s)."""
        conn = self._topics.get(topic)
        if conn is None:
            conn = self._topics[topic] = self._topic(topic, msgtype, latched)
        ns = round(time_s * 1e9)
        if self.fmt == "ros1":
            self._bag.write(conn, ns, self.store.serialize_ros1(msg, msgtype))
        elif self.fmt == "mcap":
            data = self.store.serialize_cdr(msg, msgtype)  # a buffer, not copied again
            self._mcap.add_message(conn, log_time=ns, publish_time=ns, data=data)
        else:
            self._bag.write(conn, ns, self.store.serialize_cdr(msg, msgtype))

    def close(self) -> None:
        if self.fmt == "mcap":
            self._mcap.finish()
            self._file.close()
        else:
            self._bag.close()

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


TOPICS = {
    "depth": "/thermodepth/depth/image_rect_raw",
    "depth_info": "/thermodepth/depth/camera_info",
    "thermal": "/thermodepth/thermal/image_raw",
    "thermal_info": "/thermodepth/thermal/camera_info",
    "vox": "/thermodepth/thermal/sensor_temperature",
    "ir": "/thermodepth/infra1/image_rect_raw",
}
"""Where a rig's raw streams go, named as realsense-ros names its own (each image with its
camera_info beside it), so that ``rosbag:`` finds them by itself."""
FRAMES = {
    "depth": "thermodepth_depth_optical_frame",
    "thermal": "thermodepth_thermal_optical_frame",
}
TEMPERATURE = "sensor_msgs/msg/Temperature"


def write_rig(
    writer: MessageWriter, calibration: Calibration, pair: FramePair, with_tf: bool
) -> None:
    """A pair's raw streams: depth (16UC1, the calibration's unit), thermal (mono16 as the
    camera gave it), each camera_info, the infrared image (mono8, where the pair has one),
    the sensor temperature (C, where told; before the
    thermal image, which takes the latest) and, ``with_tf``, ``/tf_static``
    (thermal_from_depth as the depth frame's pose in the thermal's)."""
    s = writer.store
    if with_tf:
        pose = calibration.thermal_from_depth
        tf = RigidTransform(pose.rotation, pose.translation_m, FRAMES["thermal"], FRAMES["depth"])
        writer.write("/tf_static", TF, tf_msg(s, [tf], pair.depth_time_s), pair.depth_time_s, True)
    vox_c = pair.telemetry.fpa_temp_c
    if np.isfinite(vox_c):
        t = pair.thermal_time_s
        msg = s.types[TEMPERATURE](
            header=header_msg(s, t, FRAMES["thermal"]), temperature=float(vox_c), variance=0.0
        )
        writer.write(TOPICS["vox"], TEMPERATURE, msg, t)
    for what, image, t in (("depth", pair.depth, pair.depth_time_s),
                           ("thermal", pair.thermal, pair.thermal_time_s)):  # fmt: skip
        frame = FRAMES[what]
        intr = getattr(calibration, what)
        encoding = "16UC1" if what == "depth" else "mono16"
        writer.write(TOPICS[what], IMAGE, image_msg(s, image, t, frame, encoding), t)
        writer.write(TOPICS[f"{what}_info"], CAMERA_INFO, camera_info_msg(s, intr, t, frame), t)
    if pair.ir is not None:  # the depth camera's own infrared image, on the depth grid
        t = pair.depth_time_s
        writer.write(TOPICS["ir"], IMAGE, image_msg(s, pair.ir, t, FRAMES["depth"]), t)
