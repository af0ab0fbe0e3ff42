"""Sources of FramePairs: the simulated rig, real cameras, recordings, image folders; pairing
in time.

:func:`open_source` turns a spec into a :class:`Source`:

================================  =========================================================
spec                              what
================================  =========================================================
``sim[:KEY=VALUE,...]``           the simulated rig (plate + 70 C chip at 1 m); keys
                                  ``thermal`` (a camera of
                                  :data:`~thermodepth.sim.cameras.THERMAL_CAMERAS`),
                                  ``depth`` (a mode, ``848x480@30``), ``pace=real`` (in
                                  real time) and ``faults`` (:mod:`.sim`)
``realsense[:SERIAL]``            a live RealSense (depth only: recordable, no pairs)
``realsense:FILE.bag|db3``        a RealSense recording played back (depth only)
``lepton[:N]``                    a Lepton 2.5/3/3.5 on a PureThermal, /dev/videoN
``p2pro[:N]``                     an InfiRay P2 Pro / Topdon TC001
``boson[:N]``                     a FLIR Boson / Boson+ (its output: the calibration's)
``DEPTH+THERMAL``                 a live depth camera and a thermal camera paired in time,
                                  each part with its options: ``realsense+lepton``,
                                  ``realsense:123456+boson:/dev/video2`` (a RealSense file
                                  cannot be paired with a live camera: their clocks differ)
``recording:PATH``                a thermodepth recording (zarr), replayed bit for bit
``folder:PATH``                   a folder of images from any rig (rig.yaml, frames.csv)
``rosbag:PATH[,KEY=TOPIC,...]``   a ROS 1 bag, rosbag2 folder or MCAP (:mod:`.rosbag`);
                                  keys ``depth``, ``thermal``, ``ir``, ``vox`` name topics
================================  =========================================================

A camera's N is its /dev/videoN (``2`` or ``/dev/video2``; none: the first of its kind found).
Parts are joined by a '+' followed by a source name, so a '+' inside a file name is kept
(:func:`split_spec`). Every source yields :class:`~thermodepth.frames.FramePair` when iterated
(if it has both streams; otherwise a one-line InputError) and
:class:`~thermodepth.frames.StreamEvent` from ``events()`` (what recorders store).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..calibration import Calibration
from ..errors import FieldError, InputError, ThermodepthError
from ..frames import parse_depth_mode
from .base import DeviceLostError, Source, event_time_s, with_device_depth
from .pairing import DEFAULT_MAX_SKEW_S, PairingStats, StreamPairer, pair_times

SPEC_HELP = (
    "sim[:thermal=CAMERA,depth=WxH,pace=real,faults=...], "
    "realsense[:SERIAL|:FILE.bag|:FILE.db3], lepton[:N], p2pro[:N], boson[:N], "
    "DEPTH+THERMAL (realsense+lepton, realsense+p2pro, ...), "
    "recording:PATH, folder:PATH, rosbag:PATH[,depth=TOPIC,thermal=TOPIC,ir=TOPIC,vox=TOPIC]"
)
DEPTH_CAMERAS = ("realsense",)
THERMAL_CAMERAS = ("lepton", "p2pro", "boson")
SOURCE_KINDS = ("sim", *DEPTH_CAMERAS, *THERMAL_CAMERAS, "recording", "folder", "rosbag")
_JOIN = re.compile(r"\+(?=(?:" + "|".join(SOURCE_KINDS) + r")(?::|\+|$))")
"""A '+' that joins two source specs: one followed by a source name (so that a '+' inside a
file name, as in ``realsense:take+1.db3``, is left alone)."""
SIM_KEYS = ("thermal", "depth", "pace", "faults")


def split_spec(spec: str) -> list[tuple[str, str]]:
    """A source spec as ``(kind, argument)`` parts: ``"realsense:123+lepton:2"`` ->
    ``[("realsense", "123"), ("lepton", "2")]``. Parts are joined by a '+' followed by a
    source name; a ``recording:``, ``folder:`` or ``rosbag:`` spec is never split."""
    text = spec.strip()
    whole = text.startswith(("recording:", "folder:", "rosbag:"))
    parts = [text] if whole else _JOIN.split(text)
    return [(kind, arg) for kind, _, arg in (part.partition(":") for part in parts)]


def sim_options(arg: str) -> dict[str, str]:
    """The ``KEY=VALUE,...`` of a ``sim:`` spec (a part without ``=`` goes on the value
    before it: ``faults=unplug@20s+5s,stall@40s``); FieldError (``source``) for a key it
    does not know, or ``pace`` other than ``real``."""
    options: dict[str, str] = {}
    key = None
    for item in filter(None, (x.strip() for x in arg.split(","))):
        name, eq, value = item.partition("=")
        if not eq and key == "faults":
            options["faults"] += "," + item
            continue
        if not eq or name not in SIM_KEYS or not value:
            raise FieldError(
                "source", f"sim:{arg}: expected KEY=VALUE with KEY one of {', '.join(SIM_KEYS)}"
            )
        key = name
        options[key] = value
    if options.get("pace", "real") != "real":
        raise FieldError("source", f"sim:{arg}: pace: expected real (in real time)")
    return options


def _is_file_arg(arg: str) -> bool:
    from .realsense import PLAYBACK_EXTENSIONS

    return bool(arg) and Path(arg).suffix.lower() in PLAYBACK_EXTENSIONS


def _realsense(
    arg: str, with_ir: bool, warn: Callable[[str], None] | None, depth_mode: str | None
) -> Any:
    from .realsense import RealSenseCamera

    mode = None
    if depth_mode is not None:
        w, h, fps = parse_depth_mode(depth_mode)
        mode = (w, h, round(fps or 30))
    if _is_file_arg(arg):
        return RealSenseCamera(path=arg, mode=mode, with_ir=with_ir, warn=warn)
    if arg and not arg.isalnum():
        raise InputError(f"realsense:{arg}: expected a serial number or a .bag/.db3 file")
    return RealSenseCamera(serial=arg or None, mode=mode, with_ir=with_ir, warn=warn)


def _thermal_camera(
    kind: str,
    arg: str,
    latency_s: float,
    calibration: Calibration | None,
    warn: Callable[[str], None] | None,
) -> Any:
    """The thermal camera ``kind:arg`` names (:data:`THERMAL_CAMERAS`)."""
    from .uvc import device_index

    index = device_index(kind, arg)
    if kind == "lepton":
        from .lepton import LeptonCamera

        return LeptonCamera(index, latency_s=latency_s, warn=warn)
    if kind == "p2pro":
        from .infiray import P2ProCamera

        return P2ProCamera(index, latency_s=latency_s, warn=warn)
    from .boson import BosonCamera

    output = calibration.thermal_output if calibration is not None else None
    return BosonCamera(index, output, latency_s=latency_s, warn=warn)


def _device_calibration(camera: Any, calibration: Calibration | None) -> Calibration | None:
    return with_device_depth(
        calibration, camera.device_depth, f"{camera.name} (device depth intrinsics)"
    )


def _closing_on_error(cameras: list[Any], build: Callable[[], Source]) -> Source:
    """``build()``, or close the (already started) cameras if it fails."""
    try:
        return build()
    except BaseException:
        for cam in cameras:
            cam.close()
        raise


def _open_both(opens: list[Callable[[], Any]], spec: str) -> list[Any]:
    """Open every camera; if any cannot be opened, close the others and raise one InputError
    naming every camera that failed."""
    cameras, errors = [], []
    try:
        for open_camera in opens:
            try:
                cameras.append(open_camera())
            except InputError as exc:
                errors.append(str(exc))
    except BaseException:
        for cam in cameras:
            cam.close()
        raise
    if errors:
        for cam in cameras:
            cam.close()
        raise FieldError("source", f"{spec}: " + "; ".join(errors))
    return cameras


def _calibration_unused(spec: str, owner: str, warn: Callable[[str], None] | None) -> None:
    if warn is not None:
        warn(f"{spec}: {owner} keeps its own calibration; the one given is not used")


def check_spec(spec: str) -> list[tuple[str, str]]:
    """The ``(kind, arg)`` parts of a spec (:func:`split_spec`), checked as far as can be
    without opening anything: the kinds and how they combine, a ``sim:`` spec's keys and
    faults, a path where one is needed, a device's number. One FieldError (``source``)
    otherwise."""
    from .sim import parse_faults
    from .uvc import device_index

    text = spec.strip()
    parts = split_spec(text)
    kinds = [k for k, _ in parts]
    if len(parts) > 1:
        if len(parts) != 2 or kinds[0] not in DEPTH_CAMERAS or kinds[1] not in THERMAL_CAMERAS:
            raise FieldError(
                "source",
                f"cannot combine {text!r}; expected a depth camera and a thermal camera, "
                f"DEPTH+THERMAL with DEPTH one of {', '.join(DEPTH_CAMERAS)} and THERMAL one of "
                f"{', '.join(THERMAL_CAMERAS)}",
            )
        if _is_file_arg(parts[0][1]):
            raise FieldError(
                "source",
                f"{text}: a RealSense file cannot be paired with a live thermal camera (the "
                "file's times are not the live clock); record the file alone, or use "
                f"realsense[:SERIAL]+{kinds[1]}",
            )
    for kind, arg in parts:
        if kind not in SOURCE_KINDS:
            raise FieldError("source", f"unknown {text!r}; expected one of {SPEC_HELP}")
        if kind == "sim":
            parse_faults(sim_options(arg).get("faults", ""))
        if kind in ("recording", "folder") and not arg:
            raise FieldError("source", f"{kind}:PATH needs a path")
        if kind == "rosbag":
            from .rosbag import parse_spec

            parse_spec(arg)
        if kind in THERMAL_CAMERAS and arg:
            device_index(kind, arg)
    return parts


def open_source(
    spec: str,
    calibration: Calibration | None = None,
    *,
    frames: int | None = None,
    max_skew_s: float = DEFAULT_MAX_SKEW_S,
    with_ir: bool = False,
    thermal_latency_s: float = 0.0,
    warn: Callable[[str], None] | None = None,
    depth_mode: str | None = None,
    thermal_camera: str | None = None,
) -> Source:
    """Open the source a spec names (table above); bad specs and missing devices raise a
    one-line InputError (a pair of cameras names every camera missing).

    calibration: the user's calibration (thermal intrinsics, extrinsics, the thermal
    camera's output); RealSense sources replace its depth section with the device's
    intrinsics and depth unit, and so does a recording made without a calibration (with the
    device's it holds). frames: for ``sim``, how many pairs (None: endless). max_skew_s: the
    pairing threshold of two live cameras (and of a folder with times). with_ir: also read
    the depth camera's infrared image. thermal_latency_s: subtracted from a thermal camera's
    frame arrival times (0: not calibrated). warn: where one-line warnings go (a recording's
    skipped frames, a RealSense stream that restarted, a calibration given to a source that
    keeps its own, a folder's bad rows, a camera's missing telemetry). depth_mode: the depth
    camera's mode, ``WxH[@FPS]`` (a RealSense's, the simulator's); thermal_camera: the
    simulated thermal camera (``sim`` only: live cameras are named in the spec).
    """
    from .paired import PairedSource, StreamSource

    text = spec.strip()
    parts = check_spec(text)
    kind, arg = parts[0]
    if thermal_camera is not None and kind != "sim":
        raise FieldError(
            "thermal_camera",
            f"chooses the simulated thermal camera (--source sim); {text} names its cameras "
            "itself (realsense+p2pro, ...)",
        )
    if len(parts) > 1:
        (_, rs_arg), (thermal_kind, thermal_arg) = parts
        depth_cam, thermal_cam = _open_both(
            [
                lambda: _realsense(rs_arg, with_ir, warn, depth_mode),
                lambda: _thermal_camera(
                    thermal_kind, thermal_arg, thermal_latency_s, calibration, warn
                ),
            ],
            text,
        )
        return _closing_on_error(
            [depth_cam, thermal_cam],
            lambda: PairedSource(
                depth_cam, thermal_cam, _device_calibration(depth_cam, calibration), max_skew_s
            ),
        )
    if kind == "sim":
        from .sim import SimSource, parse_faults

        options = sim_options(arg)
        src = SimSource(
            frames=frames,
            thermal=options.get("thermal", thermal_camera),
            depth=options.get("depth", depth_mode),
            paced="pace" in options,
            faults=parse_faults(options.get("faults", "")),
            device=text,
        )
        if with_ir:
            src.rig.with_ir = True
        if calibration is not None:
            _calibration_unused(text, "the simulated rig", warn)
        return src
    if kind == "rosbag":
        from .rosbag import RosbagSource

        return RosbagSource(arg, calibration, warn, max_skew_s, with_ir)
    if kind in ("recording", "folder"):
        if kind == "folder":
            from .folder import FolderSource

            folder = FolderSource(arg, warn, max_skew_s)
            if calibration is not None:
                _calibration_unused(text, f"the folder ({folder.folder / 'rig.yaml'})", warn)
            return folder
        from .replay import RecordingSource

        replay = RecordingSource(arg, warn, calibration)
        if calibration is not None and replay.recording.calibration is not None:
            _calibration_unused(text, "the recording", warn)
        return replay
    if kind == "realsense":
        cam = _realsense(arg, with_ir, warn, depth_mode)
        return _closing_on_error(
            [cam], lambda: StreamSource(cam, "depth", _device_calibration(cam, calibration))
        )
    thermal = _thermal_camera(kind, arg, thermal_latency_s, calibration, warn)
    return StreamSource(thermal, "thermal", calibration)


def list_devices() -> dict[str, Any]:
    """What is attached: ``{"realsense": [...], "realsense_unavailable": None or why,
    "thermal": [...] (each a capture node with its ``kind``: lepton, p2pro, boson), "video":
    [...] (every capture node)}`` (``realsense_unavailable`` says why RealSense devices cannot
    be listed: pyrealsense2 missing or not importable)."""
    from .realsense import list_realsense
    from .uvc import list_video_devices

    try:
        realsense, unavailable = list_realsense(), None
    except ThermodepthError as exc:
        realsense, unavailable = [], str(exc)
    video = list_video_devices()
    return {
        "realsense": realsense,
        "realsense_unavailable": unavailable,
        "thermal": [d for d in video if d["kind"] is not None],
        "video": video,
    }


__all__ = [
    "DEFAULT_MAX_SKEW_S",
    "SOURCE_KINDS",
    "SPEC_HELP",
    "DeviceLostError",
    "PairingStats",
    "Source",
    "StreamPairer",
    "check_spec",
    "event_time_s",
    "list_devices",
    "open_source",
    "pair_times",
    "split_spec",
]
