"""Writing recordings: appending stream frames and pairs (:class:`RecordingWriter`) and doing
it on a background thread that never stalls a live source (:class:`Recorder`)."""

from __future__ import annotations

import queue
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import zarr
from numpy.typing import NDArray

from ...calibration import Calibration
from ...errors import InputError
from ...frames import DepthFrame, FramePair, Match, StreamEvent, ThermalFrame, match_of
from .format import (
    DEFAULT_CODEC,
    DEPTH_META,
    FORMAT,
    PAIR_COLUMNS,
    THERMAL_META,
    VERSION,
    check_output,
    check_storage,
    checksum,
    create_array,
    grow,
    telemetry_row,
)


class _TableWriter:
    """Appends rows to a table array (meta or pairs), in order. The chunk being filled is
    kept in memory and written whole at every row (rows not yet written hold the fill
    value), so no chunk is read back; zarr renames it into place, so after a crash it holds
    either the rows up to the previous one or up to this one."""

    def __init__(self, array: zarr.Array, fill: Any) -> None:
        self.array = array
        self.fill = fill
        self._chunk = np.full((array.chunks[0], *array.shape[1:]), fill, dtype=array.dtype)
        self._start = 0

    def write(self, row: int, values: NDArray[Any]) -> None:
        rows = len(self._chunk)
        start = row - row % rows
        if start != self._start:
            self._chunk.fill(self.fill)
            self._start = start
        self._chunk[row - start] = values
        stop = min(start + rows, self.array.shape[0])
        self.array[start:stop] = self._chunk[: stop - start]


class _Stream:
    """One time axis of the store: image arrays (+ optional ir) and a meta array."""

    def __init__(self, root: zarr.Group, name: str, columns: tuple[str, ...], codec: str) -> None:
        self.root = root
        self.codec = codec
        self.name = name
        self.columns = columns
        self.rows = 0
        self.arrays: dict[str, zarr.Array] = {}
        self.shape: tuple[int, int] | None = None
        self.with_ir = False
        self.bytes = 0  # uncompressed image bytes written

    def create(self, shape: tuple[int, int], with_ir: bool) -> None:
        g = self.root.require_group(self.name)
        self.arrays["image"] = create_array(g, "image", shape, np.uint16, 0, self.codec)
        if with_ir:
            self.arrays["ir"] = create_array(g, "ir", shape, np.uint8, 0, self.codec)
        # the meta array is created last: its presence means the stream's arrays exist
        self.arrays["meta"] = create_array(g, "meta", (len(self.columns),), np.float64, np.nan)
        self.meta = _TableWriter(self.arrays["meta"], np.nan)
        self.shape, self.with_ir = shape, with_ir

    def append(
        self, index: int, image: NDArray[Any], ir: NDArray[Any] | None, meta: list[float]
    ) -> int:
        """Write frame ``index`` (a 2-D uint16 image, optional uint8 IR of the same size);
        returns its row. The first frame fixes the stream's size and whether it has IR."""
        image = np.asarray(image)
        if image.dtype != np.uint16 or image.ndim != 2:
            raise InputError(
                f"{self.name} frame {index}: expected (H, W) uint16, got {image.shape} "
                f"{image.dtype}"
            )
        h, w = image.shape
        if self.shape is None:
            self.create((h, w), ir is not None)
        if (h, w) != self.shape or (ir is not None) != self.with_ir:
            sh, sw = self.shape  # type: ignore[misc]
            raise InputError(
                f"{self.name} frame {index}: {w}x{h}{' + IR' if ir is not None else ''} "
                f"differs from the recording's {sw}x{sh}{' + IR' if self.with_ir else ''}"
            )
        row = self.rows
        grow(list(self.arrays.values()), row)  # meta last
        self.arrays["image"][row] = image
        if ir is not None:
            self.arrays["ir"][row] = ir
        self.meta.write(row, np.asarray(meta, dtype=np.float64))  # commit marker: last
        self.rows += 1
        self.bytes += image.nbytes + (0 if ir is None else ir.nbytes)
        return row

    def trim(self) -> None:
        for a in self.arrays.values():
            a.resize((self.rows, *a.shape[1:]))


