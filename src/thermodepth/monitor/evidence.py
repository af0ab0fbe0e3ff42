"""The evidence of an event: a clip of the raw pairs from ``pre_s`` before it to ``post_s``
after, as an ordinary recording (``run --source recording:`` and ``view`` replay it), and the
overlay PNG and PLY point cloud of the frame that raised it, in
``STORAGE/clips/RIG/YYYYmmddTHHMMSSZ-RULE/`` (``clip.zarr``, ``overlay.png``, ``frame.ply``).

The seconds before an event come from each rig's pre-trigger buffer (:class:`PreTrigger`):
its last pairs compressed in memory (Blosc LZ4), bounded by seconds and by bytes. An event
while a rig's clip is still being recorded extends that clip (one clip, both events) up to
``clip_max_s`` long; past that the clip ends and a new one begins. Each
clip is written on its own thread and the pictures on one shared thread, so that a slow disk
or a slow plot never holds up a rig. What waits for them is bounded in bytes
(:class:`~.bounded.ByteQueue`): a clip's pairs :data:`CLIP_QUEUE_BYTES`, the pictures
:data:`PICTURES_BYTES`; a pair past the bound is left out of its clip and counted (the
clip's ``frames_not_kept``), a picture past it is not drawn (``pictures_skipped``). What
cannot be kept (a full disk, a full queue) is told through ``on_fault``.
"""

from __future__ import annotations

import os
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numcodecs import Blosc

from ..figures import alarm_rois
from ..frames import DepthFrame, FramePair, Match, Telemetry, ThermalFrame
from ..io.pointcloud import write_ply
from ..io.recording import RecordingWriter
from ..pipeline import FusedFrame
from ..sinks.base import RunContext
from .bounded import MB, ByteQueue, nbytes_of
from .live import encode, framed, overlay_image
from .logs import logger
from .storage import fresh_path, stamp
from .workers import Worker

_CODEC = Blosc("lz4", 5, Blosc.SHUFFLE)
Packed = tuple[bytes, tuple[int, ...], str]
_END = object()
CLIP_QUEUE_BYTES = 64 * MB
"""A clip's pairs waiting for the disk, at most: 34 pairs of 1280x720 depth and a Lepton 3's
counts (4 s of a rig), where 256 pairs (480 MB) were let wait before."""
PICTURES_BYTES = 64 * MB
"""The frames waiting to be drawn as an overlay and a point cloud (each takes about a
second), at most: 9 fused 1280x720 frames with their depth grid (6.7 MB each)."""
PAINTER_LIMIT_S = 60.0


def _pack(a: np.ndarray | None) -> Packed | None:
    if a is None:
        return None
    a = np.ascontiguousarray(a)
    return _CODEC.encode(a), a.shape, a.dtype.str


def _unpack(p: Packed | None) -> Any:
    if p is None:
        return None
    data, shape, dtype = p
    return np.frombuffer(_CODEC.decode(data), dtype=dtype).reshape(shape)


@dataclass(frozen=True)
class PackedMatch:
    """A Match with its images compressed (:meth:`unpack` gives it back, bit for bit)."""

    depth: Packed
    thermal: Packed
    ir: Packed | None
    preview: Packed | None
    depth_time_s: float
    depth_index: int
    thermal_time_s: float
    thermal_index: int
    telemetry: Telemetry
    index: int

    @classmethod
    def of(cls, m: Match) -> PackedMatch:
        depth, thermal = _pack(m.depth.depth), _pack(m.thermal.counts)
        assert depth is not None and thermal is not None
        return cls(
            depth,
            thermal,
            _pack(m.depth.ir),
            _pack(m.thermal.preview),
            m.depth.time_s,
            m.depth.index,
            m.thermal.time_s,
            m.thermal.index,
            m.thermal.telemetry,
            m.pair.index,
        )

    @property
    def nbytes(self) -> int:
        return sum(len(p[0]) for p in (self.depth, self.thermal, self.ir, self.preview) if p)

    def unpack(self) -> Match:
        depth, thermal = _unpack(self.depth), _unpack(self.thermal)
        ir, preview = _unpack(self.ir), _unpack(self.preview)
        d = DepthFrame(depth, self.depth_time_s, self.depth_index, ir)
        t = ThermalFrame(thermal, self.thermal_time_s, self.thermal_index, self.telemetry, preview)
        pair = FramePair(
            depth,
            thermal,
            self.depth_time_s,
            self.thermal_time_s,
            self.telemetry,
            self.index,
            ir,
            preview,
        )
        return Match(d, t, pair)


