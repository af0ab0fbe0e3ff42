"""Reading recordings: what was committed, found on open, and the frames and pairs replayed
bit for bit, corrupt ones skipped and counted (:class:`Recording`)."""

from __future__ import annotations

import heapq
import re
import warnings
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import zarr
from numpy.typing import NDArray

from ...calibration import Calibration
from ...errors import InputError
from ...frames import DepthFrame, FfcState, FramePair, Match, ThermalFrame, pair_of
from .chunks import FrameChunks
from .format import (
    DEPTH_META,
    FORMAT,
    THERMAL_META,
    VERSIONS,
    CorruptFrameError,
    RecordingWarning,
    checksum,
    is_url,
    short_error,
    telemetry_from_row,
)


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
    """A recording opened for reading: a local path, or an fsspec URL (``file://``,
    ``s3://`` with s3fs installed, ...) that zarr opens through its fsspec store.

    Counts are those of the frames fully written (found from the commit markers, so a killed
    recording opens with every completed frame); the meta and pair tables are read once, in
    bulk, on open. ``pairs()`` yields the recorded FramePairs bit for bit; a frame that cannot
    be read is skipped with one warning (``warn``, default :class:`RecordingWarning`) and
    counted in ``skipped``. Unreadable array metadata (a corrupt ``zarr.json``) is a one-line
    InputError naming the array.
    """

    def __init__(self, path: str | Path, warn: Callable[[str], None] | None = None) -> None:
        url = is_url(path)
        self.path: str | Path = str(path) if url else Path(path)
        if not url and not Path(path).exists():
            raise InputError(f"{self.path}: no such recording")
        try:
            self.root = zarr.open_group(str(self.path), mode="r", zarr_format=3)
            attrs = dict(self.root.attrs)
        except Exception as exc:
            raise InputError(
                f"{self.path}: not a readable Zarr v3 store ({short_error(exc)})"
            ) from None
        if attrs.get("format") != FORMAT:
            raise InputError(f"{self.path}: not a thermodepth recording (no format attribute)")
        version = attrs.get("version")
        if version not in VERSIONS:
            raise InputError(
                f"{self.path}: recording version {version} is not supported (this "
                f"thermodepth reads versions {', '.join(map(str, VERSIONS))})"
            )
        self.version = int(version)
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
                    f"{self.path}: {name}/zarr.json is unreadable ({short_error(exc)})"
                ) from None
            if isinstance(node, zarr.Array):
                self._arrays[name] = node
        self._images = {
            name: FrameChunks(a)
            for name, a in self._arrays.items()
            if name.endswith(("image", "ir"))
        }
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
    def depth_frames(self) -> str:
        """Which depth frames the recording keeps: ``"all"``, or only those ``"paired"`` with
        a thermal frame (:data:`~thermodepth.io.recording.format.DEPTH_FRAMES`)."""
        return str(self.attrs.get("depth_frames", "all"))

    @property
    def with_ir(self) -> bool:
        return "depth/ir" in self._arrays

    def _arrays_of(self, stream: str) -> tuple[str, ...]:
        return ("image", "ir") if stream == "depth" and self.with_ir else ("image",)

    def _frame(self, stream: str, row: int, meta: NDArray[Any], arrays: list[Any]) -> Any:
        """The frame at ``row`` from its meta row and arrays, checked against the checksum
        it holds; CorruptFrameError if they do not match."""
        if checksum(*arrays, version=self.version) != int(meta[2]):
            raise CorruptFrameError(
                f"{stream} frame {row}: pixels do not match their {VERSIONS[self.version]}"
            )
        if stream == "depth":
            ir = arrays[1] if self.with_ir else None
            return DepthFrame(arrays[0], float(meta[0]), int(meta[1]), ir)
        return ThermalFrame(arrays[0], float(meta[0]), int(meta[1]), telemetry_from_row(meta[3:]))

    def _frames_at(self, stream: str, rows: list[int]) -> list[Any]:
        """The frames of ``stream`` at ``rows`` (in that order, repeats allowed), each a frame
        or the CorruptFrameError that stops it. Each run of consecutive rows is read at once
        (:class:`~.chunks.FrameChunks`: blosc decodes without the GIL); a run with a corrupt
        chunk is read again row by row, so that costs its frame only."""
        table = self._depth if stream == "depth" else self._thermal
        out: list[Any] = [None] * len(rows)
        usable: dict[int, list[int]] = {}  # row -> its places in ``rows``
        for k, row in enumerate(rows):
            try:
                table.check(row, f"{stream} frame {row}: meta row")
                usable.setdefault(row, []).append(k)
            except CorruptFrameError as exc:
                out[k] = exc
        names = self._arrays_of(stream)
        for first, last in _runs(sorted(usable)):
            try:
                blocks = [self._images[f"{stream}/{n}"].rows(first, last) for n in names]
            except Exception:  # a corrupt chunk among them: one by one
                blocks = None
            for row in range(first, last + 1):
                try:
                    if blocks is None:
                        arrays = [self._chunk(stream, n, row) for n in names]
                    else:
                        arrays = [b[row - first] for b in blocks]
                    frame: Any = self._frame(stream, row, table.rows[row], arrays)
                except CorruptFrameError as exc:
                    frame = exc
                for k in usable[row]:
                    out[k] = frame
        return out

    def _chunk(self, stream: str, name: str, row: int) -> NDArray[Any]:
        try:
            return self._images[f"{stream}/{name}"].rows(row, row)[0]
        except Exception as exc:
            raise CorruptFrameError(
                f"{stream} frame {row}: unreadable chunk ({short_error(exc)})"
            ) from None

    def _one(self, stream: str, row: int) -> Any:
        (frame,) = self._frames_at(stream, [row])
        if isinstance(frame, CorruptFrameError):
            raise frame
        return frame

    def depth_frame(self, row: int) -> DepthFrame:
        """The depth frame at ``row``; CorruptFrameError if it cannot be read or fails its CRC."""
        frame: DepthFrame = self._one("depth", row)
        return frame

    def thermal_frame(self, row: int) -> ThermalFrame:
        """The thermal frame at ``row`` with its telemetry; CorruptFrameError as depth_frame."""
        frame: ThermalFrame = self._one("thermal", row)
        return frame

    def _readable(
        self, rows: Iterable[Any], what: str, read: Callable[..., Any], first: int = 0
    ) -> Iterator[Any]:
        """``read(*row)`` for each row (numbered from ``first`` in the warnings); unreadable
        ones skipped and counted: one warning line per run of consecutive rows skipped for the
        same cause (none for a table chunk warned about on open)."""
        run: list[Any] = []  # [first, last, cause, first message] of the skips not yet told

        def tell() -> None:
            if run:
                first, last, _, message = run
                rows = f"{what} {first}" if first == last else f"{what}s {first}-{last}"
                alike = "" if first == last else f" (and alike for the {last - first} after)"
                self.warn(f"{self.path}: {rows} skipped: {message}{alike}")
                run.clear()

        try:
            for i, row in enumerate(rows, first):
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

    def matches(self, start: int = 0, stop: int | None = None) -> Iterator[Match]:
        """The recorded pairs ``start`` to ``stop`` (rows of the pairs table; default: all)
        with their frames, in order; unreadable ones skipped and counted (one warning line
        each, or one per table chunk warned about on open). The pairs are read
        :data:`READ_AHEAD` at a time by :data:`READ_THREADS` threads, each a batch ahead of
        the one being used, so decoding overlaps the caller's work."""

        def read_batch(batch: list[tuple[int, ...]]) -> list[Any]:
            depth = self._frames_at("depth", [int(r[1]) for r in batch])
            thermal = self._frames_at("thermal", [int(r[2]) for r in batch])
            out: list[Any] = []
            for (i, _, _, index), d, t in zip(batch, depth, thermal, strict=True):
                try:
                    self._pairs.check(i, "pair row")
                    for frame in (d, t):
                        if isinstance(frame, CorruptFrameError):
                            raise frame
                    out.append(Match(d, t, pair_of(d, t, int(index))))
                except CorruptFrameError as exc:
                    out.append(exc)
            return out

        table = self._pairs.rows[start:stop].tolist()
        rows = [(i, *row) for i, row in enumerate(table, start)]
        found = ((m,) for m in _read_ahead(rows, read_batch))
        yield from self._readable(found, "pair", _given, start)

    def frames(self) -> Iterator[DepthFrame | ThermalFrame]:
        """Every recorded depth and thermal frame, in time order (what a recording of one
        camera holds: it has no pairs); unreadable ones skipped and counted as in
        :meth:`matches`, read ahead as there."""

        yield from heapq.merge(
            self._stream("depth", range(self.n_depth)),
            self._stream("thermal", range(self.n_thermal)),
            key=lambda f: f.time_s,
        )

    def depth_frames_at(self, rows: Iterable[int]) -> Iterator[DepthFrame]:
        """The depth frames at ``rows``, in that order, read ahead and skipped as in
        :meth:`frames` (with one warning line per run of unreadable ones)."""
        return self._stream("depth", rows)

    def _stream(self, name: str, rows: Iterable[int]) -> Iterator[Any]:
        found = _read_ahead(list(rows), lambda batch: self._frames_at(name, batch))
        return self._readable(((f,) for f in found), f"{name} frame", _given)

    def pairs(self, start: int = 0, stop: int | None = None) -> Iterator[FramePair]:
        """The recorded FramePairs ``start`` to ``stop``, bit for bit (see :meth:`matches`)."""
        for m in self.matches(start, stop):
            yield m.pair

    def pair_in_ffc(self) -> NDArray[np.bool_]:
        """Per row of the pairs table: True where the pair's thermal frame was taken with the
        shutter closed (its telemetry's FFC state; a pipeline measures nothing there). From
        the tables read on open: no image is read."""
        rows, thermal = self._pairs.rows, self._thermal.rows
        if not len(rows) or not len(thermal):
            return np.zeros(len(rows), dtype=bool)
        state = thermal[np.clip(rows[:, 1], 0, len(thermal) - 1), THERMAL_META.index("ffc_state")]
        return np.asarray(state == FfcState.IN_PROGRESS)

    def depth_times_s(self) -> NDArray[np.float64]:
        """Per depth frame: its time (s; NaN where unknown), from the tables read on open."""
        if not len(self._depth):
            return np.zeros(0)
        return np.asarray(self._depth.rows[:, DEPTH_META.index("time_s")], dtype=np.float64)

    def pair_times_s(self) -> NDArray[np.float64]:
        """Per row of the pairs table: the thermal frame's time (s; NaN where unknown), from
        the tables read on open."""
        rows, thermal = self._pairs.rows, self._thermal.rows
        if not len(rows) or not len(thermal):
            return np.full(len(rows), np.nan)
        index = np.clip(rows[:, 1], 0, len(thermal) - 1)
        return np.asarray(thermal[index, THERMAL_META.index("time_s")], dtype=np.float64)


