"""``thermodepth capture-board``: board pairs for calibration, taken from the rig's stream."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..board import BoardSpec
from ..calibrate.capture import BoardCapture
from ..calibration import CameraSchema, intrinsics_of
from ..camera import Intrinsics
from ..errors import InputError, check_count
from ..progress import SILENT, Reporter
from ..session import stopping
from ..sinks import SessionResult
from ..sources.base import Source
from ..sources.pairing import DEFAULT_MAX_SKEW_S
from .run import Warn, check_source, open_choice


@dataclass(frozen=True)
class CaptureOptions:
    """Where pairs come from and where they go.

    source: a source with both cameras and the IR image (``realsense+lepton``, or a
    recording made with ``--ir``); out_dir: the folder of pairs (numbering continues after
    pairs already there); square_m, board: the board; count: stop after so many pairs
    kept; max_skew_s, thermal_latency_s: pairing of live cameras (s); depth_mode,
    thermal_camera: the cameras (:class:`~.run.SourceChoice`).
    """

    source: str
    out_dir: Path
    square_m: float
    board: str = "checkerboard:9x6"
    count: int = 25
    max_skew_s: float = DEFAULT_MAX_SKEW_S
    thermal_latency_s: float = 0.0
    depth_mode: str | None = None
    thermal_camera: str | None = None


@dataclass(kw_only=True)
class CaptureResult(SessionResult):
    """How a capture went (:class:`~thermodepth.sinks.SessionResult`; stopped ``"count"``
    when enough pairs were kept): the pairs kept (file stems), pairs examined, the thermal
    image's coverage by the kept pairs' corners, and how many pairs each verdict had."""

    kept: list[Path] = field(default_factory=list)
    examined: int = 0
    coverage: float = 0.0
    verdicts: dict[str, int] = field(default_factory=dict)


def _ir_intrinsics(src: Source) -> Intrinsics | None:
    """The depth camera's intrinsics the source knows (the device's, else a calibration's)."""
    if src.device_depth is not None:
        section = {k: v for k, v in src.device_depth.items() if k != "depth_scale_m"}
        return intrinsics_of(CameraSchema.model_validate(section))
    return src.calibration.depth if src.calibration is not None else None


def capture_board(
    options: CaptureOptions, reporter: Reporter = SILENT, warn: Warn | None = None
) -> CaptureResult:
    """Watch a source and keep the pairs worth calibrating with
    (:class:`~thermodepth.calibrate.capture.BoardCapture`), until ``count`` are kept, the
    source ends, Ctrl-C or a lost device; every kept pair is on disk as soon as it is kept.
    """
    o = options
    check_count("count", o.count)
    check_source(o)
    spec = BoardSpec.parse(o.board, o.square_m)
    if o.out_dir.exists() and not o.out_dir.is_dir():
        raise InputError(f"{o.out_dir}: not a folder (pairs go into a folder)")
    src = open_choice(o, None, warn, with_ir=True)
    result = CaptureResult(pairing=src.pairing)
    try:
        capture = BoardCapture(spec, o.out_dir, _ir_intrinsics(src))
        with reporter.task("capturing board pairs", o.count) as advance, stopping(result):
            for pair in src.pairs():
                if pair.ir is None:
                    raise InputError(
                        f"{src.name}: no infrared image with the depth frames (live: the IR "
                        "stream is asked for; a recording needs record --ir)"
                    )
                verdict = capture.offer(pair.ir, pair.thermal, pair.telemetry.in_ffc)
                result.examined += 1
                advance(
                    int(verdict.kept),
                    description=f"board pairs: coverage {capture.coverage:.0%}, "
                    f"last: {verdict.reason}",
                )
                if len(capture.kept) >= o.count:
                    result.stopped = "count"
                    break
    finally:
        src.close()
        result.counters = src.counters()
    result.kept, result.coverage = capture.kept, capture.coverage
    result.verdicts = dict(capture.verdicts)
    return result


def verdict_lines(result: CaptureResult) -> list[str]:
    """How many pairs each verdict had, most first."""
    return [f"{n} {why}" for why, n in sorted(result.verdicts.items(), key=lambda kv: -kv[1])]
