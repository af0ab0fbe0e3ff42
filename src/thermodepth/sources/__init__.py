"""Sources of FramePairs: the simulated rig, real cameras, recordings; pairing in time.

:func:`open_source` turns a spec into a :class:`Source`:

==========================  ===============================================================
spec                        what
==========================  ===============================================================
``sim``                     the simulated rig (plate + 70 C chip at 1 m)
``realsense[:SERIAL]``      a live RealSense (depth only: recordable, no pairs)
``realsense:FILE.bag|db3``  a RealSense recording played back (depth only)
``lepton[:INDEX]``          a Lepton 3 on a PureThermal, /dev/videoINDEX (thermal only)
``realsense+lepton``        both cameras paired in time; each part takes its options, e.g.
                            ``realsense:123456+lepton:2``
``recording:PATH``          a thermodepth recording (zarr), replayed bit for bit
==========================  ===============================================================

Every source yields :class:`~thermodepth.frames.FramePair` when iterated (if it has both
streams) and :class:`~thermodepth.frames.StreamEvent` from ``events()`` (what recorders store).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..calibration import Calibration
from ..errors import InputError
from .base import DeviceLostError, Source, event_time_s
from .pairing import DEFAULT_MAX_SKEW_S, PairingStats, StreamPairer, pair_times

SPEC_HELP = (
    "sim, realsense[:SERIAL|:FILE.bag|:FILE.db3], lepton[:INDEX], realsense+lepton, recording:PATH"
)


def _realsense(arg: str, calibration: Calibration | None, with_ir: bool) -> Any:
    from .realsense import PLAYBACK_EXTENSIONS, RealSenseCamera

    if arg and Path(arg).suffix.lower() in PLAYBACK_EXTENSIONS:
        return RealSenseCamera(path=arg, with_ir=with_ir)
    if arg and not arg.isalnum():
        raise InputError(f"realsense:{arg}: expected a serial number or a .bag/.db3 file")
    return RealSenseCamera(serial=arg or None, with_ir=with_ir)


def _lepton(arg: str) -> Any:
    from .lepton import LeptonCamera

    if arg and not arg.isdigit():
        raise InputError(f"lepton:{arg}: expected a video device number (lepton:0 = /dev/video0)")
    return LeptonCamera(int(arg) if arg else None)


def _with_device_depth(camera: Any, calibration: Calibration | None) -> Calibration | None:
    if calibration is None:
        return None
    from .realsense import depth_calibration

    return depth_calibration(calibration, camera.intrinsics, camera.depth_scale_m)


def open_source(
    spec: str,
    calibration: Calibration | None = None,
    *,
    frames: int | None = None,
    max_skew_s: float = DEFAULT_MAX_SKEW_S,
    with_ir: bool = False,
    warn: Callable[[str], None] | None = None,
) -> Source:
    """Open the source a spec names (table above); bad specs and missing devices raise a
    one-line InputError.

    calibration: the user's calibration (thermal intrinsics, extrinsics); RealSense sources
    replace its depth section with the device's intrinsics and depth unit. frames: for
    ``sim``, how many pairs (None: endless). max_skew_s: the pairing threshold of
    ``realsense+lepton``. with_ir: also read the depth camera's infrared image.
    warn: where a recording's skipped-frame warnings go.
    """
    from .paired import PairedSource, StreamSource

    text = spec.strip()
    kind, _, arg = text.partition(":")
    if "+" in text and not kind.startswith("recording"):
        parts = text.split("+")
        kinds = [p.partition(":")[0] for p in parts]
        if len(parts) != 2 or kinds != ["realsense", "lepton"]:
            raise InputError(f"--source: cannot combine {text!r}; expected realsense+lepton")
        depth_cam = _realsense(parts[0].partition(":")[2], calibration, with_ir)
        try:
            thermal_cam = _lepton(parts[1].partition(":")[2])
        except BaseException:
            depth_cam.close()
            raise
        return PairedSource(
            depth_cam, thermal_cam, _with_device_depth(depth_cam, calibration), max_skew_s
        )
    if kind == "sim":
        if arg:
            raise InputError(f"--source: 'sim' takes no argument, got {text!r}")
        from .sim import SimSource

        src = SimSource(frames=frames)
        if with_ir:
            src.rig.with_ir = True
        return src
    if kind == "recording":
        if not arg:
            raise InputError("--source: recording:PATH needs a path")
        from .replay import RecordingSource

        return RecordingSource(arg, warn)
    if kind == "realsense":
        cam = _realsense(arg, calibration, with_ir)
        return StreamSource(cam, "depth", _with_device_depth(cam, calibration))
    if kind == "lepton":
        return StreamSource(_lepton(arg), "thermal", calibration)
    raise InputError(f"--source: unknown {text!r}; expected one of {SPEC_HELP}")


def list_devices() -> dict[str, list[dict[str, Any]]]:
    """What is attached: ``{"realsense": [...], "purethermal": [...], "video": [...]}``."""
    from .lepton import list_purethermal, list_video_devices
    from .realsense import list_realsense

    return {
        "realsense": list_realsense(),
        "purethermal": list_purethermal(),
        "video": list_video_devices(),
    }


__all__ = [
    "DEFAULT_MAX_SKEW_S",
    "SPEC_HELP",
    "DeviceLostError",
    "PairingStats",
    "Source",
    "StreamPairer",
    "event_time_s",
    "list_devices",
    "open_source",
    "pair_times",
]
