"""The ``thermodepth`` command line: typer signatures and rich printing over the application
layer (:mod:`thermodepth.app`), which does the work.

Each command parses its options, calls one plain function and prints what it returns. Errors
are one red line: a :class:`~thermodepth.errors.FieldError` is shown with the option that
gave the field (``--emissivity: ...``). One module per group of commands; :mod:`.base` holds
the app, the error handling and the shared options.
"""

# in this order: the commands are listed in `thermodepth --help` as they are registered
from . import (
    batch,
    calibrate,
    compensation,
    emissivity,
    measure,
    monitor,
    report,
    ros,
    simulate,
    thermal_map,
)
from .base import app
from .measure import print_frame

__all__ = [
    "app",
    "batch",
    "calibrate",
    "compensation",
    "emissivity",
    "main",
    "measure",
    "monitor",
    "print_frame",
    "report",
    "ros",
    "simulate",
    "thermal_map",
]


def main() -> None:
    """Console-script entry point."""
    app()