READ_AHEAD = 8
"""Frames or pairs a replay reads at once (a batch), one batch per reading thread."""
READ_THREADS = 2
"""Threads that read batches ahead of the caller, each its own batch: on 2 cores decoding
one depth frame takes longer than fusing a pair, so one thread would hold the replay back
(measured in docs/recording.md, "Replay")."""


def _given(item: Any) -> Any:
    """What a read-ahead thread found: the item, or the CorruptFrameError it met."""
    if isinstance(item, CorruptFrameError):
        raise item
    return item


def _read_ahead(rows: list[Any], read: Callable[[list[Any]], list[Any]]) -> Iterator[Any]:
    """``read(batch)`` for each batch of :data:`READ_AHEAD` rows, :data:`READ_THREADS`
    batches at a time on threads ahead of the consumer; yields the items in order. A
    consumer that stops early stops the threads after the batches in hand."""
    batches = [rows[a : a + READ_AHEAD] for a in range(0, len(rows), READ_AHEAD)]
    with ThreadPoolExecutor(READ_THREADS, thread_name_prefix="replay-read") as pool:
        ahead = deque(pool.submit(read, b) for b in batches[:READ_THREADS])
        try:
            for nxt in batches[READ_THREADS:]:
                done = ahead.popleft()
                ahead.append(pool.submit(read, nxt))
                yield from done.result()
            while ahead:
                yield from ahead.popleft().result()
        finally:
            for future in ahead:
                future.cancel()
