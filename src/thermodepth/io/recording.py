"""Recordings: a Zarr v3 store appended frame by frame, crash-safe, replayed bit for bit.

Layout (docs/recording.md has the full description)::

    session.zarr/                 group; attributes: format, version, calibration, settings,
                                  source, created_utc, complete, counts, stats
      depth/image   (N, H, W) uint16   one chunk per frame
      depth/ir      (N, H, W) uint8    optional, one chunk per frame
      depth/meta    (N, 3)    float64  time_s, index, crc32 -- written last: commit marker
      thermal/image (N, h, w) uint16   one chunk per frame
      thermal/meta  (N, 11)   float64  time_s, index, crc32, telemetry (SI) -- commit marker
      pairs         (N, 3)    int64    depth row, thermal row, pair index (-1 = none)

Crash safety: a frame's image chunks are written before its meta row, and a pair row only
after both its frames; every chunk is its own file, which zarr (>= 3.1.3, zarr-python PR 3412)
writes to a temporary file and renames into place, so a SIGKILL leaves each file either whole
or absent (a torn chunk from another writer would fail its checksums). A frame counts only
when its meta row is there (not NaN) and its pixels match the CRC-32 the row holds; arrays
grow by doubling (their shape may run ahead of the frames), and the true counts are found on
open. So a killed recording loses at most the frames in flight. A corrupt or
missing chunk costs its frame only: it is skipped with one warning line and counted.

Compression: Blosc with zstd (level 1, byte shuffle) then a CRC-32C checksum codec per chunk.
"""

from __future__ import annotations

import contextlib
import os
import queue
import threading
import time
import warnings
import zlib
from collections import OrderedDict
from collections.abc import Callable, Iterator
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


class RecordingWarning(UserWarning):
    """A frame of a recording was skipped (corrupt or missing chunk)."""


class CorruptFrameError(ThermodepthError):
    """A recorded frame whose chunks cannot be read or do not match their checksum."""


def compressors() -> list[Any]:
    """Blosc zstd level 1 with byte shuffle (measured: 9 ms per 1280x720 depth frame, ratio
    2.6 on simulated depth), then a CRC-32C of the compressed chunk."""
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
    return group.create_array(
        name,
        shape=(FIRST_CAPACITY, *frame_shape),
        chunks=(1, *frame_shape),
        dtype=dtype,
        fill_value=fill,
        compressors=compressors() if len(frame_shape) == 2 else [Crc32cCodec()],
    )


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

    def create(self, shape: tuple[int, int], with_ir: bool) -> None:
        g = self.root.require_group(self.name)
        self.arrays["image"] = _array(g, "image", shape, np.uint16, 0)
        if with_ir:
            self.arrays["ir"] = _array(g, "ir", shape, np.uint8, 0)
        # the meta array is created last: its presence means the stream's arrays exist
        self.arrays["meta"] = _array(g, "meta", (len(self.columns),), np.float64, np.nan)
        self.shape, self.with_ir = shape, with_ir

    def append(self, image: NDArray[Any], ir: NDArray[Any] | None, meta: list[float]) -> int:
        row = self.rows
        capacity = self.arrays["meta"].shape[0]
        if row >= capacity:
            for a in self.arrays.values():
                a.resize((capacity * 2, *a.shape[1:]))
        self.arrays["image"][row] = image
        if ir is not None:
            self.arrays["ir"][row] = ir
        self.arrays["meta"][row] = np.asarray(meta, dtype=np.float64)  # commit marker: last
        self.rows += 1
        return row

    def trim(self) -> None:
        for a in self.arrays.values():
            a.resize((self.rows, *a.shape[1:]))


