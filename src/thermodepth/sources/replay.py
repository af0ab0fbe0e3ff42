"""Replay of a recording (``recording:PATH``): the recorded FramePairs, bit for bit."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from ..calibration import Calibration
from ..frames import DepthFrame, Match, StreamEvent
from ..io.recording import Recording
from .base import Source, with_device_depth
from .pairing import DEFAULT_MAX_SKEW_S, StreamPairer


class RecordingSource(Source):
    """The pairs of a recording, in order, exactly as recorded (pixels, times, telemetry,
    indices). Frames whose chunks are corrupt are skipped with one warning each (``warn``)
    and counted (``skipped``, ``counters()["replay_skipped"]``).

    The calibration is the one recorded; a recording made without one takes the user's
    ``calibration`` with the depth section replaced by the device's intrinsics and depth unit
    the recording holds (``device_depth``), or the user's as it is when it holds none.
    A recording whose recorder dropped events (a live run the writer could not keep up with)
    is replayed as recorded, with one warning saying so: its pairs are not all the pairs the
    live run saw. A recording of both cameras whose pairs table is lost (or was never
    written: the recorder killed before its first pair) has its frames paired again by time,
    as the live source pairs them (``max_skew_s`` as recorded, else the default), with one
    warning saying so.
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
        self.paired_by = "the recorded run"
        self.pairer: StreamPairer | None = None
        if self.streams == {"depth", "thermal"} and not self.recording.n_pairs:
            skew = self.recording.settings.get("max_skew_s", DEFAULT_MAX_SKEW_S)
            self.pairer = StreamPairer(float(skew))
            self.pairing = self.pairer.stats
            self.recording.warn(
                f"{path}: no pairs table, though it holds {self.recording.n_depth} depth and "
                f"{self.recording.n_thermal} thermal frames: paired again by time (max skew "
                f"{1000 * self.pairer.max_skew_s:g} ms); the pairs may differ from the live run's"
            )
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
        elif self.pairer is None:  # a recording of one camera: its frames
            yield from self.recording.frames()
        else:
            yield from self._paired_again(self.pairer)

    def _paired_again(self, pairer: StreamPairer) -> Iterator[StreamEvent]:
        """The frames in time order, each followed by the pairs it completes."""
        matches: list[Match]
        for frame in self.recording.frames():
            yield frame
            if isinstance(frame, DepthFrame):
                matches = pairer.add_depth(frame)
            else:
                matches = pairer.add_thermal(frame)
            yield from matches
        yield from pairer.flush()

    def settings(self) -> dict[str, Any]:
        return {"source": self.name, "recorded_settings": self.recording.settings}