class RecordingWriter:
    """Append stream frames and pairs to a new recording (synchronously; see
    :class:`Recorder` for a background writer that never blocks a live source).

    path: the store directory (checked by :func:`check_output`: it must not exist, unless
    ``overwrite`` and it is a recording, and must not be one of ``inputs``); calibration:
    stored as an attribute (the depth intrinsics from the device plus the user's
    thermal/extrinsics); settings: any JSON-able mapping (source spec, pairing threshold,
    ...); device_depth: the depth camera's own intrinsics and depth unit (a calibration
    file's ``depth`` section), stored whether or not a calibration is; depth_frames: keep
    ``"all"`` the depth frames, or only those ``"paired"`` with a thermal frame (a depth frame
    alone is then not written; :data:`~thermodepth.io.recording.format.DEPTH_FRAMES`);
    codec: the images' codec (:data:`~thermodepth.io.recording.format.CODECS`).
    """

    def __init__(
        self,
        path: str | Path,
        calibration: Calibration | None = None,
        settings: dict[str, Any] | None = None,
        source: str = "",
        overwrite: bool = False,
        inputs: tuple[Path, ...] = (),
        device_depth: dict[str, Any] | None = None,
        depth_frames: str = "all",
        codec: str = DEFAULT_CODEC,
    ) -> None:
        check_storage(depth_frames, codec)
        self.depth_frames = depth_frames
        self.path = check_output(path, overwrite, inputs)
        try:
            self.root = zarr.open_group(str(self.path), mode="w", zarr_format=3)
        except OSError as exc:
            raise InputError(f"{self.path}: cannot create ({exc.strerror or exc})") from None
        self.root.attrs.update(
            {
                "format": FORMAT,
                "version": VERSION,
                "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                "source": source,
                "calibration": None if calibration is None else calibration.to_dict(),
                "settings": settings or {},
                "device_depth": device_depth,
                "depth_frames": depth_frames,
                "complete": False,
            }
        )
        self.depth = _Stream(self.root, "depth", DEPTH_META, codec)
        self.thermal = _Stream(self.root, "thermal", THERMAL_META, codec)
        self.pairs: _TableWriter | None = None
        self.n_pairs = 0
        # rows of recent frames by (index, time): a camera that restarts numbers again from 0
        self._depth_rows: OrderedDict[tuple[int, float], int] = OrderedDict()
        self._thermal_rows: OrderedDict[tuple[int, float], int] = OrderedDict()
        self.closed = False

    # -- appending -------------------------------------------------------------------------

    def add_depth(self, frame: DepthFrame) -> int:
        """Write a depth frame; returns its row. Every frame must have the first one's shape
        (and an IR image if the first had one)."""
        depth = np.asarray(frame.depth)
        ir = None if frame.ir is None else np.asarray(frame.ir, dtype=np.uint8)
        meta = [frame.time_s, float(frame.index), float(checksum(depth, ir))]
        row = self.depth.append(frame.index, depth, ir, meta)
        _remember(self._depth_rows, (frame.index, frame.time_s), row)
        return row

    def add_thermal(self, frame: ThermalFrame) -> int:
        """Write a thermal frame (raw counts) and its telemetry; returns its row."""
        counts = np.asarray(frame.counts)
        meta = [frame.time_s, float(frame.index), float(checksum(counts))]
        row = self.thermal.append(frame.index, counts, None, meta + telemetry_row(frame.telemetry))
        _remember(self._thermal_rows, (frame.index, frame.time_s), row)
        return row

    @property
    def bytes_written(self) -> int:
        """Uncompressed image bytes written."""
        return self.depth.bytes + self.thermal.bytes

    def add_pair_rows(self, depth_row: int, thermal_row: int, index: int) -> None:
        """Write a pair as references to recorded rows (after both frames are written)."""
        if self.pairs is None:
            array = create_array(self.root, "pairs", (len(PAIR_COLUMNS),), np.int64, -1)
            self.pairs = _TableWriter(array, -1)
        grow([self.pairs.array], self.n_pairs)
        self.pairs.write(self.n_pairs, np.array([depth_row, thermal_row, index], np.int64))
        self.n_pairs += 1

    def add_match(self, match: Match) -> None:
        """Write a pair; its frames are written first unless they already are."""
        d = self._depth_rows.get((match.depth.index, match.depth.time_s))
        if d is None:
            d = self.add_depth(match.depth)
        t = self._thermal_rows.get((match.thermal.index, match.thermal.time_s))
        if t is None:
            t = self.add_thermal(match.thermal)
        self.add_pair_rows(d, t, match.pair.index)

    def keeps(self, event: StreamEvent) -> bool:
        """Whether the recording keeps ``event``: all but a depth frame alone when only
        paired ones are kept (its match, if it pairs, writes it)."""
        return not (isinstance(event, DepthFrame) and self.depth_frames == "paired")

    def add(self, event: StreamEvent) -> None:
        """Write what a source emitted (a depth frame, a thermal frame or a match), if the
        recording keeps it (:meth:`keeps`)."""
        if not self.keeps(event):
            return
        if isinstance(event, Match):
            self.add_match(event)
        elif isinstance(event, DepthFrame):
            self.add_depth(event)
        else:
            self.add_thermal(event)

    def add_pair(self, pair: FramePair) -> None:
        """Write a FramePair on its own (its frames numbered by the pair's index)."""
        self.add_match(match_of(pair))

    # -- closing ---------------------------------------------------------------------------

    def close(self, extra_attrs: dict[str, Any] | None = None) -> None:
        """Trim the arrays to the frames written and mark the recording complete."""
        if self.closed:
            return
        self.depth.trim()
        self.thermal.trim()
        if self.pairs is not None:
            self.pairs.array.resize((self.n_pairs, len(PAIR_COLUMNS)))
        self.root.attrs.update(
            {
                "complete": True,
                "counts": {
                    "depth": self.depth.rows,
                    "thermal": self.thermal.rows,
                    "pairs": self.n_pairs,
                },
                **(extra_attrs or {}),
            }
        )
        self.closed = True

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _remember(
    rows: OrderedDict[tuple[int, float], int], key: tuple[int, float], row: int, keep: int = 512
) -> None:
    rows[key] = row
    while len(rows) > keep:
        rows.popitem(last=False)