class RecordingWriter:
    """Append stream frames and pairs to a new recording (synchronously; see
    :class:`Recorder` for a background writer that never blocks a live source).

    path: the store directory (must not exist unless ``overwrite``); calibration: stored as an
    attribute (the depth intrinsics from the device plus the user's thermal/extrinsics);
    settings: any JSON-able mapping (source spec, pairing threshold, ...).
    """

    def __init__(
        self,
        path: str | Path,
        calibration: Calibration | None = None,
        settings: dict[str, Any] | None = None,
        source: str = "",
        overwrite: bool = False,
    ) -> None:
        self.path = Path(path)
        if self.path.exists() and not overwrite:
            raise InputError(f"{self.path}: already exists (choose another output or remove it)")
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
                "complete": False,
            }
        )
        self.depth = _Stream(self.root, "depth", DEPTH_META)
        self.thermal = _Stream(self.root, "thermal", THERMAL_META)
        self.pairs: zarr.Array | None = None
        self.n_pairs = 0
        self.bytes_written = 0  # uncompressed image bytes
        self._depth_rows: OrderedDict[int, int] = OrderedDict()
        self._thermal_rows: OrderedDict[int, int] = OrderedDict()
        self.closed = False

    # -- appending -------------------------------------------------------------------------

    def add_depth(self, frame: DepthFrame) -> int:
        """Write a depth frame; returns its row. Every frame must have the first one's shape
        (and an IR image if the first had one)."""
        depth = np.asarray(frame.depth)
        if depth.dtype != np.uint16 or depth.ndim != 2:
            raise InputError(
                f"depth frame: expected (H, W) uint16, got {depth.shape} {depth.dtype}"
            )
        if self.depth.shape is None:
            self.depth.create((depth.shape[0], depth.shape[1]), frame.ir is not None)
        if depth.shape != self.depth.shape or (frame.ir is not None) != self.depth.with_ir:
            raise InputError(
                f"depth frame {frame.index}: {depth.shape[1]}x{depth.shape[0]}"
                f"{' + IR' if frame.ir is not None else ''} differs from the recording's "
                f"{self.depth.shape[1]}x{self.depth.shape[0]}"  # type: ignore[index]
                f"{' + IR' if self.depth.with_ir else ''}"
            )
        ir = None if frame.ir is None else np.asarray(frame.ir, dtype=np.uint8)
        row = self.depth.append(
            depth, ir, [frame.time_s, float(frame.index), float(checksum(depth, ir))]
        )
        self.bytes_written += depth.nbytes + (0 if ir is None else ir.nbytes)
        _remember(self._depth_rows, frame.index, row)
        return row

    def add_thermal(self, frame: ThermalFrame) -> int:
        """Write a thermal frame and its telemetry; returns its row."""
        counts = np.asarray(frame.counts)
        if counts.dtype != np.uint16 or counts.ndim != 2:
            raise InputError(
                f"thermal frame: expected (h, w) uint16 counts, got {counts.shape} {counts.dtype}"
            )
        if self.thermal.shape is None:
            self.thermal.create((counts.shape[0], counts.shape[1]), False)
        if counts.shape != self.thermal.shape:
            raise InputError(
                f"thermal frame {frame.index}: shape {counts.shape} differs from the "
                f"recording's {self.thermal.shape}"
            )
        meta = [frame.time_s, float(frame.index), float(checksum(counts))]
        row = self.thermal.append(counts, None, meta + telemetry_row(frame.telemetry))
        self.bytes_written += counts.nbytes
        _remember(self._thermal_rows, frame.index, row)
        return row

    def add_pair_rows(self, depth_row: int, thermal_row: int, index: int) -> None:
        """Write a pair as references to recorded rows (after both frames are written)."""
        if self.pairs is None:
            self.pairs = _array(self.root, "pairs", (len(PAIR_COLUMNS),), np.int64, -1)
        cap = self.pairs.shape[0]
        if self.n_pairs >= cap:
            self.pairs.resize((cap * 2, len(PAIR_COLUMNS)))
        self.pairs[self.n_pairs] = np.array([depth_row, thermal_row, index], dtype=np.int64)
        self.n_pairs += 1

    def add_match(self, match: Match) -> None:
        """Write a pair; its frames are written first unless they already are."""
        d = self._depth_rows.get(match.depth.index)
        if d is None:
            d = self.add_depth(match.depth)
        t = self._thermal_rows.get(match.thermal.index)
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
            self.pairs.resize((self.n_pairs, len(PAIR_COLUMNS)))
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


