"""Replay of a recording (``recording:PATH``): the recorded FramePairs, bit for bit."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from ..frames import StreamEvent
from ..io.recording import Recording
from .base import Source


class RecordingSource(Source):
    """The pairs of a recording, in order, exactly as recorded (pixels, times, telemetry,
    indices). Frames whose chunks are corrupt are skipped with one warning each
    (``warn``) and counted in ``skipped``. The calibration is the one recorded."""

    def __init__(self, path: str | Path, warn: Callable[[str], None] | None = None) -> None:
        self.recording = Recording(path, warn)
        self.name = f"recording:{path}"
        self.calibration = self.recording.calibration
        streams = set()
        if self.recording.n_depth:
            streams.add("depth")
        if self.recording.n_thermal:
            streams.add("thermal")
        self.streams = frozenset(streams) if self.recording.n_pairs == 0 else self.streams

    @property
    def skipped(self) -> int:
        return self.recording.skipped

    def events(self) -> Iterator[StreamEvent]:
        yield from self.recording.matches()

    def settings(self) -> dict[str, Any]:
        return {"source": self.name, "recorded_settings": self.recording.settings}
