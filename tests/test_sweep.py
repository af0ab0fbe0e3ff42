"""The sweep CSV parser: property tests (round trips, fuzzed cells, arbitrary text)."""

from __future__ import annotations

import itertools
import string
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from thermodepth.errors import InputError
from thermodepth.sweep import REQUIRED, SweepTable, read_sweep_csv, write_sweep_csv

finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)
# text cells: no separators, quotes or line breaks, and never a number
words = st.text(alphabet=string.ascii_letters + " _-", min_size=1, max_size=8).filter(
    lambda w: w.strip() and not w.strip().lower().startswith(("inf", "nan"))
)


_DIR = tempfile.TemporaryDirectory(prefix="test-sweep-")  # removed when the run ends
_files = itertools.count()


def _tmp(text: str) -> Path:
    path = Path(_DIR.name) / f"sweep{next(_files)}.csv"
    path.write_text(text, encoding="utf-8")
    return path


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.tuples(finite, finite, finite, finite), min_size=1, max_size=20),
    st.lists(words, min_size=1, max_size=20),
)
def test_write_then_read_round_trips(rows: list[tuple[float, ...]], notes: list[str]) -> None:
    arr = np.array(rows)
    table = SweepTable({name: arr[:, i] for i, name in enumerate(REQUIRED)})
    table = table.with_columns(note=[notes[i % len(notes)] for i in range(len(rows))])
    path = _tmp("")
    write_sweep_csv(path, table, digits=17)
    back = read_sweep_csv(path)
    for name in REQUIRED:
        np.testing.assert_array_equal(back[name], table[name])
    assert back.extra["note"] == table.extra["note"]
    assert back.names == [*REQUIRED, "note"]


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 4), st.integers(0, 3), words)
def test_a_bad_cell_names_its_line_and_column(row: int, col: int, bad: str) -> None:
    lines = [",".join(REQUIRED)] + [f"{1 + i},{25 + i},{38 + i / 10},39" for i in range(5)]
    cells = lines[row + 1].split(",")
    cells[col] = bad
    lines[row + 1] = ",".join(cells)
    path = _tmp("\n".join(lines) + "\n")
    try:
        read_sweep_csv(path)
    except InputError as exc:
        assert str(exc) == (
            f"{path}: line {row + 2}, column {REQUIRED[col]}: not a number: {bad!r}"
        )
    else:
        raise AssertionError("a non-numeric cell was accepted")


@settings(max_examples=150, deadline=None)
@given(st.text(max_size=300))
def test_arbitrary_text_gives_a_table_or_one_clear_line(text: str) -> None:
    path = _tmp(text)
    try:
        table = read_sweep_csv(path)
    except InputError as exc:
        message = str(exc)
        assert message.startswith(str(path)) and "\n" not in message
    else:
        assert len(table) > 0 and all(np.isfinite(table[c]).all() for c in REQUIRED)


def test_replacing_a_column_keeps_one_of_it() -> None:
    table = SweepTable({name: np.arange(3.0) for name in REQUIRED})
    once = table.with_columns(flag=np.zeros(3), note=["a", "b", "c"])
    twice = once.with_columns(flag=np.ones(3), note=["x", "y", "z"])
    assert twice.names == [*REQUIRED, "flag", "note"]
    path = _tmp("")
    write_sweep_csv(path, twice)
    assert path.read_text().splitlines()[0] == ",".join([*REQUIRED, "flag", "note"])


def test_a_repeated_header_name_is_one_line() -> None:
    path = _tmp(",".join([*REQUIRED, "distance_m"]) + "\n1,25,38,39,2\n")
    try:
        read_sweep_csv(path)
    except InputError as exc:
        assert str(exc) == f"{path}: header names distance_m more than once"
    else:
        raise AssertionError("a repeated column was accepted")
