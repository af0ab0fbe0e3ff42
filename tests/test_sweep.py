"""The sweep CSV parser: property tests (round trips, fuzzed cells, arbitrary text)."""

from __future__ import annotations

import csv
import itertools
import string
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from thermodepth.errors import InputError
from thermodepth.sweep import (
    REQUIRED,
    SweepAppender,
    SweepTable,
    read_sweep_csv,
    write_sweep_csv,
)

# what each required column can hold: distances up to 1000 m, temperatures above 0 K to 5000 C
distance = st.floats(-1e6, 1000, allow_nan=False, allow_infinity=False)
temp = st.floats(-273.15, 5000, exclude_min=True)
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
    st.lists(st.tuples(distance, temp, temp, temp), min_size=1, max_size=20),
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


@settings(max_examples=80, deadline=None)
@given(
    st.sampled_from(
        [
            ("vox_temp_c", st.floats(-1e300, -273.15) | st.floats(5000, 1e300, exclude_min=True)),
            ("reference_temp_c", st.floats(5000, 1e300, exclude_min=True)),
            ("distance_m", st.floats(1000, 1e300, exclude_min=True)),
            (
                "humidity_pct",
                st.floats(-1e9, 0, exclude_max=True) | st.floats(100, 1e9, exclude_min=True),
            ),
            ("emissivity", st.floats(-10, 0) | st.floats(1, 10, exclude_min=True)),
            ("n", st.floats(-5, 50).filter(lambda n: n < 1 or not n.is_integer())),
        ]
    ).flatmap(lambda c: st.tuples(st.just(c[0]), c[1])),
    st.integers(0, 3),
)
def test_a_value_its_column_cannot_hold_names_its_line(bad: tuple[str, float], row: int) -> None:
    column, value = bad
    header = [*REQUIRED, "humidity_pct", "emissivity", "n"]
    lines = [",".join(header)] + [f"{1 + i},{25 + i},38.5,39,50,0.95,4" for i in range(4)]
    cells = lines[row + 1].split(",")
    cells[header.index(column)] = repr(value)
    lines[row + 1] = ",".join(cells)
    path = _tmp("\n".join(lines) + "\n")
    try:
        read_sweep_csv(path)
    except InputError as exc:
        assert str(exc).startswith(f"{path}: line {row + 2}, column {column}: {value!r} is ")
        assert "\n" not in str(exc)
    else:
        raise AssertionError(f"{column} = {value!r} was accepted")


@pytest.mark.parametrize("sep", ["\f", "\v", "\x1c", "\u2028"])
def test_text_cells_keep_characters_that_str_splitlines_would_break_on(sep: str) -> None:
    path = _tmp(",".join([*REQUIRED, "note"]) + f"\r\n1,25,38,39,a{sep}b\r\n2,26,38,39,c\r\n")
    table = read_sweep_csv(path)
    assert table.extra["note"] == [f"a{sep}b", "c"]
    assert table.lines is not None and list(table.lines) == [2, 3]


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


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.tuples(distance, temp, temp, temp, st.integers(1, 50)), min_size=1, max_size=8),
    st.permutations([*REQUIRED, "n", "note"]),
)
def test_each_cell_is_under_its_own_header_name(
    rows: list[tuple[float, float, float, float, int]], order: list[str]
) -> None:
    """Read by name (csv.DictReader), every cell of a written table is the value of its
    column, in whatever order the columns are written."""
    arr = np.array([r[:4] for r in rows])
    columns = {name: arr[:, i] for i, name in enumerate(REQUIRED)}
    columns["n"] = np.array([float(r[4]) for r in rows])
    notes = [f"row {i}" for i in range(len(rows))]
    table = SweepTable(columns, {"note": notes}, order=order)
    path = _tmp("")
    write_sweep_csv(path, table, digits=None)
    with path.open(newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        back = list(reader)
    assert reader.fieldnames == order
    assert [r["note"] for r in back] == notes
    for name in columns:
        assert [float(r[name]) for r in back] == list(columns[name]), name


def test_appended_rows_go_under_the_files_own_header(tmp_path: Path) -> None:
    """A new file's header is the columns given; a file appended to keeps its own order,
    a column it lacks left out, one a row lacks left empty."""
    row = {"distance_m": 1.5, "vox_temp_c": 30.25, "measured_temp_c": 38.5,
           "reference_temp_c": 39.0, "n": 4.0, "frame": 12.0}  # fmt: skip
    new = tmp_path / "new.csv"
    appender = SweepAppender(new, [*REQUIRED, "n", "frame"])
    appender.write(row)
    appender.write({**row, "distance_m": 2.0})
    appender.close()
    with new.open(newline="", encoding="utf-8") as f:
        assert list(csv.DictReader(f)) == [
            {**{k: f"{v:g}" for k, v in row.items()}, "n": "4", "frame": "12"},
            {**{k: f"{v:g}" for k, v in row.items()}, "n": "4", "frame": "12", "distance_m": "2"},
        ]
    theirs = tmp_path / "theirs.csv"
    theirs.write_text(
        "note,reference_temp_c,measured_temp_c,vox_temp_c,distance_m\r\nx,39,38,30,1\r\n"
    )
    appender = SweepAppender(theirs, [*REQUIRED, "n", "frame"], append=True)
    appender.write(row)
    appender.close()
    with theirs.open(newline="", encoding="utf-8") as f:
        back = list(csv.DictReader(f))
    assert back[1] == {"note": "", "reference_temp_c": "39", "measured_temp_c": "38.5",
                       "vox_temp_c": "30.25", "distance_m": "1.5"}  # fmt: skip
    assert read_sweep_csv(theirs).names == ["note", *reversed(REQUIRED)]


def test_a_row_that_does_not_name_every_column_of_a_new_file_is_refused(tmp_path: Path) -> None:
    row = {"distance_m": 1.5, "vox_temp_c": 30.0, "measured_temp_c": 38.5, "reference_temp_c": 39}
    appender = SweepAppender(tmp_path / "s.csv", [*REQUIRED, "n"])
    with pytest.raises(ValueError, match="CSV row lacks n"):
        appender.write(row)
    with pytest.raises(ValueError, match="'note'"):  # csv.DictWriter's own refusal
        appender.write({**row, "n": 1.0, "note": 2.0})
    appender.close()
