"""Recordings: a Zarr v3 store appended frame by frame, crash-safe, replayed bit for bit.

Layout (docs/recording.md has the full description)::

    session.zarr/                 group; attributes: format, version, calibration, settings,
                                  device_depth, source, created_utc, complete, counts, ...
      depth/image   (N, H, W) uint16   one chunk per frame
      depth/ir      (N, H, W) uint8    optional, one chunk per frame
      depth/meta    (N, 3)    float64  time_s, index, crc32 -- written last: commit marker
      thermal/image (N, h, w) uint16   one chunk per frame
      thermal/meta  (N, 11)   float64  time_s, index, crc32, telemetry (SI) -- commit marker
      pairs         (N, 3)    int64    depth row, thermal row, pair index (-1 = none)

Crash safety: a frame's image chunks are written before its meta row, and a pair row only
after both its frames; every chunk is a file, which zarr (>= 3.1.3, zarr-python PR 3412)
writes to a temporary file and renames into place, so a SIGKILL leaves each file either whole
(old or new content) or absent (a torn chunk from another writer would fail its checksums).
Image chunks hold one frame; meta and pair chunks hold :data:`TABLE_CHUNK_ROWS` rows, each
row write rewriting its chunk whole (so a recording opens reading a few hundred files, not one
per frame). A frame counts only when its meta row is there (not NaN) and its pixels match the
CRC-32 the row holds; arrays grow by doubling (their shape may run ahead of the frames), and
the true counts are found on open. So a killed recording loses at most the frames in flight.
A corrupt or missing image chunk costs its frame only, a corrupt meta or pair chunk the rows
it holds: each is skipped with one warning line and counted.

Compression: Blosc with zstd (level 1, byte shuffle) then a CRC-32C checksum codec per chunk.
"""

from __future__ import annotations

import heapq
import json
import os
import queue
import re
import threading
import time
import warnings
import zlib
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import zarr
from numpy.typing import NDArray
from zarr.codecs import BloscCodec, Crc32cCodec

from ..calibration import Calibration
from ..errors import InputError, ThermodepthError
from ..frames import (
    DepthFrame,
    FfcState,
    FramePair,
    Match,
    StreamEvent,
    Telemetry,
    ThermalFrame,
    match_of,
    pair_of,
)

FORMAT = "thermodepth-recording"
VERSION = 1
DEPTH_META = ("time_s", "index", "crc32")
THERMAL_META = (
    "time_s",
    "index",
    "crc32",
    "frame_counter",
    "fpa_temp_k",
    "housing_temp_k",
    "ffc_state",
    "time_since_ffc_s",
    "ffc_desired",
    "tlinear",
    "tlinear_resolution_k",
)
PAIR_COLUMNS = ("depth_row", "thermal_row", "index")
FIRST_CAPACITY = 64
TABLE_CHUNK_ROWS = 256
"""Rows per chunk of the meta and pair tables (one file each): a row write rewrites its
chunk (at most 256 x 11 float64 = 22 KB), a corrupt chunk costs its rows."""


class RecordingWarning(UserWarning):
    """A frame of a recording was skipped (corrupt or missing chunk)."""


class CorruptFrameError(ThermodepthError):
    """A recorded frame whose chunks cannot be read or do not match their checksum.
    ``reported``: the cause was already warned about when the recording was opened (a table
    chunk missing or corrupt: one warning for all the rows it held)."""

    def __init__(self, message: str, reported: bool = False) -> None:
        super().__init__(message)
        self.reported = reported


def compressors() -> list[Any]:
    """Blosc zstd level 1 with byte shuffle (ratio 2.6 on simulated 1280x720 depth; the cost
    of compressing a depth frame and of its whole write are measured in docs/recording.md,
    "Throughput"), then a CRC-32C of the compressed chunk."""
    return [BloscCodec(cname="zstd", clevel=1, shuffle="shuffle"), Crc32cCodec()]


def checksum(*arrays: NDArray[Any] | None) -> int:
    """CRC-32 of the arrays' bytes in order (None skipped)."""
    crc = 0
    for a in arrays:
        if a is not None:
            crc = zlib.crc32(np.ascontiguousarray(a).data, crc)
    return crc