def match_of(pair: FramePair) -> Match:
    """A FramePair as a Match whose stream frames are numbered by the pair's index."""
    d = DepthFrame(pair.depth, pair.depth_time_s, pair.index, pair.ir)
    t = ThermalFrame(pair.thermal, pair.thermal_time_s, pair.index, pair.telemetry)
    return Match(d, t, pair)


def _remember(rows: OrderedDict[int, int], index: int, row: int, keep: int = 512) -> None:
    rows[index] = row
    while len(rows) > keep:
        rows.popitem(last=False)


# -- background recorder ----------------------------------------------------------------------

_STOP = object()


@dataclass
class RecorderStats:
    """What a :class:`Recorder` wrote and dropped, and how fast it wrote."""

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

    def add_pair(self, pair: FramePair) -> None:
        """Queue a FramePair on its own (see :meth:`RecordingWriter.add_pair`)."""
        self.add(match_of(pair))

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
            self.stats.depth_frames = w.depth.rows
            self.stats.thermal_frames = w.thermal.rows
            self.stats.pairs = w.n_pairs
            self.stats.bytes_written = w.bytes_written

    def close(self, extra_attrs: dict[str, Any] | None = None) -> RecorderStats:
        """Finish writing what is queued, mark the recording complete, return the stats."""
        if not self.closed:
            self.closed = True
            self._queue.put(_STOP)
            self._thread.join()
            self.stats.wall_s = time.perf_counter() - self._t0
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


def _committed_rows(
    meta: zarr.Array, missing: Callable[[NDArray[Any]], NDArray[np.bool_]]
) -> tuple[int, set[int]]:
    """(frames, bad rows): frames = 1 + the last committed row; bad rows = rows below it whose
    meta row is missing or unreadable."""
    try:
        rows = np.asarray(meta[:])
        bad = missing(rows)
    except Exception:  # a corrupt meta chunk: find it row by row
        bad_list = []
        rows_l = []
        for i in range(meta.shape[0]):
            try:
                r = np.asarray(meta[i])
            except Exception:
                r = np.full(meta.shape[1:], np.nan if meta.dtype.kind == "f" else -1)
            rows_l.append(r)
            bad_list.append(bool(missing(r[None])[0]))
        rows = np.stack(rows_l) if rows_l else np.zeros((0, *meta.shape[1:]))
        bad = np.asarray(bad_list, dtype=bool)
    good = np.flatnonzero(~bad)
    n = int(good[-1]) + 1 if good.size else 0
    return n, {int(i) for i in np.flatnonzero(bad[:n])}


