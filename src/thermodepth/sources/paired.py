"""Two cameras as one source (``realsense+lepton``): each read on its own thread, frames merged
as they arrive and paired in time by :class:`~thermodepth.sources.pairing.StreamPairer`."""

from __future__ import annotations

import contextlib
import queue
import threading
from collections.abc import Iterable, Iterator
from typing import Any, Protocol

from ..calibration import Calibration
from ..frames import DepthFrame, StreamEvent, ThermalFrame
from .base import DeviceLostError, Source
from .pairing import DEFAULT_MAX_SKEW_S, StreamPairer


class Camera(Protocol):
    """A single-stream device: iterate its frames, then close it."""

    name: str

    def __iter__(self) -> Iterator[Any]: ...

    def close(self) -> None: ...


_END = object()


class StreamSource(Source):
    """One camera alone (``realsense``, ``realsense:FILE``, ``lepton``): its frames as events
    (recordable), but no FramePairs."""

    def __init__(self, camera: Camera, stream: str, calibration: Calibration | None = None):
        self.camera = camera
        self.name = camera.name
        self.streams = frozenset({stream})
        self.live = bool(getattr(camera, "live", False))
        self.calibration = calibration

    def events(self) -> Iterator[StreamEvent]:
        yield from self.camera

    def close(self) -> None:
        self.camera.close()

    def settings(self) -> dict[str, Any]:
        return {"source": self.name, **getattr(self.camera, "settings", {})}


class PairedSource(Source):
    """A depth camera and a thermal camera paired in time.

    Each camera is read on its own thread (a blocking read of one never holds up the other);
    ``events()`` yields depth and thermal frames in arrival order and a Match whenever a pair
    forms. When a camera stops (end of a file, or unplugged: :class:`DeviceLostError`) the waiting
    thermal frames are decided, both cameras are closed, and a lost device's error is raised
    after every frame up to then has been yielded (a recorder attached keeps them all).
    """

    def __init__(
        self,
        depth: Camera,
        thermal: Camera,
        calibration: Calibration | None = None,
        max_skew_s: float = DEFAULT_MAX_SKEW_S,
    ) -> None:
        self.depth_camera = depth
        self.thermal_camera = thermal
        self.name = f"{depth.name}+{thermal.name}"
        self.live = bool(getattr(depth, "live", False) or getattr(thermal, "live", False))
        self.calibration = calibration
        self.pairer = StreamPairer(max_skew_s)
        self.pairing = self.pairer.stats
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=256)
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []

    def _reader(self, camera: Iterable[Any]) -> None:
        try:
            for frame in camera:
                if self._stop.is_set():
                    break
                self._queue.put(frame)
            self._queue.put(_END)
        except BaseException as exc:  # handed to the consumer
            self._queue.put(exc)

    def events(self) -> Iterator[StreamEvent]:
        for cam in (self.depth_camera, self.thermal_camera):
            t = threading.Thread(target=self._reader, args=(cam,), daemon=True, name=cam.name)
            t.start()
            self._threads.append(t)
        error: BaseException | None = None
        try:
            while True:
                item = self._queue.get()
                if item is _END or isinstance(item, BaseException):
                    # one stream ended: pairs can no longer form
                    error = item if isinstance(item, BaseException) else None
                    break
                yield item
                if isinstance(item, DepthFrame):
                    yield from self.pairer.add_depth(item)
                elif isinstance(item, ThermalFrame):
                    yield from self.pairer.add_thermal(item)
            yield from self.pairer.flush()
        finally:
            self.close()
        if error is not None:
            raise error

    def close(self) -> None:
        self._stop.set()
        for cam in (self.depth_camera, self.thermal_camera):
            with contextlib.suppress(Exception):  # closing a lost device may fail
                cam.close()
        while True:  # unblock readers waiting on a full queue
            try:
                self._queue.get_nowait()
            except queue.Empty:
                break

    def settings(self) -> dict[str, Any]:
        return {
            "source": self.name,
            "max_skew_s": self.pairer.max_skew_s,
            "depth": getattr(self.depth_camera, "settings", {}),
            "thermal": getattr(self.thermal_camera, "settings", {}),
        }


__all__ = ["Camera", "DeviceLostError", "PairedSource", "StreamSource"]