def telemetry_row(t: Telemetry) -> list[float]:
    """Telemetry as float64 columns (THERMAL_META[3:]); None -> NaN, exact for every value
    the Lepton reports (32-bit counters, centikelvin)."""
    nan = float("nan")
    return [
        float(t.frame_counter),
        t.fpa_temp_k,
        t.housing_temp_k,
        float(int(t.ffc_state)),
        nan if t.time_since_ffc_s is None else t.time_since_ffc_s,
        float(t.ffc_desired),
        float(t.tlinear),
        nan if t.tlinear_resolution_k is None else t.tlinear_resolution_k,
    ]


def telemetry_from_row(row: NDArray[np.float64]) -> Telemetry:
    """Inverse of :func:`telemetry_row`."""
    since, res = float(row[4]), float(row[7])
    return Telemetry(
        frame_counter=int(row[0]),
        fpa_temp_k=float(row[1]),
        housing_temp_k=float(row[2]),
        ffc_state=FfcState(int(row[3])),
        time_since_ffc_s=None if np.isnan(since) else since,
        ffc_desired=bool(row[5]),
        tlinear=bool(row[6]),
        tlinear_resolution_k=None if np.isnan(res) else res,
    )


def _array(
    group: zarr.Group, name: str, frame_shape: tuple[int, ...], dtype: Any, fill: Any
) -> zarr.Array:
    """An array growing along time: images (2-D frames) one compressed frame per chunk,
    table rows (1-D) :data:`TABLE_CHUNK_ROWS` per chunk, uncompressed; CRC-32C on every
    chunk."""
    image = len(frame_shape) == 2
    return group.create_array(
        name,
        shape=(FIRST_CAPACITY, *frame_shape),
        chunks=(1 if image else TABLE_CHUNK_ROWS, *frame_shape),
        dtype=dtype,
        fill_value=fill,
        compressors=compressors() if image else [Crc32cCodec()],
    )


def _grow(arrays: list[zarr.Array], row: int) -> None:
    """Double the time extent of ``arrays`` (one ``zarr.json`` rewrite each) if ``row`` is
    past it."""
    capacity = arrays[-1].shape[0]
    if row >= capacity:
        for a in arrays:
            a.resize((capacity * 2, *a.shape[1:]))


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

    def __init__(self, root: zarr.Group, name: str, columns: tuple[str, ...]) -> None:
        self.root = root
        self.name = name
        self.columns = columns
        self.rows = 0
        self.arrays: dict[str, zarr.Array] = {}
        self.shape: tuple[int, int] | None = None
        self.with_ir = False
        self.bytes = 0  # uncompressed image bytes written

    def create(self, shape: tuple[int, int], with_ir: bool) -> None:
        g = self.root.require_group(self.name)
        self.arrays["image"] = _array(g, "image", shape, np.uint16, 0)
        if with_ir:
            self.arrays["ir"] = _array(g, "ir", shape, np.uint8, 0)
        # the meta array is created last: its presence means the stream's arrays exist
        self.arrays["meta"] = _array(g, "meta", (len(self.columns),), np.float64, np.nan)
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
        _grow(list(self.arrays.values()), row)  # meta last
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


