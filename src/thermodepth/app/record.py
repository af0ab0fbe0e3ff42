"""``thermodepth record``: a source into a crash-safe recording."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..calibration import Calibration
from ..errors import FieldError, check_count
from ..io.recording import DEFAULT_CODEC, check_output, check_storage
from ..progress import SILENT, Reporter
from ..session import RecordResult, record_session
from ..sources.pairing import DEFAULT_MAX_SKEW_S
from .run import Warn, check_source, never_ends, open_choice


@dataclass(frozen=True)
class RecordOptions:
    """What to record and where.

    source: a source spec; out: the recording to create (``.zarr``); duration_s: stop after
    so many seconds of source time; frames: after so many pairs (a single camera's frames);
    calibration: a calibration file to store (a RealSense's own depth intrinsics replace its
    depth section; sim and recordings keep theirs); max_skew_s, thermal_latency_s: pairing of
    live cameras (s); with_ir: also the infrared image; overwrite: replace an existing
    recording (nothing else is replaced); depth_frames: keep ``"all"`` the depth frames or
    only those ``"paired"`` with a thermal frame (3.4x fewer at 30 + 8.7 fps; needs both
    cameras); codec: the images' (``lz4``, fast; ``zstd``, smaller); depth_mode,
    thermal_camera: the cameras (:class:`~.run.SourceChoice`).
    """

    source: str
    out: Path
    duration_s: float | None = None
    frames: int | None = None
    calibration: Path | None = None
    max_skew_s: float = DEFAULT_MAX_SKEW_S
    thermal_latency_s: float = 0.0
    with_ir: bool = False
    overwrite: bool = False
    depth_frames: str = "all"
    codec: str = DEFAULT_CODEC
    depth_mode: str | None = None
    thermal_camera: str | None = None

    def check(self) -> None:
        """One FieldError for an option that cannot be (a simulator with no end included)."""
        if self.duration_s is not None and not self.duration_s > 0:
            raise FieldError("duration_s", "must be > 0 seconds")
        check_count("frames", self.frames)
        if self.duration_s is None and self.frames is None and never_ends(self.source):
            raise FieldError("source", "sim never ends: give frames or a duration")
        check_source(self)
        check_storage(self.depth_frames, self.codec)


def record(
    options: RecordOptions, reporter: Reporter = SILENT, warn: Warn | None = None
) -> RecordResult:
    """Check the options and the output (before any camera starts), open the source and
    record it (:func:`~thermodepth.session.record_session`: closed cleanly in every case)."""
    options.check()
    check_output(options.out, options.overwrite)
    cal = Calibration.load(options.calibration) if options.calibration else None
    src = open_choice(options, cal, warn, with_ir=options.with_ir, pairs=False)
    return record_session(
        src,
        options.out,
        duration_s=options.duration_s,
        frames=options.frames,
        calibration=cal,
        overwrite=options.overwrite,
        reporter=reporter,
        depth_frames=options.depth_frames,
        codec=options.codec,
    )
