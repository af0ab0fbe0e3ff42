"""Sources of FramePairs: the simulated rig, real cameras, recordings; pairing in time.

:func:`open_source` turns a spec into a :class:`Source`:

==========================  ===============================================================
spec                        what
==========================  ===============================================================
``sim``                     the simulated rig (plate + 70 C chip at 1 m)
``realsense[:SERIAL]``      a live RealSense (depth only: recordable, no pairs)
``realsense:FILE.bag|db3``  a RealSense recording played back (depth only)
``lepton[:INDEX]``          a Lepton 3 on a PureThermal, /dev/videoINDEX (thermal only)
``realsense+lepton``        both live cameras paired in time; each part takes its options,
                            e.g. ``realsense:123456+lepton:2`` (a RealSense file cannot be
                            paired with a live Lepton: their clocks differ)
``recording:PATH``          a thermodepth recording (zarr), replayed bit for bit
==========================  ===============================================================

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
from .base import DeviceLostError, Source, event_time_s, with_device_depth
from .pairing import DEFAULT_MAX_SKEW_S, PairingStats, StreamPairer, pair_times

SPEC_HELP = (
    "sim, realsense[:SERIAL|:FILE.bag|:FILE.db3], lepton[:INDEX], realsense+lepton, recording:PATH"
)
SOURCE_KINDS = ("sim", "realsense", "lepton", "recording")
_JOIN = re.compile(r"\+(?=(?:" + "|".join(SOURCE_KINDS) + r")(?::|\+|$))")
"""A '+' that joins two source specs: one followed by a source name (so that a '+' inside a
file name, as in ``realsense:take+1.db3``, is left alone)."""


def split_spec(spec: str) -> list[tuple[str, str]]:
    """A source spec as ``(kind, argument)`` parts: ``"realsense:123+lepton:2"`` ->
    ``[("realsense", "123"), ("lepton", "2")]``. Parts are joined by a '+' followed by a
    source name; a ``recording:PATH`` spec is never split."""
    text = spec.strip()
    parts = [text] if text.startswith("recording:") else _JOIN.split(text)
    return [(kind, arg) for kind, _, arg in (part.partition(":") for part in parts)]


def _is_file_arg(arg: str) -> bool:
    from .realsense import PLAYBACK_EXTENSIONS

    return bool(arg) and Path(arg).suffix.lower() in PLAYBACK_EXTENSIONS


def _realsense(arg: str, with_ir: bool, warn: Callable[[str], None] | None) -> Any:
    from .realsense import RealSenseCamera

    if _is_file_arg(arg):
        return RealSenseCamera(path=arg, with_ir=with_ir, warn=warn)
    if arg and not arg.isalnum():
        raise InputError(f"realsense:{arg}: expected a serial number or a .bag/.db3 file")
    return RealSenseCamera(serial=arg or None, with_ir=with_ir, warn=warn)


def _lepton(arg: str, latency_s: float) -> Any:
    from .lepton import LeptonCamera

    if arg and not arg.isdigit():
        raise InputError(f"lepton:{arg}: expected a video device number (lepton:0 = /dev/video0)")
    return LeptonCamera(int(arg) if arg else None, latency_s=latency_s)


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


def open_source(
    spec: str,
    calibration: Calibration | None = None,
    *,
    frames: int | None = None,
    max_skew_s: float = DEFAULT_MAX_SKEW_S,
    with_ir: bool = False,
    thermal_latency_s: float = 0.0,
    warn: Callable[[str], None] | None = None,
) -> Source:
    """Open the source a spec names (table above); bad specs and missing devices raise a
    one-line InputError (``realsense+lepton`` names every camera missing).

    calibration: the user's calibration (thermal intrinsics, extrinsics); RealSense sources
    replace its depth section with the device's intrinsics and depth unit, and so does a
    recording made without a calibration (with the device's it holds). frames: for ``sim``,
    how many pairs (None: endless). max_skew_s: the pairing threshold of
    ``realsense+lepton``. with_ir: also read the depth camera's infrared image.
    thermal_latency_s: subtracted from the Lepton's frame arrival times (0: not calibrated;
    see :mod:`.lepton`). warn: where one-line warnings go (a recording's skipped frames, a
    RealSense stream that restarted, a calibration given to a source that keeps its own).
    """
    from .paired import PairedSource, StreamSource

    text = spec.strip()
    parts = split_spec(text)
    kind, arg = parts[0]
    if len(parts) > 1:
        if [k for k, _ in parts] != ["realsense", "lepton"]:
            raise FieldError("source", f"cannot combine {text!r}; expected realsense+lepton")
        rs_arg, lepton_arg = parts[0][1], parts[1][1]
        if _is_file_arg(rs_arg):
            raise FieldError(
                "source",
                f"{text}: a RealSense file cannot be paired with a live Lepton (the "
                "file's times are not the live clock); record the file alone, or use "
                "realsense[:SERIAL]+lepton",
            )
        depth_cam, thermal_cam = _open_both(
            [
                lambda: _realsense(rs_arg, with_ir, warn),
                lambda: _lepton(lepton_arg, thermal_latency_s),
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
        if arg:
            raise FieldError("source", f"'sim' takes no argument, got {text!r}")
        from .sim import SimSource

        src = SimSource(frames=frames)
        if with_ir:
            src.rig.with_ir = True
        if calibration is not None:
            _calibration_unused(text, "the simulated rig", warn)
        return src
    if kind == "recording":
        if not arg:
            raise FieldError("source", "recording:PATH needs a path")
        from .replay import RecordingSource

        replay = RecordingSource(arg, warn, calibration)
        if calibration is not None and replay.recording.calibration is not None:
            _calibration_unused(text, "the recording", warn)
        return replay
    if kind == "realsense":
        cam = _realsense(arg, with_ir, warn)
        return _closing_on_error(
            [cam], lambda: StreamSource(cam, "depth", _device_calibration(cam, calibration))
        )
    if kind == "lepton":
        return StreamSource(_lepton(arg, thermal_latency_s), "thermal", calibration)
    raise FieldError("source", f"unknown {text!r}; expected one of {SPEC_HELP}")


def list_devices() -> dict[str, Any]:
    """What is attached: ``{"realsense": [...], "realsense_unavailable": None or why,
    "purethermal": [...], "video": [...]}`` (``realsense_unavailable`` says why RealSense
    devices cannot be listed: pyrealsense2 missing or not importable)."""
    from .lepton import list_purethermal, list_video_devices
    from .realsense import list_realsense

    try:
        realsense, unavailable = list_realsense(), None
    except ThermodepthError as exc:
        realsense, unavailable = [], str(exc)
    return {
        "realsense": realsense,
        "realsense_unavailable": unavailable,
        "purethermal": list_purethermal(),
        "video": list_video_devices(),
    }


__all__ = [
    "DEFAULT_MAX_SKEW_S",
    "SOURCE_KINDS",
    "SPEC_HELP",
    "DeviceLostError",
    "PairingStats",
    "Source",
    "StreamPairer",
    "event_time_s",
    "list_devices",
    "open_source",
    "pair_times",
    "split_spec",
]
