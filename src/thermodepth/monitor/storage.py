"""Bounded storage: each rig's rolling recording of everything (when ``storage.continuous``)
and the rule that keeps the disk from filling.

``STORAGE/continuous/RIG/STAMP.zarr``: a new segment every ``segment_s``, written on a
background thread that drops rather than stalls a live rig (``RecorderSink``'s rule). A segment
that cannot be written or closed (a full disk) is told through ``on_fault`` and no segment
is tried again for :data:`RETRY_S`.

:class:`Retention` deletes, oldest first, what is older than ``retention_days`` (segments,
clips, the scheduled reports of ``STORAGE/reports/``), then, while less than ``min_free_gb``
is free, continuous segments, then clips, and only then reports (the event rows always stay;
the events of a deleted clip say so). What is being written is never deleted. (The readings'
rows go by age too: the monitor's sweep, :mod:`.store`.)
"""

from __future__ import annotations

import shutil
import threading
import time
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from ..frames import StreamEvent
from ..io.recording import Recorder, RecordingWriter
from ..sinks.base import RunContext, SessionResult, closing_attrs
from .config import StorageConfig

RETRY_S = 30.0
CLIPS, CONTINUOUS, REPORTS = "clips", "continuous", "reports"
GB = 1e9


def stamp(time_s: float) -> str:
    """A Unix time as a compact UTC stamp for names: ``20261126T143501Z``."""
    return datetime.fromtimestamp(time_s, timezone.utc).strftime("%Y%m%dT%H%M%SZ")


def fresh_path(folder: Path, name: str, suffix: str = "") -> Path:
    """``folder/name+suffix``, or with ``-2``, ``-3`` ... after the name while that exists."""
    path, n = folder / f"{name}{suffix}", 1
    while path.exists():
        n += 1
        path = folder / f"{name}-{n}{suffix}"
    return path


class ContinuousRecorder:
    """A rig's rolling recording (module docstring): ``open`` with each session's context,
    ``add`` every event, ``close`` at the session's end."""

    def __init__(self, folder: Path, segment_s: float, on_fault: Callable[[str], None]) -> None:
        self.folder, self.segment_s, self.on_fault = folder, segment_s, on_fault
        self.context: RunContext | None = None
        self.recorder: Recorder | None = None
        self.path: Path | None = None
        self._started = 0.0
        self._retry_at = 0.0
        self._closing: list[threading.Thread] = []

    def open(self, context: RunContext) -> None:
        self.context = context

    def add(self, event: StreamEvent) -> None:
        now = time.monotonic()
        if self.recorder is not None and now - self._started >= self.segment_s:
            self._finish({"stopped": "segment"})
        if self.recorder is None:
            if now < self._retry_at or self.context is None:
                return
            self._start(now)
            if self.recorder is None:  # not started (told): tried again after RETRY_S
                return
        try:
            self.recorder.add(event)
        except Exception as exc:
            self._failed(exc)

    def _start(self, now: float) -> None:
        assert self.context is not None
        source = self.context.source
        path = fresh_path(self.folder, stamp(time.time()), ".zarr")
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            writer = RecordingWriter(
                path,
                source.calibration or self.context.calibration,
                {**source.settings(), **self.context.provenance},
                source=source.name,
                device_depth=source.device_depth,
            )
        except Exception as exc:
            self._retry_at = now + RETRY_S
            self.on_fault(f"continuous recording {path.name} not started: {exc}")
            return
        self.recorder, self.path, self._started = Recorder(writer, block=False), path, now

    def _failed(self, exc: Exception) -> None:
        self.on_fault(
            f"continuous recording {self.path}: stopped ({exc}); from now until "
            f"{RETRY_S:g} s later nothing is kept of this rig but clips"
        )
        self.recorder, self._retry_at = None, time.monotonic() + RETRY_S

    def _finish(self, attrs: dict[str, Any]) -> None:
        """Close the segment on a thread of its own (its queue may take a while)."""
        recorder, path = self.recorder, self.path
        self.recorder = None
        if recorder is None:
            return

        def close() -> None:
            try:
                recorder.close(attrs)
            except Exception as exc:
                # the writer thread can fail after the segment's time is up (a slow disk, a
                # busy machine): the same pause as a failure seen by add
                self._retry_at = time.monotonic() + RETRY_S
                self.on_fault(f"continuous recording {path}: not closed cleanly ({exc})")

        thread = threading.Thread(target=close, name=f"closing {path}", daemon=True)
        thread.start()
        self._closing = [t for t in self._closing if t.is_alive()] + [thread]

    def close(self, result: SessionResult) -> None:
        self._finish(closing_attrs(result))

    def join(self, timeout_s: float = 30.0) -> None:
        for thread in self._closing:
            thread.join(timeout_s)

    @property
    def active(self) -> set[Path]:
        """The segments being written or closed."""
        return {self.path} if self.path is not None and self.recorder is not None else set()


