"""CSV files as the project writes them: one sequence of field names gives both the header
and the order of every row's cells (:class:`csv.DictWriter`), so a header can never say one
order while the rows hold another. Each row is a mapping from those names to its cells."""

from __future__ import annotations

import csv
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, TextIO


class CsvWriter:
    """Rows by field name into an open text file (opened with ``newline=""``).

    A row must name exactly ``fields`` (a missing or unknown name is a ValueError naming it:
    a programming error, never a silently empty or dropped column), unless ``fill``: then a
    field a row lacks is left empty and a name not among ``fields`` is not written (rows
    added to a file whose header is someone else's).
    """

    def __init__(self, file: TextIO, fields: Sequence[str], fill: bool = False) -> None:
        self.fields = tuple(fields)
        self.fill = fill
        self._writer = csv.DictWriter(
            file, self.fields, restval="", extrasaction="ignore" if fill else "raise"
        )

    def header(self) -> None:
        """The header line: the field names."""
        self._writer.writeheader()

    def row(self, row: Mapping[str, Any]) -> None:
        """One row (field -> cell: None an empty cell, anything else as ``str`` gives it)."""
        if not self.fill:
            missing = [f for f in self.fields if f not in row]
            if missing:
                raise ValueError(f"CSV row lacks {', '.join(missing)}")
        self._writer.writerow(row)

    def rows(self, rows: Iterable[Mapping[str, Any]]) -> None:
        for row in rows:
            self.row(row)


def write_csv(path: str | Path, fields: Sequence[str], rows: Iterable[Mapping[str, Any]]) -> Path:
    """Write a whole CSV file (UTF-8, ``\\r\\n`` line ends as :mod:`csv` writes them): the
    header ``fields``, then ``rows`` (each naming exactly ``fields``). Returns ``path``."""
    p = Path(path)
    with p.open("w", newline="", encoding="utf-8") as fh:
        writer = CsvWriter(fh, fields)
        writer.header()
        writer.rows(rows)
    return p
