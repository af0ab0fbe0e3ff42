"""The monitor's log: the standard :mod:`logging` module, a logger per part and per rig.

=====================================  ==========================================================
logger                                 what logs there
=====================================  ==========================================================
``thermodepth.monitor``                the service: start, stop, reload, events, storage
``thermodepth.monitor.rig.RIG``        one rig: opened, stalled, reopened, its events
``thermodepth.monitor.workers``        the monitor's own workers: a failure and its restart
``thermodepth.monitor.http``,          each output
``.mqtt``, ``.opcua``, ...
``thermodepth.monitor.central``        ``thermodepth dashboard``
=====================================  ==========================================================

Levels come from the config's ``log`` section (``{level: info, rigs: {press7: debug}}``):
:func:`apply_levels`. ``thermodepth monitor`` writes one line per record on stderr
(:func:`install_handler`): ``2026-11-28T14:35:01.123+00:00 press7: stalled (...)``; under
systemd (``$JOURNAL_STREAM`` set) each line starts with its syslog priority instead
(``<4>press7: stalled``), which journald reads as the entry's priority and strips (the journal
stamps the time itself).
"""

from __future__ import annotations

import logging
import os
import sys
from datetime import datetime, timezone
from typing import IO, Literal

ROOT = "thermodepth.monitor"
Level = Literal["debug", "info", "warning", "error"]
LEVELS: dict[str, int] = {
    "debug": logging.DEBUG,
    "info": logging.INFO,
    "warning": logging.WARNING,
    "error": logging.ERROR,
}
JOURNAL_PRIORITY = {logging.DEBUG: 7, logging.INFO: 6, logging.WARNING: 4, logging.ERROR: 3}
"""syslog priorities (sd-daemon(3)): debug, info, warning, err; CRITICAL is 2."""


def logger(part: str | None = None) -> logging.Logger:
    """The logger of a part of the monitor (``None``: the service's own)."""
    return logging.getLogger(ROOT if part is None else f"{ROOT}.{part}")


def rig_logger(rig: str) -> logging.Logger:
    """The logger of one rig (``thermodepth.monitor.rig.RIG``)."""
    return logging.getLogger(f"{ROOT}.rig.{rig}")


def apply_levels(level: Level = "info", rigs: dict[str, Level] | None = None) -> None:
    """Set the monitor's level and each named rig's own (the others follow the monitor's)."""
    logging.getLogger(ROOT).setLevel(LEVELS[level])
    known = logging.Logger.manager.loggerDict
    for name in [n for n in known if n.startswith(f"{ROOT}.rig.")]:
        logging.getLogger(name).setLevel(logging.NOTSET)
    for rig, rig_level in (rigs or {}).items():
        rig_logger(rig).setLevel(LEVELS[rig_level])


class OneLine(logging.Formatter):
    """``TIME MESSAGE`` (UTC, ms), or ``<PRIORITY>MESSAGE`` for the journal; a traceback
    follows on the lines after."""

    def __init__(self, journal: bool) -> None:
        super().__init__()
        self.journal = journal

    def format(self, record: logging.LogRecord) -> str:
        text = record.getMessage()
        if record.exc_info:
            text += "\n" + self.formatException(record.exc_info)
        if self.journal:
            priority = JOURNAL_PRIORITY.get(record.levelno, 2 if record.levelno > 40 else 6)
            return f"<{priority}>{text}"
        when = datetime.fromtimestamp(record.created, timezone.utc)
        return f"{when.isoformat(timespec='milliseconds')} {text}"


def install_handler(stream: IO[str] | None = None) -> logging.Handler:
    """Log every line of ``thermodepth.monitor`` (and its parts) to ``stream`` (stderr), in
    the journal's form under systemd; returns the handler (to remove it)."""
    handler = logging.StreamHandler(stream or sys.stderr)
    handler.setFormatter(OneLine(journal=bool(os.environ.get("JOURNAL_STREAM"))))
    root = logging.getLogger(ROOT)
    root.addHandler(handler)
    if root.level == logging.NOTSET:
        root.setLevel(logging.INFO)
    return handler
