"""Two cameras as one source (``realsense+lepton``): each read on its own thread, frames merged
as they arrive and paired in time by :class:`~thermodepth.sources.pairing.StreamPairer`."""

from __future__ import annotations

import contextlib
import queue
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Protocol

from ..calibration import Calibration
from ..frames import DepthFrame, StreamEvent, ThermalFrame
from .base import DeviceLostError, Source
from .pairing import DEFAULT_MAX_SKEW_S, StreamPairer


class Camera(Protocol):
    """A single-stream device: iterate its frames, then close it. Optional attributes the
    sources use: ``live``, ``settings`` (a mapping), ``counters()``, ``recover()``,
    ``device_depth``, ``path`` (a file played back)."""

    name: str

    def __iter__(self) -> Iterator[Any]: ...

    def close(self) -> None: ...


_END = object()


def _camera_counters(camera: Camera) -> dict[str, int]:
    counters = getattr(camera, "counters", None)
    return dict(counters()) if callable(counters) else {}


def _recover(*cameras: Camera) -> str | None:
    """What the cameras that can revive a stalled device did (their ``recover()`` lines)."""
    done = [line for c in cameras if callable(r := getattr(c, "recover", None)) and (line := r())]
    return "; ".join(done) or None


def _camera_files(camera: Camera) -> tuple[Path, ...]:
    path = getattr(camera, "path", None)
    return (Path(path),) if path is not None else ()


class StreamSource(Source):
    """One camera alone (``realsense``, ``realsense:FILE``, ``lepton``): its frames as events
    (recordable), but no FramePairs."""

    def __init__(self, camera: Camera, stream: str, calibration: Calibration | None = None):
        self.camera = camera
        self.name = camera.name
        self.streams = frozenset({stream})
        self.live = bool(getattr(camera, "live", False))
        self.calibration = calibration
        self.files = _camera_files(camera)
        self.device_depth = getattr(camera, "device_depth", None)

    def events(self) -> Iterator[StreamEvent]:
        yield from self.camera

    def close(self) -> None:
        self.camera.close()

    def settings(self) -> dict[str, Any]:
        return {"source": self.name, **getattr(self.camera, "settings", {})}

    def counters(self) -> dict[str, int]:
        return _camera_counters(self.camera)

    def recover(self) -> str | None:
        return _recover(self.camera)


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

    Closing (``close()``, from the consumer's thread: the end, Ctrl-C, a lost device) only
    tells the reader threads to stop and waits up to ``join_timeout_s`` for each; every
    reader closes its own camera on its own thread when it stops, so a camera is never
    released under a blocking read. A reader still inside a read after the timeout closes its
    camera when that read returns.
    """

    def __init__(
        self,
        depth: Camera,
        thermal: Camera,
        calibration: Calibration | None = None,
        max_skew_s: float = DEFAULT_MAX_SKEW_S,
        history_s: float = 2.0,
        join_timeout_s: float = 3.0,
    ) -> None:
        self.depth_camera = depth
        self.thermal_camera = thermal
        self.name = f"{depth.name}+{thermal.name}"
        self.live = bool(getattr(depth, "live", False) or getattr(thermal, "live", False))
        self.calibration = calibration
        self.files = _camera_files(depth) + _camera_files(thermal)
        self.device_depth = getattr(depth, "device_depth", None)
        self.pairer = StreamPairer(max_skew_s, history_s)
        self.pairing = self.pairer.stats
        self.join_timeout_s = join_timeout_s
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=256)
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []

    def _offer(self, item: Any) -> bool:
        """Queue an item for the consumer; False (not queued) once the source is stopping."""
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def _reader(self, key: str, camera: Camera) -> None:
        try:
            for frame in camera:
                if self._stop.is_set() or not self._offer(frame):
                    break
            self._offer((key, _END))
        except BaseException as exc:  # handed to the consumer
            self._offer((key, exc))
        finally:
            with contextlib.suppress(Exception):  # closing a lost device may fail
                camera.close()

    def events(self) -> Iterator[StreamEvent]:
        for key, cam in (("depth", self.depth_camera), ("thermal", self.thermal_camera)):
            t = threading.Thread(target=self._reader, args=(key, cam), daemon=True, name=key)
            self._threads.append(t)
            t.start()
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
        """Stop the readers and wait for them (see the class docstring); cameras that were
        never read are closed here."""
        self._stop.set()
        if not self._threads:
            for cam in (self.depth_camera, self.thermal_camera):
                with contextlib.suppress(Exception):
                    cam.close()
            return
        for t in self._threads:
            if t is not threading.current_thread():
                t.join(self.join_timeout_s)

    def settings(self) -> dict[str, Any]:
        return {
            "source": self.name,
            "max_skew_s": self.pairer.max_skew_s,
            "depth": getattr(self.depth_camera, "settings", {}),
            "thermal": getattr(self.thermal_camera, "settings", {}),
        }

    def counters(self) -> dict[str, int]:
        return {**_camera_counters(self.depth_camera), **_camera_counters(self.thermal_camera)}

    def recover(self) -> str | None:
        return _recover(self.depth_camera, self.thermal_camera)


__all__ = ["Camera", "DeviceLostError", "PairedSource", "StreamSource"]
