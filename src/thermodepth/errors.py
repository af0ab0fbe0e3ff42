"""Errors that reach the user as one clear line (the CLI prints them without a traceback)."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path


class ThermodepthError(Exception):
    """Base class: bad input or a failed operation, with a one-line message for the user."""


class InputError(ThermodepthError, ValueError):
    """A file, field, row or frame the user gave is not acceptable; the message says which."""


class FieldError(InputError):
    """A value given for a named field (a function's argument, a setting) is not acceptable.

    ``str()`` reads ``field: message``; the command line names its option instead of the
    field (``--emissivity: ...``), so the library never needs to know the flags.
    """

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field = field
        self.message = message


def check_count(field: str, value: int | None, minimum: int = 1) -> None:
    """A count the user gives (frames, samples, poses, pairs): a whole number of at least
    ``minimum``, or None where the count is optional; FieldError otherwise."""
    if value is not None and value < minimum:
        raise FieldError(field, f"must be at least {minimum}, got {value}")


def read_text(path: str | Path, encoding: str = "utf-8") -> str:
    """A text file's content; a file that cannot be read or is not text in ``encoding``
    raises one InputError line naming it (and the first bad byte's offset)."""
    p = Path(path)
    try:
        return p.read_text(encoding=encoding)
    except OSError as exc:
        raise InputError(f"{p}: cannot read ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise InputError(
            f"{p}: not {encoding.upper().removesuffix('-SIG')} text "
            f"(byte 0x{exc.object[exc.start]:02x} at offset {exc.start})"
        ) from None


def repeated(names: Iterable[str]) -> list[str]:
    """The names that occur more than once, sorted: what a message says is given twice."""
    seen = list(names)
    return sorted({n for n in seen if seen.count(n) > 1})
