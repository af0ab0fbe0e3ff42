"""Replay of a recording (``recording:PATH``): the recorded FramePairs, bit for bit."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from ..calibration import Calibration
from ..frames import StreamEvent
from ..io.recording import Recording
from .base import Source, with_device_depth


class RecordingSource(Source):
    """The pairs of a recording, in order, exactly as recorded (pixels, times, telemetry,
    indices). Frames whose chunks are corrupt are skipped with one warning each (``warn``)
    and counted (``skipped``, ``counters()["replay_skipped"]``).

    The calibration is the one recorded; a recording made without one takes the user's
    ``calibration`` with the depth section replaced by the device's intrinsics and depth unit
    the recording holds (``device_depth``), or the user's as it is when it holds none.
    A recording whose recorder dropped events (a live run the writer could not keep up with)
    is replayed as recorded, with one warning saying so: its pairs are not all the pairs the
    live run saw.
    """

    def __init__(
        self,
        path: str | Path,
        warn: Callable[[str], None] | None = None,
        calibration: Calibration | None = None,
    ) -> None:
        self.recording = Recording(path, warn)
        self.name = f"recording:{path}"
        self.files = (Path(path),)
        self.device_depth = self.recording.device_depth
        self.calibration = (
            self.recording.calibration
            or with_device_depth(calibration, self.device_depth, f"{path} (device_depth)")
            or calibration
        )
        streams = set()
        if self.recording.n_depth:
            streams.add("depth")
        if self.recording.n_thermal:
            streams.add("thermal")
        self.streams = frozenset(streams) if self.recording.n_pairs == 0 else self.streams
        dropped = self.recording.dropped
        if sum(dropped.values()):
            self.recording.warn(
                f"{path}: the recorder dropped {sum(dropped.values())} events while recording ("
                + ", ".join(f"{k} {v}" for k, v in dropped.items())
                + "): the replay gives the pairs recorded, not every pair the live run saw"
            )

    @property
    def skipped(self) -> int:
        return self.recording.skipped

    def counters(self) -> dict[str, int]:
        return {"replay_skipped": self.recording.skipped}

    def events(self) -> Iterator[StreamEvent]:
        if self.recording.n_pairs:
            yield from self.recording.matches()
        else:  # a recording of one camera: its frames
            yield from self.recording.frames()

    def settings(self) -> dict[str, Any]:
        return {"source": self.name, "recorded_settings": self.recording.settings}