def is_recording(path: str | Path) -> bool:
    """True when ``path`` is a thermodepth recording: a directory whose ``zarr.json`` is a
    group carrying our format marker (read as plain JSON; nothing is opened for writing)."""
    meta = Path(path) / "zarr.json"
    try:
        data = json.loads(meta.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    attrs = data.get("attributes") if isinstance(data, dict) else None
    return isinstance(attrs, dict) and attrs.get("format") == FORMAT


def check_output(path: str | Path, overwrite: bool = False, inputs: tuple[Path, ...] = ()) -> Path:
    """Where a new recording may be written, or a one-line InputError: the path must not be
    (inside) one of ``inputs`` (the files a source reads) nor contain one; it must not exist,
    unless ``overwrite`` and it is a thermodepth recording (:func:`is_recording`) -- any
    other file or directory is never deleted."""
    out = Path(path)
    target = out.resolve()
    for inp in inputs:
        src = Path(inp).resolve()
        if target == src or src.is_relative_to(target) or target.is_relative_to(src):
            raise InputError(f"{out}: the source reads {inp}; write the recording somewhere else")
    if out.exists() or out.is_symlink():
        if not overwrite:
            raise InputError(
                f"{out}: already exists (choose another output, or --overwrite to replace a "
                "recording)"
            )
        if not is_recording(out):
            raise InputError(
                f"{out}: not a thermodepth recording; --overwrite replaces recordings only "
                "(nothing was deleted)"
            )
    return out


class RecordingWriter:
    """Append stream frames and pairs to a new recording (synchronously; see
    :class:`Recorder` for a background writer that never blocks a live source).

    path: the store directory (checked by :func:`check_output`: it must not exist, unless
    ``overwrite`` and it is a recording, and must not be one of ``inputs``); calibration:
    stored as an attribute (the depth intrinsics from the device plus the user's
    thermal/extrinsics); settings: any JSON-able mapping (source spec, pairing threshold,
    ...); device_depth: the depth camera's own intrinsics and depth unit (a calibration
    file's ``depth`` section), stored whether or not a calibration is.
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
    ) -> None:
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
                "complete": False,
            }
        )
        self.depth = _Stream(self.root, "depth", DEPTH_META)
        self.thermal = _Stream(self.root, "thermal", THERMAL_META)
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
            array = _array(self.root, "pairs", (len(PAIR_COLUMNS),), np.int64, -1)
            self.pairs = _TableWriter(array, -1)
        _grow([self.pairs.array], self.n_pairs)
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

    def add(self, event: StreamEvent) -> None:
        """Write what a source emitted (a depth frame, a thermal frame or a match)."""
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


# -- reading ----------------------------------------------------------------------------------


@dataclass
class _Table:
    """A meta or pair table as found on open: ``rows`` up to the last committed one (rows that
    could not be read filled like rows never written); ``missing``: rows below it never
    written, or whose chunk file is gone; ``unreadable``: rows whose chunk is corrupt (below
    or past the last committed row)."""

    rows: NDArray[Any]
    missing: set[int]
    unreadable: set[int]

    def __len__(self) -> int:
        return len(self.rows)

    def check(self, row: int, what: str) -> None:
        """Raise CorruptFrameError (``reported``: warned about on open) if ``row`` cannot be
        used; ``what`` names it (``"depth frame 3: meta row"``)."""
        if row in self.unreadable:
            raise CorruptFrameError(f"{what} unreadable (corrupt chunk)", reported=True)
        if not 0 <= row < len(self.rows) or row in self.missing:
            raise CorruptFrameError(f"{what} missing", reported=row in self.missing)

    def problems(self) -> list[str]:
        """One phrase per run of missing or unreadable rows below the end: ``rows 0-255
        unreadable (corrupt chunk)``."""
        out = []
        for rows, why in (
            (self.unreadable, "unreadable (corrupt chunk)"),
            (self.missing, "missing"),
        ):
            for a, b in _runs(sorted(rows)):
                out.append(f"{'row' if a == b else 'rows'} {a if a == b else f'{a}-{b}'} {why}")
        return out


def _runs(rows: list[int]) -> list[tuple[int, int]]:
    """Consecutive runs of sorted integers as (first, last)."""
    runs: list[tuple[int, int]] = []
    for r in rows:
        if runs and r == runs[-1][1] + 1:
            runs[-1] = (runs[-1][0], r)
        else:
            runs.append((r, r))
    return runs


_EMPTY_TABLE = _Table(np.zeros((0, 0)), set(), set())


def _read_table(
    array: zarr.Array, absent: Callable[[NDArray[Any]], NDArray[np.bool_]], fill: Any
) -> _Table:
    """Read a meta or pair table in bulk (chunk by chunk if a chunk is corrupt). A row is
    committed when ``absent(rows)`` is False for it; the table ends at the last committed
    row."""
    try:
        rows = np.asarray(array[:])
        unreadable = np.zeros(len(rows), dtype=bool)
    except Exception:  # a corrupt chunk: read around it
        parts, flags = [], []
        step = array.chunks[0]
        for a in range(0, array.shape[0], step):
            b = min(a + step, array.shape[0])
            try:
                parts.append(np.asarray(array[a:b]))
                flags.append(np.zeros(b - a, dtype=bool))
            except Exception:
                parts.append(np.full((b - a, *array.shape[1:]), fill, dtype=array.dtype))
                flags.append(np.ones(b - a, dtype=bool))
        rows = np.concatenate(parts) if parts else np.zeros((0, *array.shape[1:]), array.dtype)
        unreadable = np.concatenate(flags) if flags else np.zeros(0, dtype=bool)
    missing = absent(rows) & ~unreadable
    good = np.flatnonzero(~(missing | unreadable))
    n = int(good[-1]) + 1 if good.size else 0
    return _Table(
        rows[:n],
        {int(i) for i in np.flatnonzero(missing[:n])},
        {int(i) for i in np.flatnonzero(unreadable)},
    )


def _nan_rows(rows: NDArray[Any]) -> NDArray[np.bool_]:
    return np.isnan(rows[:, 0])


def _negative_rows(rows: NDArray[Any]) -> NDArray[np.bool_]:
    return rows[:, 0] < 0


class Recording:
    """A recording opened for reading.

    Counts are those of the frames fully written (found from the commit markers, so a killed
    recording opens with every completed frame); the meta and pair tables are read once, in
    bulk, on open. ``pairs()`` yields the recorded FramePairs bit for bit; a frame that cannot
    be read is skipped with one warning (``warn``, default :class:`RecordingWarning`) and
    counted in ``skipped``. Unreadable array metadata (a corrupt ``zarr.json``) is a one-line
    InputError naming the array.
    """

    def __init__(self, path: str | Path, warn: Callable[[str], None] | None = None) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise InputError(f"{self.path}: no such recording")
        try:
            self.root = zarr.open_group(str(self.path), mode="r", zarr_format=3)
            attrs = dict(self.root.attrs)
        except Exception as exc:
            raise InputError(f"{self.path}: not a readable Zarr v3 store ({_short(exc)})") from None
        if attrs.get("format") != FORMAT:
            raise InputError(f"{self.path}: not a thermodepth recording (no format attribute)")
        if attrs.get("version") != VERSION:
            raise InputError(
                f"{self.path}: recording version {attrs.get('version')} is not supported "
                f"(expected {VERSION})"
            )
        self.attrs = attrs
        self.warn = warn or (lambda msg: warnings.warn(msg, RecordingWarning, stacklevel=3))
        self.skipped = 0
        self._arrays: dict[str, zarr.Array] = {}
        for name in (
            "depth/image",
            "depth/ir",
            "depth/meta",
            "thermal/image",
            "thermal/meta",
            "pairs",
        ):
            try:
                node = self.root[name]
            except KeyError:
                continue
            except Exception as exc:
                raise InputError(
                    f"{self.path}: {name}/zarr.json is unreadable ({_short(exc)})"
                ) from None
            if isinstance(node, zarr.Array):
                self._arrays[name] = node
        self._depth = self._table("depth/meta", _nan_rows, np.nan)
        self._thermal = self._table("thermal/meta", _nan_rows, np.nan)
        self._pairs = self._table("pairs", _negative_rows, -1)
        for name, table in (
            ("depth/meta", self._depth),
            ("thermal/meta", self._thermal),
            ("pairs", self._pairs),
        ):
            for problem in table.problems():
                self.warn(f"{self.path}: {name} {problem}: the frames and pairs there are skipped")
        self.n_depth, self.n_thermal, self.n_pairs = (
            len(self._depth),
            len(self._thermal),
            len(self._pairs),
        )
        for stream, n in (("depth", self.n_depth), ("thermal", self.n_thermal)):
            if n and f"{stream}/image" not in self._arrays:
                raise InputError(
                    f"{self.path}: {stream}/image/zarr.json is missing: the {n} {stream} "
                    "frames the recording lists cannot be read"
                )
        self.calibration = (
            Calibration.from_dict(attrs["calibration"], source=f"{self.path} (calibration)")
            if attrs.get("calibration")
            else None
        )

    def _table(
        self, name: str, absent: Callable[[NDArray[Any]], NDArray[np.bool_]], fill: Any
    ) -> _Table:
        array = self._arrays.get(name)
        return _EMPTY_TABLE if array is None else _read_table(array, absent, fill)

    @property
    def complete(self) -> bool:
        """True when the recording was closed (False: the recorder was killed)."""
        return bool(self.attrs.get("complete"))

    @property
    def settings(self) -> dict[str, Any]:
        settings = self.attrs.get("settings")
        return dict(settings) if isinstance(settings, dict) else {}

    @property
    def device_depth(self) -> dict[str, Any] | None:
        """The depth camera's own intrinsics and depth unit (a calibration file's ``depth``
        section), when the recording holds them."""
        value = self.attrs.get("device_depth")
        return dict(value) if isinstance(value, dict) else None

    @property
    def dropped(self) -> dict[str, int]:
        """Events the recorder dropped while recording (depth, thermal, pairs); empty when the
        recording was not closed (the counts are stored on close)."""
        recorder = self.attrs.get("recorder")
        value = recorder.get("dropped") if isinstance(recorder, dict) else None
        return {str(k): int(v) for k, v in value.items()} if isinstance(value, dict) else {}

    @property
    def with_ir(self) -> bool:
        return "depth/ir" in self._arrays

    def _read(
        self, stream: str, row: int, names: tuple[str, ...]
    ) -> tuple[NDArray[np.float64], list[NDArray[Any]]]:
        """Frame ``row`` of ``stream``: its meta row and its arrays ``names``, checked against
        the CRC; CorruptFrameError if they cannot be read or do not match."""
        table = self._depth if stream == "depth" else self._thermal
        table.check(row, f"{stream} frame {row}: meta row")
        meta = table.rows[row]
        try:
            arrays = [np.asarray(self._arrays[f"{stream}/{n}"][row]) for n in names]
        except Exception as exc:
            raise CorruptFrameError(
                f"{stream} frame {row}: unreadable chunk ({_short(exc)})"
            ) from None
        if checksum(*arrays) != int(meta[2]):
            raise CorruptFrameError(f"{stream} frame {row}: pixels do not match their CRC-32")
        return meta, arrays

    def depth_frame(self, row: int) -> DepthFrame:
        """The depth frame at ``row``; CorruptFrameError if it cannot be read or fails its CRC."""
        meta, arrays = self._read("depth", row, ("image", "ir") if self.with_ir else ("image",))
        ir = arrays[1] if self.with_ir else None
        return DepthFrame(arrays[0], float(meta[0]), int(meta[1]), ir)

    def thermal_frame(self, row: int) -> ThermalFrame:
        """The thermal frame at ``row`` with its telemetry; CorruptFrameError as depth_frame."""
        meta, (counts,) = self._read("thermal", row, ("image",))
        return ThermalFrame(counts, float(meta[0]), int(meta[1]), telemetry_from_row(meta[3:]))

    def _readable(self, rows: Iterable[Any], what: str, read: Callable[..., Any]) -> Iterator[Any]:
        """``read(*row)`` for each row; unreadable ones skipped and counted: one warning line
        per run of consecutive rows skipped for the same cause (none for a table chunk
        warned about on open)."""
        run: list[Any] = []  # [first, last, cause, first message] of the skips not yet told

        def tell() -> None:
            if run:
                first, last, _, message = run
                rows = f"{what} {first}" if first == last else f"{what}s {first}-{last}"
                alike = "" if first == last else f" (and alike for the {last - first} after)"
                self.warn(f"{self.path}: {rows} skipped: {message}{alike}")
                run.clear()

        try:
            for i, row in enumerate(rows):
                try:
                    item = read(*row)
                except CorruptFrameError as exc:
                    self.skipped += 1
                    if not exc.reported:
                        cause = re.sub(r"\d+", "#", str(exc))  # the same cause, another frame
                        if run and run[2] == cause and run[1] == i - 1:
                            run[1] = i
                        else:
                            tell()
                            run.extend([i, i, cause, str(exc)])
                    continue
                tell()
                yield item
        finally:  # also when the reader stops early
            tell()

    def matches(self) -> Iterator[Match]:
        """Every recorded pair with its frames, in order; unreadable ones skipped and
        counted (one warning line each, or one per table chunk warned about on open)."""

        def read(i: int, d_row: int, t_row: int, index: int) -> Match:
            self._pairs.check(i, "pair row")
            d = self.depth_frame(int(d_row))
            t = self.thermal_frame(int(t_row))
            return Match(d, t, pair_of(d, t, int(index)))

        rows = ((i, *row) for i, row in enumerate(self._pairs.rows.tolist()))
        yield from self._readable(rows, "pair", read)

    def frames(self) -> Iterator[DepthFrame | ThermalFrame]:
        """Every recorded depth and thermal frame, in time order (what a recording of one
        camera holds: it has no pairs); unreadable ones skipped and counted as in
        :meth:`matches`."""
        depth = self._readable(((r,) for r in range(self.n_depth)), "depth frame", self.depth_frame)
        thermal = self._readable(
            ((r,) for r in range(self.n_thermal)), "thermal frame", self.thermal_frame
        )
        yield from heapq.merge(depth, thermal, key=lambda f: f.time_s)

    def pairs(self) -> Iterator[FramePair]:
        """The recorded FramePairs, bit for bit (see :meth:`matches`)."""
        for m in self.matches():
            yield m.pair


def _short(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


def store_size_bytes(path: str | Path) -> int:
    """Bytes on disk of a recording directory."""
    total = 0
    for root, _dirs, files in os.walk(path):
        for f in files:
            total += os.path.getsize(os.path.join(root, f))
    return total