# -- background recorder ----------------------------------------------------------------------

_STOP = object()


@dataclass
class RecorderStats:
    """What a :class:`Recorder` wrote and dropped, and how fast it wrote (the written counts
    and ``wall_s`` are filled in on close; ``dropped`` and ``busy_s`` as it goes)."""

    depth_frames: int = 0
    thermal_frames: int = 0
    pairs: int = 0
    dropped: dict[str, int] = field(default_factory=lambda: {"depth": 0, "thermal": 0, "pairs": 0})
    bytes_written: int = 0
    busy_s: float = 0.0
    wall_s: float = 0.0

    @property
    def total_dropped(self) -> int:
        return sum(self.dropped.values())

    @property
    def mb_per_s(self) -> float:
        """Uncompressed image megabytes (1e6 bytes) per second of wall time."""
        return self.bytes_written / 1e6 / self.wall_s if self.wall_s > 0 else 0.0

    def summary(self) -> str:
        return (
            f"recorded {self.pairs} pairs ({self.depth_frames} depth, {self.thermal_frames} "
            f"thermal frames), dropped {self.total_dropped} "
            f"(depth {self.dropped['depth']}, thermal {self.dropped['thermal']}, "
            f"pairs {self.dropped['pairs']}), {self.bytes_written / 1e6:.1f} MB raw at "
            f"{self.mb_per_s:.1f} MB/s"
        )


class Recorder:
    """A :class:`RecordingWriter` on a background thread behind a bounded queue.

    ``add(event)`` never blocks when ``block=False`` (live cameras): when the queue is full
    the event is dropped and counted, and a pair whose frame was dropped is dropped too.
    With ``block=True`` (files, the simulator) it waits instead, so nothing is dropped.
    ``close()`` writes what is queued and marks the recording complete; an error on the writer
    thread (disk full, ...) is raised by the next ``add`` or by ``close``.
    """

    def __init__(self, writer: RecordingWriter, block: bool = False, max_queue: int = 90) -> None:
        self.writer = writer
        self.block = block
        self.stats = RecorderStats()
        self._queue: queue.Queue[Any] = queue.Queue(max_queue)
        self._dropped_depth: set[int] = set()
        self._dropped_thermal: set[int] = set()
        self._error: BaseException | None = None
        self._t0 = time.perf_counter()
        self._thread = threading.Thread(target=self._run, name="recorder", daemon=True)
        self._thread.start()
        self.closed = False

    def add(self, event: StreamEvent) -> None:
        if self._error is not None:
            raise self._error
        if not self.writer.keeps(event):
            return  # not queued: no slot taken, nothing dropped
        if isinstance(event, Match) and (
            event.depth.index in self._dropped_depth or event.thermal.index in self._dropped_thermal
        ):
            self.stats.dropped["pairs"] += 1
            return
        try:
            self._queue.put(event, block=self.block)
        except queue.Full:
            if isinstance(event, DepthFrame):
                self.stats.dropped["depth"] += 1
                _bounded_add(self._dropped_depth, event.index)
            elif isinstance(event, ThermalFrame):
                self.stats.dropped["thermal"] += 1
                _bounded_add(self._dropped_thermal, event.index)
            else:
                self.stats.dropped["pairs"] += 1

    def _run(self) -> None:
        w = self.writer
        while True:
            event = self._queue.get()
            if event is _STOP:
                return
            if self._error is not None:
                continue  # drain after a failure
            t0 = time.perf_counter()
            try:
                w.add(event)
            except BaseException as exc:  # reported to the producer
                self._error = exc
            self.stats.busy_s += time.perf_counter() - t0

    def close(self, extra_attrs: dict[str, Any] | None = None) -> RecorderStats:
        """Finish writing what is queued, mark the recording complete, return the stats."""
        if not self.closed:
            self.closed = True
            self._queue.put(_STOP)
            self._thread.join()
            w = self.writer
            self.stats.wall_s = time.perf_counter() - self._t0
            self.stats.depth_frames, self.stats.thermal_frames = w.depth.rows, w.thermal.rows
            self.stats.pairs, self.stats.bytes_written = w.n_pairs, w.bytes_written
            if self._error is not None:
                raise self._error
            self.writer.close({"recorder": {"dropped": self.stats.dropped}, **(extra_attrs or {})})
        return self.stats

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _bounded_add(s: set[int], value: int, keep: int = 4096) -> None:
    if len(s) >= keep:
        s.clear()
    s.add(value)
