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
    forms. When a camera stops (end of a file, or unplugged: :class:`DeviceLostError`) the
    other one is read on until its frames are too late to pair with the stopped one's last
    frame, the waiting thermal frames are decided, both cameras are closed, and a lost
    device's error is raised after every frame up to then has been yielded (a recorder
    attached keeps them all). history_s: depth kept before the first thermal frame arrives
    (see :class:`StreamPairer`).
    """

    def __init__(
        self,
        depth: Camera,
        thermal: Camera,
        calibration: Calibration | None = None,
        max_skew_s: float = DEFAULT_MAX_SKEW_S,
        history_s: float = 2.0,
    ) -> None:
        self.depth_camera = depth
        self.thermal_camera = thermal
        self.name = f"{depth.name}+{thermal.name}"
        self.live = bool(getattr(depth, "live", False) or getattr(thermal, "live", False))
        self.calibration = calibration
        self.pairer = StreamPairer(max_skew_s, history_s)
        self.pairing = self.pairer.stats
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=256)
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []

    def _reader(self, key: str, camera: Iterable[Any]) -> None:
        try:
            for frame in camera:
                if self._stop.is_set():
                    break
                self._queue.put(frame)
            self._queue.put((key, _END))
        except BaseException as exc:  # handed to the consumer
            self._queue.put((key, exc))

    def events(self) -> Iterator[StreamEvent]:
        for key, cam in (("depth", self.depth_camera), ("thermal", self.thermal_camera)):
            t = threading.Thread(target=self._reader, args=(key, cam), daemon=True, name=key)
            t.start()
            self._threads.append(t)
        error: BaseException | None = None
        last = {"depth": float("-inf"), "thermal": float("-inf")}
        limit = float("inf")  # once a stream has ended: the last time a pair can use
        running = 2
        try:
            while running:
                item = self._queue.get()
                if isinstance(item, tuple):  # a stream ended (its end, or its error)
                    key, why = item
                    running -= 1
                    if isinstance(why, BaseException) and error is None:
                        error = why
                    limit = min(limit, last[key] + self.pairer.max_skew_s)
                    continue
                if item.time_s > limit:
                    break  # the other stream ended: nothing later can be paired
                last["depth" if isinstance(item, DepthFrame) else "thermal"] = item.time_s
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
