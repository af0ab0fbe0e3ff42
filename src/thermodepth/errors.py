"""Errors that reach the user as one clear line (the CLI prints them without a traceback)."""

from __future__ import annotations


class ThermodepthError(Exception):
    """Base class: bad input or a failed operation, with a one-line message for the user."""


class InputError(ThermodepthError, ValueError):
    """A file, field, row or frame the user gave is not acceptable; the message says which."""
