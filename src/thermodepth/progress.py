"""Progress reporting: long work says how far it has come without knowing who listens (a rich
bar on the command line, nothing in tests and scripts).

Work takes a :class:`Reporter` and opens a task per stage (``with reporter.task("detecting
boards", total=25) as advance: ... advance(1)``); the command line passes one that draws bars,
everything else :data:`SILENT`.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager
from typing import Protocol


class Progress(Protocol):
    """Told of work done: ``progress(n)`` after ``n`` more units (pairs, frames, poses);
    ``description`` renames the task (a new step starting)."""

    def __call__(self, n: int = 1, /, description: str | None = None) -> None: ...


class Reporter(Protocol):
    """Opens a task of ``total`` units (None: no known end) and yields its :class:`Progress`."""

    def task(self, description: str, total: int | None) -> AbstractContextManager[Progress]: ...


def _nothing(n: int = 1, /, description: str | None = None) -> None:
    """A :class:`Progress` that tells no one."""


class _Silent:
    """A :class:`Reporter` that reports nothing."""

    @contextmanager
    def task(self, description: str, total: int | None) -> Iterator[Progress]:
        yield _nothing


SILENT: Reporter = _Silent()
"""The reporter of work nobody watches (library calls, tests)."""
