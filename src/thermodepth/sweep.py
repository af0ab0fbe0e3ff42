"""The sweep CSV: readings of a target of known temperature at several distances and VOx
(sensor) temperatures, the interchange between users' measurements, the simulator and the
compensation models.

Columns (one row per reading, or per averaged reading with ``n``), Celsius and percent at this
edge as users write them:

==================  ========  =================================================================
column              required  meaning
==================  ========  =================================================================
distance_m          yes       distance from the camera to the target, metres
vox_temp_c          yes       the thermal camera's FPA (VOx) temperature, C (empty: the
                              camera tells none, as an InfiRay P2 Pro)
measured_temp_c     yes       uncompensated reading of the target (ROI mean), C: radiometry
                              with emissivity, without distance correction
reference_temp_c    yes*      the target's true temperature (contact sensor), C
ambient_temp_c      no        air / surroundings temperature, C
humidity_pct        no        relative humidity, percent
emissivity          no        target emissivity used for measured_temp_c
raw_counts          no        mean raw pixel value of the ROI (counts, or the camera's
                              own kelvin units)
n                   no        number of readings averaged into the row (default 1)
==================  ========  =================================================================

(*) not needed to apply a model to new readings. Other columns are kept as they are.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .csvfile import CsvWriter, write_csv
from .errors import FieldError, InputError, read_text, repeated
from .radiometry import MAX_DISTANCE_M, TEMP_LIMITS_C

FloatArray = NDArray[np.float64]

SAME_PLACE = 0.02
"""Distances of one placement of the target differ by less than this fraction."""

REQUIRED = ("distance_m", "vox_temp_c", "measured_temp_c", "reference_temp_c")
OPTIONAL = ("ambient_temp_c", "humidity_pct", "emissivity", "raw_counts", "n")
COLUMNS = REQUIRED + OPTIONAL


@dataclass(eq=False)
class SweepTable:
    """Numeric columns as float arrays of equal length, plus any other columns as text.

    ``source`` names the file in messages; ``lines`` holds each row's line number in it;
    ``order`` the column order to write (a read file's header, then added columns).
    """

    columns: dict[str, FloatArray]
    extra: dict[str, list[str]] = field(default_factory=dict)
    source: str = "<sweep>"
    lines: NDArray[np.int64] | None = None
    order: list[str] = field(default_factory=list)

    @property
    def names(self) -> list[str]:
        """Every column: ``order`` first, then the known columns in their documented order,
        then the rest."""
        present = [*self.columns, *self.extra]
        known = [c for c in COLUMNS if c in present and c not in self.order]
        rest = [c for c in present if c not in self.order and c not in known]
        return [c for c in self.order if c in present] + known + rest

    def __len__(self) -> int:
        return len(next(iter(self.columns.values()))) if self.columns else 0

    def __getitem__(self, name: str) -> FloatArray:
        return self.columns[name]

    def __contains__(self, name: object) -> bool:
        return name in self.columns

    def get(self, name: str, default: float) -> FloatArray:
        """A column, or ``default`` for every row when the file lacks it."""
        return self.columns.get(name, np.full(len(self), float(default)))

    def distance_groups(self) -> tuple[NDArray[np.intp], FloatArray]:
        """Rows taken at one placement of the target: each row's group and each group's
        median distance (m), groups in order of distance. Sorted, a distance more than
        :data:`SAME_PLACE` beyond the previous starts a new group, so the millimetres a
        measured distance wanders by stay in one (a simulated sweep's exact distances give one
        group each)."""
        d = self["distance_m"]
        order = np.argsort(d, kind="stable")
        ds = d[order]
        starts = np.concatenate([[True], ds[1:] > ds[:-1] * (1 + SAME_PLACE)])
        labels = np.empty(len(d), np.intp)
        labels[order] = np.cumsum(starts) - 1
        centres = np.array([np.median(d[labels == g]) for g in range(int(starts.sum()))])
        return labels, centres

    def select(self, mask: NDArray[np.bool_]) -> SweepTable:
        """The rows where ``mask`` is True."""
        idx = np.flatnonzero(mask)
        return SweepTable(
            {k: v[idx] for k, v in self.columns.items()},
            {k: [v[i] for i in idx] for k, v in self.extra.items()},
            self.source,
            None if self.lines is None else self.lines[idx],
            self.order,
        )

    def with_columns(self, **cols: FloatArray | Sequence[str]) -> SweepTable:
        """A copy with columns added or replaced (numeric arrays or lists of text)."""
        num = dict(self.columns)
        txt = dict(self.extra)
        for k, v in cols.items():
            if isinstance(v, np.ndarray) and v.dtype.kind in "fiub":
                num[k] = v.astype(np.float64)
                txt.pop(k, None)
            else:
                txt[k] = [str(x) for x in v]
                num.pop(k, None)
        added = [k for k in cols if k not in self.names]  # a replaced column keeps its place
        return SweepTable(num, txt, self.source, self.lines, self.names + added)


def read_sweep_csv(path: str | Path, required: Sequence[str] = REQUIRED) -> SweepTable:
    """Read and validate a sweep CSV.

    Raises :class:`InputError` with one line naming the file and, where it applies, the line
    and column: an empty file, missing columns (all named), a value that is not a number or
    that its column cannot hold (a temperature at or below absolute zero or above 5000 C, a
    distance beyond 1000 m, humidity outside 0-100 %, emissivity outside (0, 1], n not a
    whole number >= 1). Known columns must be numeric (an empty vox_temp_c reads as NaN: a
    camera that tells no sensor temperature); others are kept as text.
    """
    p = Path(path)
    text = read_text(p, "utf-8-sig")
    reader = csv.reader(io.StringIO(text, newline=""))  # not splitlines: a \f is no line end
    header = next(reader, None)
    if header is None or not any(h.strip() for h in header):
        raise InputError(f"{p}: empty file (expected a header with {', '.join(required)})")
    header = [h.strip() for h in header]
    twice = repeated(header)
    if twice:
        raise InputError(f"{p}: header names {', '.join(twice)} more than once")
    missing = [c for c in required if c not in header]
    if missing:
        raise InputError(
            f"{p}: missing column{'s' if len(missing) > 1 else ''}: "
            f"{', '.join(missing)} (found: {', '.join(header)})"
        )
    numeric = [h for h in header if h in COLUMNS]
    values: dict[str, list[float]] = {h: [] for h in numeric}
    extra: dict[str, list[str]] = {h: [] for h in header if h not in COLUMNS}
    lines: list[int] = []
    for row in reader:
        line = reader.line_num
        if not row or not any(cell.strip() for cell in row):
            continue  # blank line
        if len(row) != len(header):
            raise InputError(f"{p}: line {line}: {len(row)} fields, header has {len(header)}")
        for name, cell in zip(header, row, strict=True):
            if name in values:
                if name == "vox_temp_c" and not cell.strip():  # the camera told none
                    values[name].append(math.nan)
                    continue
                value = _number(cell, p, line, name)
                why = _out_of_range(name, value)
                if why:
                    raise InputError(f"{p}: line {line}, column {name}: {cell.strip()} {why}")
                values[name].append(value)
            else:
                extra[name].append(cell)
        lines.append(line)
    if not lines:
        raise InputError(f"{p}: no data rows after the header")
    return SweepTable(
        {k: np.array(v) for k, v in values.items()},
        extra,
        str(p),
        np.array(lines, dtype=np.int64),
        header,
    )


def _out_of_range(column: str, value: float) -> str | None:
    """Why a known column's value cannot be right, or None: what the models' physics takes."""
    lo, hi = TEMP_LIMITS_C
    if column.endswith("_temp_c") and not lo < value <= hi:
        return f"is outside {lo:g} < T <= {hi:g} C"
    if column == "distance_m" and value > MAX_DISTANCE_M:
        return f"is beyond {MAX_DISTANCE_M:g} m"
    if column == "humidity_pct" and not 0 <= value <= 100:
        return "is outside 0-100 %"
    if column == "emissivity" and not 0 < value <= 1:
        return "is outside 0 < emissivity <= 1"
    if column == "n" and not (value >= 1 and value.is_integer()):
        return "is not a whole number of readings >= 1"
    return None


def _number(cell: str, path: Path, line: int, column: str) -> float:
    try:
        if "_" in cell:  # Python's float() reads "1_0" as 10
            raise ValueError
        value = float(cell)
    except ValueError:
        raise InputError(f"{path}: line {line}, column {column}: not a number: {cell!r}") from None
    if not math.isfinite(value):
        raise InputError(f"{path}: line {line}, column {column}: not a finite number: {cell!r}")
    return value


def write_sweep_csv(path: str | Path, table: SweepTable, digits: int | None = 6) -> None:
    """Write a sweep table, columns in :attr:`SweepTable.names` order, numbers to ``digits``
    significant digits (None: the shortest text that reads back as the same float, so a
    table read and written again keeps every value)."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)

    def row(i: int) -> dict[str, str]:
        return {
            name: format_cell(name, table.columns[name][i], digits)
            if name in table.columns
            else table.extra[name][i]
            for name in table.names
        }

    write_csv(p, table.names, (row(i) for i in range(len(table))))


COUNT_COLUMNS = ("n", "frame", "target_px")
"""Columns of whole numbers, written without a decimal point."""


def format_cell(name: str, value: float, digits: int | None = 6) -> str:
    """One number of column ``name`` as the sweep CSV writes it: ``digits`` significant
    digits (None: the shortest text that reads back as the same float), whole numbers for
    :data:`COUNT_COLUMNS`, empty for NaN."""
    if not math.isfinite(value):
        return ""
    if name in COUNT_COLUMNS:
        return str(round(float(value)))
    if digits is None:
        return repr(float(value)).removesuffix(".0")
    return f"{value:.{digits}g}"


class SweepAppender:
    """Sweep rows written as they are made, each flushed and synced to disk: a run killed at
    any moment keeps every completed row.

    A new file gets ``columns`` as its header, written with the first row (no rows, no file);
    each row names every one of them. With ``append`` an existing file keeps its own header,
    which must hold the required columns; each row is written in that order (cells of columns
    a row lacks left empty, columns the header lacks not written).
    Without ``append`` an existing file is refused. :meth:`check` says so before any camera
    starts (a FieldError naming ``out``, or an InputError naming the file).
    """

    def __init__(self, path: str | Path, columns: Sequence[str], append: bool = False) -> None:
        self.path = Path(path)
        self.columns = list(columns)
        self.append = append
        self.rows = 0
        self._file: io.TextIOWrapper | None = None
        self._writer: CsvWriter | None = None

    def check(self) -> None:
        """Refuse an output that exists without ``append``, and with it one whose header
        lacks a required column or whose last line was left unfinished."""
        p = self.path
        if p.is_dir():
            raise FieldError("out", f"{p} is a folder, not a sweep CSV")
        if not p.exists():
            return
        if not self.append:
            raise FieldError(
                "out", f"{p} exists; add --append to add rows to it, or choose another file"
            )
        text = read_text(p, "utf-8-sig")
        header = next(csv.reader(io.StringIO(text, newline="")), None)
        missing = [c for c in REQUIRED if c not in (h.strip() for h in header or [])]
        if missing:
            raise InputError(
                f"{p}: cannot append: its header lacks {', '.join(missing)} (not a sweep CSV?)"
            )
        if not text.endswith("\n"):
            raise InputError(
                f"{p}: cannot append: its last line is unfinished (a run killed while "
                "writing it?); remove that line first"
            )
        self.columns = [h.strip() for h in header or []]

    def write(self, row: dict[str, float]) -> None:
        """Write one row (column -> value) and push it to the disk."""
        if self._file is None or self._writer is None:
            self.check()
            new = not self.path.exists()
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = self.path.open("a", newline="", encoding="utf-8")
            # a file appended to keeps its header: a column it lacks is not written
            self._writer = CsvWriter(self._file, self.columns, fill=not new)
            if new:
                self._writer.header()
        self._writer.row({c: format_cell(c, v) for c, v in row.items()})
        self._file.flush()
        os.fsync(self._file.fileno())
        self.rows += 1

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
