"""The recorder as a sink: every event a source emits (raw frames and pairs) into a
crash-safe recording (:mod:`thermodepth.io.recording`), on a background thread."""

from __future__ import annotations

from pathlib import Path

from ..frames import StreamEvent
from ..io.recording import (
    DEFAULT_CODEC,
    Recorder,
    RecorderStats,
    RecordingWriter,
    check_output,
)
from .base import BaseSink, RunContext, SessionResult, closing_attrs


class RecorderSink(BaseSink):
    """Records the session's source at ``out`` (a new recording; ``overwrite`` replaces a
    recording and nothing else).

    The recording stores the source's calibration (else the one frames are fused with, else
    the user's), the source's settings with the run's provenance, and the depth camera's own
    intrinsics where the source has them; ``depth_frames``: all of them or only the
    ``"paired"`` ones (:class:`~thermodepth.io.recording.RecordingWriter`). It blocks for
    files and the simulator (nothing dropped) and drops for live cameras (never stalls them).
    It refuses to write over a path the source reads. Closed with why the session stopped,
    the pairing statistics and the source's counters (:func:`~thermodepth.session.closing_attrs`).
    """

    def __init__(
        self,
        out: str | Path,
        overwrite: bool = False,
        depth_frames: str = "all",
        codec: str = DEFAULT_CODEC,
    ) -> None:
        self.out = Path(out)
        self.overwrite = overwrite
        self.depth_frames = depth_frames
        self.codec = codec
        self.recorder: Recorder | None = None

    @property
    def stats(self) -> RecorderStats:
        """What was written and dropped (empty before ``open``)."""
        return self.recorder.stats if self.recorder is not None else RecorderStats()

    def check(self) -> None:
        check_output(self.out, self.overwrite)

    def open(self, context: RunContext) -> None:
        source = context.source
        if self.depth_frames == "paired":
            source.require_pairs()  # else nothing pairs, and no depth frame is kept
        writer = RecordingWriter(
            self.out,
            source.calibration or context.calibration,
            {**source.settings(), **context.provenance},
            source=source.name,
            overwrite=self.overwrite,
            inputs=source.files,
            device_depth=source.device_depth,
            depth_frames=self.depth_frames,
            codec=self.codec,
        )
        self.recorder = Recorder(writer, block=not source.live)

    def event(self, event: StreamEvent) -> None:
        assert self.recorder is not None, "open the sink first"
        self.recorder.add(event)

    def close(self, result: SessionResult) -> None:
        if self.recorder is not None:
            self.recorder.close(closing_attrs(result))

    def summary(self) -> str:
        return f"recorded to {self.out}: {self.stats.summary()}"
