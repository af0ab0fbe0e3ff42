"""The inspection reports the monitor makes by itself (``reports:``,
:class:`.config.ReportSchedule`; the report: :mod:`thermodepth.app.report`).

A supervised worker (``reports``) looks every :data:`CHECK_S`: for each schedule, the period
just ended (``day``: yesterday; ``week``: last Monday to Sunday; ``month``: last month; UTC)
has its file ``STORAGE/reports/STAMP-EVERY.FORMAT`` (``STAMP``: the period's end, UTC) made
once, written whole or not at all, and deleted by age with the storage's ``retention_days``
(:class:`.storage.Retention`). A period that ended more than :data:`CATCH_UP_S` before the
monitor started is not made (a new schedule does not make old reports); one that ended while
it was off for less than that is.

With ``to`` the file goes through that ``notify`` target (:mod:`.outputs.notify`: an e-mail
with the file attached; a webhook a signed JSON naming it, with a link when
``http.public_url`` is set). Once delivered (or refused for good) a marker
``FILE.sent-TARGET`` beside it says so, so that a restart sends it no second time; a temporary
failure is tried again at the next look. Reports do not count toward a target's
``max_per_hour``.
"""

from __future__ import annotations

import os
import re
import time
from collections.abc import Callable
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..app.report import Period, gather, write_report
from .config import MonitorConfig, ReportSchedule
from .logs import logger
from .storage import REPORTS, stamp
from .workers import Worker

if TYPE_CHECKING:
    from .outputs.notify import Notifier

CHECK_S = 60.0
LIMIT_S = 600.0
"""How long the worker may be down (a month's report takes a while) before the monitor is
unwell."""
CATCH_UP_S = 86400.0
REPORT_NAME = re.compile(r"\d{8}T\d{6}Z-(day|week|month)\.(pdf|html)")
"""A kept report's file name (the only names ``/api/reports/FILE`` serves)."""


def last_period(every: str, now: datetime) -> Period:
    """The period of ``every`` (``day``, ``week``, ``month``) that ended last before ``now``
    (UTC)."""
    day0 = now.astimezone(timezone.utc).replace(hour=0, minute=0, second=0, microsecond=0)
    if every == "day":
        return Period(day0 - timedelta(days=1), day0)
    if every == "week":
        monday = day0 - timedelta(days=day0.weekday())
        return Period(monday - timedelta(days=7), monday)
    first = day0.replace(day=1)
    return Period((first - timedelta(days=1)).replace(day=1), first)


def report_path(folder: Path, schedule: ReportSchedule, period: Period) -> Path:
    """Where a schedule's report of ``period`` is kept."""
    return folder / f"{stamp(period.end.timestamp())}-{schedule.every}.{schedule.format}"


def sent_marker(path: Path, target: str) -> Path:
    """The file that says ``path`` went to ``target`` (or was refused for good)."""
    return path.with_name(f"{path.name}.sent-{re.sub(r'[^A-Za-z0-9_.@-]', '_', target)}")


class Reports:
    """The scheduled reports of ``config`` (module docstring); ``target(name)``: the notify
    output a report goes to (None: none of that name); ``started_s``: when the monitor
    started (Unix s)."""

    def __init__(
        self,
        config: MonitorConfig,
        target: Callable[[str], Notifier | None],
        started_s: float,
    ) -> None:
        self.config, self.target, self.started_s = config, target, started_s
        self.folder = config.storage.path / REPORTS
        self.log = logger("reports")
        self.made = self.sent = self.failed = 0
        self.last_error: str | None = None
        self.worker = Worker("reports", self._loop, CHECK_S, LIMIT_S, self.log)

    def _loop(self, worker: Worker) -> None:
        while True:
            worker.beat()
            self.run(time.time(), worker.beat)
            if worker.stopping.wait(CHECK_S):
                return

    def run(self, now_s: float, beat: Callable[[], None] = lambda: None) -> list[Path]:
        """Make and send what is due at ``now_s``; returns the reports made."""
        made = []
        now = datetime.fromtimestamp(now_s, timezone.utc)
        for schedule in self.config.reports:
            period = last_period(schedule.every, now)
            if period.end.timestamp() < self.started_s - CATCH_UP_S:
                continue
            path = report_path(self.folder, schedule, period)
            summary = ""
            if not path.exists():
                summary = self._make(path, period)
                made.append(path)
                beat()
            if schedule.to is not None:
                self._send(schedule.to, path, period, summary)
                beat()
        return made

    def _make(self, path: Path, period: Period) -> str:
        report = gather(self.config, period, "this monitor")
        path.parent.mkdir(parents=True, exist_ok=True)
        part = path.with_name(f".part-{path.name}")  # no stamp: the storage rule skips it
        write_report(report, part)
        os.replace(part, path)
        self.made += 1
        summary = f"{len(report.rigs)} rigs, {report.events} events"
        self.log.info("reports: %s made (%s, %s)", path, period.label(), summary)
        return summary

    def _send(self, to: str, path: Path, period: Period, summary: str) -> None:
        from .outputs.notify import DeliveryError

        output = self.target(to)
        if output is None:
            return  # told by the config's check
        marker = sent_marker(path, output.name)
        if marker.exists():
            return
        try:
            output.send_report(path, period, summary)
        except DeliveryError as exc:
            self.last_error = f"{output.name}: {exc.message}"
            if exc.retry:
                self.log.warning("reports: %s to %s: %s; again in %g s", path.name,
                                 output.name, exc.message, CHECK_S)  # fmt: skip
                return
            self.failed += 1
            self.log.error("reports: %s to %s: %s; not retried", path.name, output.name,
                           exc.message)  # fmt: skip
            marker.write_text(f"refused: {exc.message}\n", encoding="utf-8")
            return
        self.sent += 1
        self.last_error = None
        marker.write_text("delivered\n", encoding="utf-8")
        self.log.info("reports: %s sent to %s", path.name, output.name)

    def status(self) -> dict[str, Any]:
        return {"made": self.made, "sent": self.sent, "failed": self.failed,
                "last_error": self.last_error}  # fmt: skip