class PreTrigger:
    """A rig's last ``keep_s`` seconds of pairs (by their thermal time), compressed, at most
    ``max_bytes``; the oldest go first (``evicted`` counts those that went for the bytes)."""

    def __init__(self, keep_s: float, max_bytes: int) -> None:
        self.keep_s, self.max_bytes = keep_s, max_bytes
        self.items: deque[PackedMatch] = deque()
        self.nbytes = 0
        self.evicted = 0
        self._lock = threading.Lock()

    def add(self, match: Match) -> None:
        if self.keep_s <= 0:
            return
        packed = PackedMatch.of(match)
        with self._lock:
            self.items.append(packed)
            self.nbytes += packed.nbytes
            newest = packed.thermal_time_s
            while self.items and (
                newest - self.items[0].thermal_time_s > self.keep_s or self.nbytes > self.max_bytes
            ):
                old = self.items.popleft()
                self.nbytes -= old.nbytes
                self.evicted += newest - old.thermal_time_s <= self.keep_s

    def snapshot(self) -> list[PackedMatch]:
        with self._lock:
            return list(self.items)


class Clip:
    """One clip being written: the pairs before its event, then every pair until ``until_s``
    (thermal time, s), on its own thread into ``folder/clip.zarr``. ``on_fault`` hears what
    could not be kept."""

    def __init__(
        self,
        clip_id: str,
        folder: Path,
        context: RunContext,
        before: list[PackedMatch],
        until_s: float,
        on_fault: Callable[[str], None],
        max_bytes: int = CLIP_QUEUE_BYTES,
    ) -> None:
        self.id, self.folder, self.until_s = clip_id, folder, until_s
        self.started_s = before[0].thermal_time_s if before else until_s
        self.on_fault = on_fault
        self.pipeline = context.pipeline  # its ROIs and alarm rules, for the picture
        self.events: list[dict[str, Any]] = []
        self.written = 0
        self._queue = ByteQueue(max_bytes)
        for packed in before:  # the pre-trigger's own, bounded there: not counted twice
            self._queue.put(packed)
        self._failed = False
        self._thread = threading.Thread(
            target=self._write, args=(context,), name=f"clip {clip_id}", daemon=True
        )
        self._thread.start()

    def add(self, match: Match) -> bool:
        """Queue a pair; False once the clip's time is over (the pair is not taken)."""
        if match.pair.thermal_time_s > self.until_s:
            return False
        self._queue.offer(match, nbytes_of(match))  # refused: the disk cannot keep up; go on
        return True

    @property
    def lost(self) -> int:
        """The pairs left out of the clip: its queue was full (:data:`CLIP_QUEUE_BYTES`)."""
        return self._queue.refused

    def _write(self, context: RunContext) -> None:
        source = context.source
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            writer = RecordingWriter(
                self.folder / "clip.zarr",
                source.calibration or context.calibration,
                {**source.settings(), **context.provenance},
                source=source.name,
                device_depth=source.device_depth,
                depth_frames="paired",
            )
        except Exception as exc:
            self._fail(f"clip {self.id} not kept: {exc}")
            return
        try:
            while (item := self._queue.get()) is not _END:
                if not self._failed:
                    writer.add_match(item.unpack() if isinstance(item, PackedMatch) else item)
                    self.written += 1
            writer.close({"stopped": "clip", "events": self.events, "frames_not_kept": self.lost})
        except Exception as exc:
            self._fail(f"clip {self.id} kept only its first {self.written} pairs: {exc}")
            while self._queue.get() is not _END:
                pass

    def _fail(self, line: str) -> None:
        self._failed = True
        self.on_fault(line)

    def finish(self) -> None:
        """No more pairs: the clip is closed once its queue is written."""
        self._queue.put(_END)

    def join(self, timeout_s: float | None = None) -> None:
        self._thread.join(timeout_s)


