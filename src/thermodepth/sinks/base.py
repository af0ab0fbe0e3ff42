"""What a sink is (:class:`Sink`): a consumer of a session, opened before any frame flows,
fed every event and fused frame, and closed in every case with how the session ended
(:class:`SessionResult`).

A sink is one small object; a session calls it and knows nothing else of it, so a new sink
touches neither the pipeline nor the session's loop. :class:`BaseSink` does nothing:
subclasses override what they consume.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

from ..calibration import Calibration
from ..frames import StreamEvent
from ..io.measurements import jsonable
from ..io.recording import RecorderStats
from ..pipeline import FusedFrame, Pipeline
from ..sources.base import Source
from ..sources.pairing import PairingStats


@dataclass(kw_only=True)
class SessionResult:
    """What every session reports: why it stopped (``"frames"``, ``"duration"``, ``"end"``
    (the source ended), ``"interrupted"`` (Ctrl-C), ``"device lost"`` or ``"error"``, with
    ``error``), the recorder's stats if it recorded, the pairing statistics (of the source's
    pairing in time; for sources that do not pair, of the pairs the session saw, with
    ``pairing_by`` saying who paired them), the source's counters (frames it skipped, by
    name; see :meth:`~thermodepth.sources.base.Source.counters`) and each sink's closing line
    for the user (``outputs``)."""

    stopped: str = "end"
    error: str | None = None
    recorder: RecorderStats | None = None
    pairing: PairingStats | None = None
    pairing_by: str | None = None
    counters: dict[str, int] = field(default_factory=dict)
    outputs: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class RunContext:
    """What a sink may need to open: the source (its name, calibration, settings, files,
    whether it is live), the calibration frames are fused with (None when only recording),
    the pipeline's settings, and ``provenance``: what a recording stores of the run's
    settings (the settings file's text, the compensation model's hash)."""

    source: Source
    calibration: Calibration | None = None
    pipeline: Pipeline | None = None
    provenance: dict[str, Any] = field(default_factory=dict)


class Sink(Protocol):
    """A consumer of a session (see the module docstring). ``check`` refuses, before any
    camera starts, what ``open`` would refuse (an output that exists); ``open`` before any
    frame (it may still refuse with an InputError: nothing has flowed); ``event`` for every
    event the source emits (raw frames and pairs, in order); ``frame`` for every fused frame
    (runs only); ``close`` once, in every case, with how the session ended; ``summary`` a
    line for the user at the end (None: nothing to say)."""

    def check(self) -> None: ...

    def open(self, context: RunContext) -> None: ...

    def event(self, event: StreamEvent) -> None: ...

    def frame(self, fused: FusedFrame) -> None: ...

    def close(self, result: SessionResult) -> None: ...

    def summary(self) -> str | None: ...


class BaseSink:
    """A sink that does nothing: subclasses override what they consume."""

    def check(self) -> None:
        """Nothing to refuse."""

    def open(self, context: RunContext) -> None:
        """Nothing to open."""

    def event(self, event: StreamEvent) -> None:
        """Raw events are not wanted."""

    def frame(self, fused: FusedFrame) -> None:
        """Fused frames are not wanted."""

    def close(self, result: SessionResult) -> None:
        """Nothing to close."""

    def summary(self) -> str | None:
        return None


def closing_attrs(result: SessionResult) -> dict[str, Any]:
    """The attributes a recording is closed with: ``stopped`` (and ``error``), ``pairing``
    (pairs, drops, skew in ms) where the source pairs in time, and ``source_counters``."""
    attrs: dict[str, Any] = {"stopped": result.stopped, "source_counters": dict(result.counters)}
    if result.error is not None:
        attrs["error"] = result.error
    p = result.pairing
    if p is not None and result.pairing_by is None:
        attrs["pairing"] = jsonable(
            {
                "pairs": p.pairs,
                "dropped": p.dropped,
                "thermal_frames": p.thermal_frames,
                "depth_frames": p.depth_frames,
                "median_abs_skew_ms": p.median_abs_skew_ms,
                "max_abs_skew_ms": p.max_abs_skew_ms,
            }
        )
    return attrs
