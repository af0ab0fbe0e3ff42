"""What every source is: an iterable of FramePair with ``close()``, built on a stream of
events (stream frames as they arrive, pairs as they form) that recorders consume."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ..calibration import Calibration
from ..errors import InputError, ThermodepthError
from ..frames import DepthFrame, FramePair, Match, StreamEvent, ThermalFrame
from ..trajectory import Trajectory
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
    recording's); ``pairing`` holds pairing statistics where the source pairs in time;
    ``files`` are the files or directories it reads (a recording must not be written over
    them); ``device_depth`` is the depth camera's own intrinsics and depth unit as a
    calibration file's ``depth`` section (pixels, metres per count), where the source knows
    them. ``counters()`` counts what the source skipped (frames without telemetry, ...).
    ``paired_by`` says who paired the frames of a source that does not pair them in time
    itself (the simulator, a recording's live run). Use it as a context manager or call
    ``close()``.
    """

    name: str = "source"
    paired_by: str | None = None
    live: bool = False
    streams: frozenset[str] = frozenset({"depth", "thermal"})
    calibration: Calibration | None = None
    pairing: PairingStats | None = None
    files: tuple[Path, ...] = ()
    device_depth: dict[str, Any] | None = None

    def events(self) -> Iterator[StreamEvent]:
        raise NotImplementedError

    def require_pairs(self) -> None:
        """Raise a one-line InputError unless the source has both streams (can give pairs)."""
        if not self.streams:  # e.g. a recording whose writer was stopped before its first frame
            raise InputError(f"{self.name}: holds no frames: nothing to pair")
        if self.streams != {"depth", "thermal"}:
            have = " and ".join(sorted(self.streams))
            raise InputError(
                f"{self.name}: gives {have} only; FramePairs need a depth and a thermal camera "
                "(use realsense+lepton, sim or recording:PATH)"
            )

    def pairs(self, on_event: Callable[[StreamEvent], None] | None = None) -> Iterator[FramePair]:
        """The FramePairs of the stream; ``on_event`` sees every event first (a recorder's
        ``add``: raw frames included). A source without pairs is refused
        (:meth:`require_pairs`)."""
        self.require_pairs()
        for event in self.events():
            if on_event is not None:
                on_event(event)
            if isinstance(event, Match):
                yield event.pair

    def trajectory(self) -> tuple[Trajectory, str] | None:
        """The depth camera's poses over time where the source knows them (a bag's ``/tf``),
        with one line saying whence; None: it does not."""
        return None

    def __iter__(self) -> Iterator[FramePair]:
        return self.pairs()

    def close(self) -> None:
        """Release the devices or files (idempotent)."""

    def settings(self) -> dict[str, Any]:
        """What to store with a recording of this source."""
        return {"source": self.name}

    def counters(self) -> dict[str, int]:
        """What the source skipped so far, by name (e.g. ``thermal_bad_telemetry``)."""
        return {}

    def recover(self) -> str | None:
        """Try to revive a device that stalled, once the source is closed and before it is
        opened again (a USB reset of a thermal camera over UVC); a line saying what was done
        or why it could not be, None when there is nothing to do."""
        return None

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


def with_device_depth(
    user: Calibration | None, device_depth: dict[str, Any] | None, where: str
) -> Calibration | None:
    """The user's calibration with its depth section replaced by the device's (``None`` when
    either is missing). The thermal intrinsics and ``thermal_from_depth`` come from the user's
    file; a depth image size that differs from the file's is allowed (the device's wins: it
    describes the stream actually delivered). ``where`` names the device in errors."""
    if user is None or device_depth is None:
        return None
    return Calibration.from_dict({**user.to_dict(), "depth": device_depth}, source=where)


class DeviceGuard:
    """Releases a device exactly once, and never while a read is in progress on it.

    The thread that reads the device wraps each blocking read in ``with guard.reading() as
    open_:`` (``open_`` False: the device was closed, stop reading) and calls ``release()``
    when it stops. ``close()`` may come from any thread (Ctrl-C, the other camera lost): it
    marks the device closed and releases it at once unless a read is in progress, in which
    case the reader releases it as soon as its read returns. (OpenCV and librealsense release
    the GIL in their blocking reads: releasing the device under a read is a use-after-free.)
    """

    def __init__(self, release: Callable[[], None]) -> None:
        self._release = release
        self._lock = threading.Lock()
        self.closed = False
        self.released = False

    @contextmanager
    def reading(self) -> Iterator[bool]:
        with self._lock:
            yield not self.closed

    def close(self) -> None:
        self.closed = True
        if self._lock.acquire(blocking=False):
            try:
                self._release_once()
            finally:
                self._lock.release()

    def release(self) -> None:
        """Release now (from the reading thread, or when nothing reads the device)."""
        self.closed = True
        with self._lock:
            self._release_once()

    def _release_once(self) -> None:
        if not self.released:
            self.released = True
            self._release()