class Evidence:
    """The clips and pictures of a monitor's events under ``root`` (module docstring).
    pre_s, post_s: a clip's seconds before and after its event; max_s: how long a clip that
    events extend may grow; on_fault: told, in one line, what could not be written;
    ``pictures_skipped`` counts the overlays not drawn because too many were waiting (each
    said through ``log``)."""

    def __init__(
        self,
        root: Path,
        pre_s: float,
        post_s: float,
        max_s: float,
        on_fault: Callable[[str], None],
    ) -> None:
        self.root, self.pre_s, self.post_s, self.max_s = root, pre_s, post_s, max_s
        self.on_fault, self.log = on_fault, logger("evidence")
        self.open: dict[str, Clip] = {}
        self.finished: list[Clip] = []
        self._lock = threading.Lock()
        self._pictures = ByteQueue(PICTURES_BYTES)
        self.painter = Worker("evidence pictures", self._paint, 10.0, PAINTER_LIMIT_S, self.log)

    @property
    def pictures_skipped(self) -> int:
        """The pictures not drawn: too many bytes were waiting (:data:`PICTURES_BYTES`)."""
        return self._pictures.refused

    def active_folders(self) -> set[Path]:
        """The folders of clips still being written (never deleted by the storage rule)."""
        with self._lock:
            self.finished = [c for c in self.finished if c._thread.is_alive()]
            return {c.folder for c in (*self.open.values(), *self.finished)}

    def trigger(
        self,
        rig: str,
        event: dict[str, Any],
        now_s: float,
        context: RunContext,
        before: PreTrigger,
    ) -> tuple[Clip, bool]:
        """The clip of a raising event at ``now_s`` (its frame's thermal time, s): a new one
        (True), or the rig's open clip extended (False). Cheap: the clip is written on its
        own thread, and its picture is :meth:`draw`'s."""
        with self._lock:
            clip = self.open.get(rig)
            if clip is not None and now_s + self.post_s - clip.started_s > self.max_s:
                self._end(rig)  # long enough: it ends here, a new one begins
                clip = None
            new = clip is None
            if clip is None:
                folder = fresh_path(self.root / rig, f"{stamp(time.time())}-{event['rule']}")
                first = [p for p in before.snapshot() if p.thermal_time_s >= now_s - self.pre_s]
                clip = Clip(
                    f"{rig}/{folder.name}",
                    folder,
                    context,
                    first,
                    now_s + self.post_s,
                    self.on_fault,
                )
                self.open[rig] = clip
            clip.until_s = max(clip.until_s, now_s + self.post_s)
            clip.events.append(event)
            return clip, new

    def draw(
        self,
        fused: FusedFrame,
        clip: Clip,
        event: dict[str, Any],
        range_c: tuple[float, float] | None,
    ) -> None:
        """Queue the overlay and point cloud of the frame that began ``clip`` (its depth grid
        sampled here, on the rig's thread: the registration is not shared), the ROIs
        outlined, in red those that ``event``'s rule watches."""
        _ = fused.on_depth
        pipe = clip.pipeline
        rois = pipe.rois if pipe is not None else []
        marked = alarm_rois(pipe.alarms.rules, {event["rule"]}) if pipe is not None else {}
        title = (
            f"{clip.id}: {event['event'].upper()} {event['rule']} [{event.get('level', 'alarm')}], "
            f"frame {fused.index}, "
            f"VOx {fused.vox_label}"
        )
        item = (fused, clip.folder, title, range_c, rois, marked)
        if not self._pictures.offer(item, nbytes_of(fused)):  # an old event's picture helps
            self.log.warning(  # no one: the clip is kept
                "clip %s: no overlay or point cloud (%d pictures, %.0f MB waiting)",
                clip.id,
                len(self._pictures),
                self._pictures.nbytes / MB,
            )

    def _paint(self, worker: Worker) -> None:
        """The painter's loop: every picture queued, until the end is queued (by
        :meth:`close`)."""
        from ..figures import display_range_c

        while True:
            worker.beat()
            try:
                item = self._pictures.get(timeout_s=1.0)
            except TimeoutError:
                continue
            if item is _END:
                return
            fused, folder, title, range_c, rois, marked = item
            try:
                folder.mkdir(parents=True, exist_ok=True)
                scale = range_c or display_range_c(fused.temp_depth_c)
                # written aside and renamed: a reader never gets half a file
                png, ply = folder / ".overlay.png", folder / ".frame.ply"
                drawn = framed(overlay_image(fused, scale, list(rois), marked), scale, title)
                png.write_bytes(encode(drawn, "png"))
                write_ply(ply, *fused.points(), *scale)
                os.replace(ply, folder / "frame.ply")
                os.replace(png, folder / "overlay.png")
            except Exception as exc:
                self.on_fault(f"{folder.name}: overlay and point cloud not kept: {exc}")

    def feed(self, rig: str, match: Match) -> None:
        """A rig's pair: into its open clip, which is finished once its time is over."""
        with self._lock:
            clip = self.open.get(rig)
            if clip is not None and not clip.add(match):
                self._end(rig)

    def _end(self, rig: str) -> None:
        """The rig's open clip takes no more pairs (under the lock)."""
        clip = self.open.pop(rig)
        self.finished.append(clip)
        clip.finish()

    def close(self, timeout_s: float = 30.0) -> None:
        """Finish every clip (with the pairs it has) and the pictures queued; wait for them."""
        with self._lock:
            clips = [*self.open.values(), *self.finished]
            for clip in self.open.values():
                clip.finish()
            self.open.clear()
        self.painter.stopping.set()  # its loop returns at the end of what is queued
        self._pictures.put(_END)
        for clip in clips:
            clip.join(timeout_s)
        self.painter.stop(timeout_s)