def _started_s(path: Path) -> float | None:
    """When a segment or clip began (the UTC stamp its name starts with), Unix s."""
    try:
        when = datetime.strptime(path.name[:16], "%Y%m%dT%H%M%SZ")
    except ValueError:
        return None
    return when.replace(tzinfo=timezone.utc).timestamp()


class Retention:
    """Keeps ``config.path`` within its bounds (module docstring). ``active()``: what is
    being written (never deleted); ``clip_deleted(clip_id)``: told of each clip deleted;
    ``free_bytes``: how free space is measured (the disk's, by default)."""

    def __init__(
        self,
        config: StorageConfig,
        active: Callable[[], set[Path]],
        clip_deleted: Callable[[str], None],
        free_bytes: Callable[[Path], int] | None = None,
    ) -> None:
        self.config, self.active, self.clip_deleted = config, active, clip_deleted
        self.free_bytes = free_bytes or (lambda p: shutil.disk_usage(p).free)
        self.deleted: dict[str, int] = {CONTINUOUS: 0, CLIPS: 0, REPORTS: 0}

    def _items(self, kind: str) -> list[tuple[float, Path]]:
        """(start, path) of the segments or clips (folders, a folder per rig) or reports
        (files), oldest first."""
        root = self.config.path / kind
        found = []
        pattern, folders = ("*", False) if kind == REPORTS else ("*/*", True)
        for path in root.glob(pattern) if root.is_dir() else ():
            started = _started_s(path)
            if started is not None and path.is_dir() == folders:
                found.append((started, path))
        return sorted(found)

    def _delete(self, kind: str, path: Path) -> None:
        # the events are told first: if the store cannot take it, the clip stays for the
        # next sweep, and no event points at a clip that is gone without saying so
        if kind == CLIPS:
            self.clip_deleted(f"{path.parent.name}/{path.name}")
        if kind == REPORTS:
            path.unlink(missing_ok=True)
        else:
            shutil.rmtree(path, ignore_errors=True)
        self.deleted[kind] += 1

    def sweep(self, now_s: float | None = None) -> str | None:
        """Delete what the rule says; a line when less than ``min_free_gb`` stays free with
        nothing left to delete, else None."""
        now_s = time.time() if now_s is None else now_s
        c = self.config
        busy = self.active()
        oldest = now_s - c.retention_days * 86400.0
        queue = []
        for kind in (CONTINUOUS, CLIPS, REPORTS):
            for started, path in self._items(kind):
                if path in busy:
                    continue
                if started < oldest:
                    self._delete(kind, path)
                else:
                    queue.append((kind, path))
        need = c.min_free_gb * GB
        c.path.mkdir(parents=True, exist_ok=True)
        while self.free_bytes(c.path) < need:
            if not queue:
                free = self.free_bytes(c.path) / GB
                return (
                    f"{c.path}: {free:.2f} GB free, less than min_free_gb {c.min_free_gb:g}, "
                    "and no recording, clip or report left to delete"
                )
            kind, path = queue.pop(0)  # continuous segments first, then clips, then reports
            self._delete(kind, path)
        return None


def free_bytes(path: Path) -> int:
    """Free space on the file system of ``path`` (0: it cannot be asked)."""
    try:
        return shutil.disk_usage(path).free
    except OSError:
        return 0
