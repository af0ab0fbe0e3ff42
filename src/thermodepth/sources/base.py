"""What every source is: an iterable of FramePair with ``close()``, built on a stream of
events (stream frames as they arrive, pairs as they form) that recorders consume."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from ..calibration import Calibration
from ..errors import InputError, ThermodepthError
from ..frames import DepthFrame, FramePair, Match, StreamEvent, ThermalFrame
from .pairing import PairingStats


class DeviceLostError(ThermodepthError):
    """A camera stopped delivering frames mid-stream (unplugged, crashed)."""


class Source:
    """A source of FramePairs.

    ``for pair in source`` yields FramePairs; ``source.events()`` yields what the source
    emits in order: :class:`DepthFrame` and :class:`ThermalFrame` as they arrive (sources with
    raw streams) and :class:`Match` (a pair with its frames) as pairs form -- what a recorder
    stores. ``streams`` says which of "depth" and "thermal" the source has; ``live`` is True
    for cameras (a recorder must then drop rather than block); ``calibration`` is what the
    source knows (the device's depth intrinsics merged into the user's file, or the
    recording's); ``pairing`` holds pairing statistics where the source pairs in time.
    Use it as a context manager or call ``close()``.
    """

    name: str = "source"
    live: bool = False
    streams: frozenset[str] = frozenset({"depth", "thermal"})
    calibration: Calibration | None = None
    pairing: PairingStats | None = None

    def events(self) -> Iterator[StreamEvent]:
        raise NotImplementedError

    def __iter__(self) -> Iterator[FramePair]:
        if self.streams != {"depth", "thermal"}:
            have = " and ".join(sorted(self.streams)) or "nothing"
            raise InputError(
                f"{self.name}: gives {have} only; FramePairs need a depth and a thermal camera "
                "(use realsense+lepton, sim or recording:PATH)"
            )
        for event in self.events():
            if isinstance(event, Match):
                yield event.pair

    def close(self) -> None:
        """Release the devices or files (idempotent)."""

    def settings(self) -> dict[str, Any]:
        """What to store with a recording of this source."""
        return {"source": self.name}

    def __enter__(self) -> Source:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def event_time_s(event: StreamEvent) -> float:
    """The capture time of an event (a pair's thermal time)."""
    if isinstance(event, Match):
        return event.pair.thermal_time_s
    if isinstance(event, DepthFrame | ThermalFrame):
        return event.time_s
    raise TypeError(type(event))