class Recording:
    """A recording opened for reading.

    Counts are those of the frames fully written (found from the commit markers, so a killed
    recording opens with every completed frame). ``pairs()`` yields the recorded FramePairs
    bit for bit; a frame that cannot be read is skipped with one warning (``warn``, default
    :class:`RecordingWarning`) and counted in ``skipped``.
    """

    def __init__(self, path: str | Path, warn: Callable[[str], None] | None = None) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise InputError(f"{self.path}: no such recording")
        try:
            self.root = zarr.open_group(str(self.path), mode="r", zarr_format=3)
            attrs = dict(self.root.attrs)
        except Exception as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise InputError(f"{self.path}: not a readable Zarr v3 store ({first})") from None
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
        for name in ("depth/image", "depth/ir", "depth/meta", "thermal/image", "thermal/meta"):
            with contextlib.suppress(KeyError):
                self._arrays[name] = self.root[name]  # type: ignore[assignment]
        pairs = self.root.get("pairs")
        nan_missing = lambda r: np.isnan(r[:, 0])  # noqa: E731
        self.n_depth, self._bad_depth = (
            _committed_rows(self._arrays["depth/meta"], nan_missing)
            if "depth/meta" in self._arrays
            else (0, set())
        )
        self.n_thermal, self._bad_thermal = (
            _committed_rows(self._arrays["thermal/meta"], nan_missing)
            if "thermal/meta" in self._arrays
            else (0, set())
        )
        self._pairs = pairs if isinstance(pairs, zarr.Array) else None
        self.n_pairs, self._bad_pairs = (
            _committed_rows(self._pairs, lambda r: r[:, 0] < 0)
            if self._pairs is not None
            else (0, set())
        )
        self.calibration = (
            Calibration.from_dict(attrs["calibration"], source=f"{self.path} (calibration)")
            if attrs.get("calibration")
            else None
        )

    @property
    def complete(self) -> bool:
        """True when the recording was closed (False: the recorder was killed)."""
        return bool(self.attrs.get("complete"))

    @property
    def settings(self) -> dict[str, Any]:
        settings = self.attrs.get("settings")
        return dict(settings) if isinstance(settings, dict) else {}

    @property
    def with_ir(self) -> bool:
        return "depth/ir" in self._arrays

    def depth_frame(self, row: int) -> DepthFrame:
        """The depth frame at ``row``; CorruptFrameError if it cannot be read or fails its CRC."""
        if not 0 <= row < self.n_depth or row in self._bad_depth:
            raise CorruptFrameError(f"depth frame {row}: missing")
        try:
            meta = np.asarray(self._arrays["depth/meta"][row])
            depth = np.asarray(self._arrays["depth/image"][row])
            ir = np.asarray(self._arrays["depth/ir"][row]) if self.with_ir else None
        except Exception as exc:
            raise CorruptFrameError(
                f"depth frame {row}: unreadable chunk ({_short(exc)})"
            ) from None
        if checksum(depth, ir) != int(meta[2]):
            raise CorruptFrameError(f"depth frame {row}: pixels do not match their CRC-32")
        return DepthFrame(depth, float(meta[0]), int(meta[1]), ir)

    def thermal_frame(self, row: int) -> ThermalFrame:
        """The thermal frame at ``row`` with its telemetry; CorruptFrameError as depth_frame."""
        if not 0 <= row < self.n_thermal or row in self._bad_thermal:
            raise CorruptFrameError(f"thermal frame {row}: missing")
        try:
            meta = np.asarray(self._arrays["thermal/meta"][row])
            counts = np.asarray(self._arrays["thermal/image"][row])
        except Exception as exc:
            raise CorruptFrameError(
                f"thermal frame {row}: unreadable chunk ({_short(exc)})"
            ) from None
        if checksum(counts) != int(meta[2]):
            raise CorruptFrameError(f"thermal frame {row}: pixels do not match their CRC-32")
        return ThermalFrame(counts, float(meta[0]), int(meta[1]), telemetry_from_row(meta[3:]))

    def matches(self) -> Iterator[Match]:
        """Every recorded pair with its frames, in order; unreadable ones skipped and
        counted (one warning line each)."""
        if self._pairs is None or self.n_pairs == 0:
            return
        try:
            table = np.asarray(self._pairs[: self.n_pairs])
        except Exception:
            table = np.stack([self._pair_row(i) for i in range(self.n_pairs)])
        for i, (d_row, t_row, index) in enumerate(table.tolist()):
            try:
                if i in self._bad_pairs or d_row < 0:
                    raise CorruptFrameError("pair row missing")
                d = self.depth_frame(int(d_row))
                t = self.thermal_frame(int(t_row))
            except CorruptFrameError as exc:
                self.skipped += 1
                self.warn(f"{self.path}: pair {i} skipped: {exc}")
                continue
            yield Match(
                d,
                t,
                FramePair(d.depth, t.counts, d.time_s, t.time_s, t.telemetry, int(index), d.ir),
            )

    def pairs(self) -> Iterator[FramePair]:
        """The recorded FramePairs, bit for bit (see :meth:`matches`)."""
        for m in self.matches():
            yield m.pair

    def _pair_row(self, i: int) -> NDArray[np.int64]:
        try:
            return np.asarray(self._pairs[i])  # type: ignore[index]
        except Exception:
            return np.full(len(PAIR_COLUMNS), -1, dtype=np.int64)

    def summary(self) -> str:
        state = "complete" if self.complete else "not closed (recorder stopped abruptly)"
        return (
            f"{self.path}: {self.n_pairs} pairs, {self.n_depth} depth and {self.n_thermal} "
            f"thermal frames, {state}"
        )


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
