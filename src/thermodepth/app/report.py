"""``thermodepth report``: the inspection report of a period, from a monitor's event store and
readings (:mod:`thermodepth.monitor.store`), as a PDF or a self-contained HTML file
(:mod:`.report_render`).

Per rig: where it is, its viewing conditions (from its settings file as it is now), its
calibration (file, date, check), per ROI the readings of the period (max, mean, min, C; the
distance, m) with a trend, and every event of the period with its evidence picture (the
clip's overlay) and who acknowledged it and when. A period is whole UTC days (``--from``
and ``--to`` inclusive) or, given with a time, from one instant up to another.
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass, field
from datetime import date, datetime, timedelta, timezone
from pathlib import Path
from typing import Any

from ..errors import FieldError, InputError, ThermodepthError

FORMATS = ("pdf", "html")
SEVERITY_NOTE = "severity classes (issue 38, section 1): filled in once the monitor records them"


@dataclass(frozen=True)
class Period:
    """``start`` <= time < ``end`` (UTC)."""

    start: datetime
    end: datetime

    @property
    def start_utc(self) -> str:
        return self.start.isoformat()

    @property
    def end_utc(self) -> str:
        return self.end.isoformat()

    def label(self) -> str:
        """``2026-11-01 to 2026-11-30`` for whole days, else the two instants (UTC)."""
        whole = self.start.time() == self.end.time() == datetime.min.time()
        if whole:
            last = (self.end - timedelta(days=1)).date()
            if last == self.start.date():
                return f"{self.start.date()} (UTC)"
            return f"{self.start.date()} to {last} (UTC)"
        return f"{when(self.start_utc)} to {when(self.end_utc)}"


def _instant(text: str, field_name: str, end: bool) -> datetime:
    """A ``YYYY-MM-DD`` (a whole UTC day: its start, or for ``end`` the next day's start) or
    an ISO 8601 date and time (UTC unless it says otherwise)."""
    try:
        if len(text.strip()) == 10:
            day = date.fromisoformat(text.strip())
            start = datetime(day.year, day.month, day.day, tzinfo=timezone.utc)
            return start + timedelta(days=1) if end else start
        moment = datetime.fromisoformat(text.strip())
    except ValueError:
        raise FieldError(
            field_name, f"{text!r} is not a date (YYYY-MM-DD) or a date and time (ISO 8601)"
        ) from None
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=timezone.utc)
    return moment.astimezone(timezone.utc)


def parse_period(start: str, end: str) -> Period:
    """The period of ``--from`` and ``--to`` (module docstring); FieldError naming the one
    that is not a date, or ``to`` when it is not after ``from``."""
    period = Period(_instant(start, "from", False), _instant(end, "to", True))
    if period.end <= period.start:
        raise FieldError("to", f"{end!r} is before --from {start!r}: the period is empty")
    return period


def when(time_utc: str | None) -> str:
    """A stored ISO time as a report says it: ``2026-11-03 14:35:01 UTC``."""
    if not time_utc:
        return "-"
    moment = datetime.fromisoformat(time_utc).astimezone(timezone.utc)
    return moment.strftime("%Y-%m-%d %H:%M:%S UTC")


@dataclass
class RoiReport:
    """One ROI's readings of the period (``*``: the hottest spot of the whole view):
    ``points`` (minute UTC, max, mean, min C), the period's max, mean (of the minutes') and
    min (C), the median distance (m), its emissivity and reflected temperature (C; None: the
    rig's)."""

    name: str
    points: list[tuple[str, float, float, float]]
    max_c: float | None
    mean_c: float | None
    min_c: float | None
    distance_m: float | None
    emissivity: float | None = None
    reflected_temp_c: float | None = None
    severity: str | None = None  # SEVERITY_NOTE: left for the severity classes

    @property
    def label(self) -> str:
        return "whole view (hottest spot)" if self.name == "*" else self.name


@dataclass
class EventReport:
    """One event of the period: its row, the overlay of its clip (PNG bytes, None when it
    has none or it is no longer kept) and, for a raised one, its acknowledgement."""

    event: dict[str, Any]
    picture: bytes | None = None
    ack_by: str | None = None
    ack_at_utc: str | None = None
    severity: str | None = None  # SEVERITY_NOTE: left for the severity classes


@dataclass
class RigReport:
    """One rig in the report (a rig of the store no longer in the config: ``in_config``
    False, its conditions and calibration unknown)."""

    name: str
    location: str | None = None
    source: str | None = None
    in_config: bool = True
    settings: str | None = None
    conditions: dict[str, Any] = field(default_factory=dict)
    calibration: dict[str, Any] = field(default_factory=dict)
    rois: list[RoiReport] = field(default_factory=list)
    events: list[EventReport] = field(default_factory=list)

    def counts(self) -> dict[str, int]:
        """Events by kind (alarm, escalated, acknowledged, clear)."""
        out: dict[str, int] = {}
        for e in self.events:
            kind = str(e.event.get("event"))
            out[kind] = out.get(kind, 0) + 1
        return out


@dataclass
class Report:
    """The whole report: its ``period``, when it was made (UTC), the config file, the rigs."""

    period: Period
    made_utc: str
    config: str
    rigs: list[RigReport]

    @property
    def events(self) -> int:
        return sum(len(r.events) for r in self.rigs)

    @property
    def empty(self) -> bool:
        """No reading and no event in the period."""
        return not any(r.events or any(roi.points for roi in r.rois) for r in self.rigs)


def _conditions(settings: Any) -> dict[str, Any]:
    r = settings.radiometry
    return {
        "emissivity": r.emissivity,
        "reflected_temp_c": r.reflected_temp_c,
        "ambient_temp_c": r.ambient_temp_c,
        "humidity_pct": r.humidity_pct,
        "window_transmission": r.window_transmission,
    }


def _calibration(path: Path | None) -> dict[str, Any]:
    """The calibration's file, its date (the file's modification time, UTC) and its check
    (``check-calibration``'s: valid with its facts, or the line that says why not)."""
    if path is None:
        return {"file": None, "check": "none given: the simulator's or the camera's own"}
    from .calibrate import check_calibration

    out: dict[str, Any] = {"file": str(path)}
    try:
        out["date_utc"] = when(
            datetime.fromtimestamp(path.stat().st_mtime, timezone.utc).isoformat()
        )
        facts = check_calibration(path)
    except OSError as exc:
        out["check"] = f"cannot read it ({exc.strerror or exc})"
    except ThermodepthError as exc:
        out["check"] = f"not valid: {exc}"
    else:
        out["check"] = "valid"
        out["facts"] = facts
    return out


def _roi_reports(rows: list[dict[str, Any]], settings: Any) -> list[RoiReport]:
    by_roi: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        by_roi.setdefault(row["roi"], []).append(row)
    names = [r.name for r in settings.rois] if settings is not None else []
    order = ["*", *names, *sorted(set(by_roi) - {"*", *names})]
    overrides = {r.name: r for r in settings.rois} if settings is not None else {}
    out = []
    for name in order:
        found = [r for r in by_roi.get(name, []) if r["max_c"] is not None]
        if not found and name not in overrides:
            continue
        distances = [r["distance_m"] for r in found if r["distance_m"] is not None]
        roi = overrides.get(name)
        out.append(
            RoiReport(
                name,
                [(r["minute_utc"], r["max_c"], r["mean_c"], r["min_c"]) for r in found],
                max(r["max_c"] for r in found) if found else None,
                statistics.fmean(r["mean_c"] for r in found) if found else None,
                min(r["min_c"] for r in found) if found else None,
                statistics.median(distances) if distances else None,
                None if roi is None else roi.emissivity,
                None if roi is None else roi.reflected_temp_c,
            )
        )
    return out


def _acknowledge(events: list[EventReport]) -> None:
    """Each raised event gets the first acknowledgement of its rule after it (before the
    rule is raised again)."""
    from ..alarms import RAISED

    for i, e in enumerate(events):
        if e.event.get("event") not in RAISED:
            continue
        for later in events[i + 1 :]:
            if later.event.get("rule") != e.event.get("rule"):
                continue
            if later.event.get("event") == "acknowledged":
                e.ack_by, e.ack_at_utc = later.event.get("by"), later.event.get("at_utc")
                break
            if later.event.get("event") == "alarm":
                break


def _picture(storage: Path, event: dict[str, Any]) -> bytes | None:
    """The overlay of the event's clip, when it is kept (read by the clip's id, never a
    path from outside the clips' folder)."""
    from ..monitor.storage import CLIPS

    clip = event.get("clip")
    if not clip or not event.get("clip_kept", True):
        return None
    root = (storage / CLIPS).resolve()
    path = (root / str(clip) / "overlay.png").resolve()
    if not path.is_relative_to(root):
        return None
    try:
        return path.read_bytes()
    except OSError:
        return None


def gather(config: Any, period: Period, config_name: str = "") -> Report:
    """The report of ``period`` from the monitor of ``config`` (a
    :class:`~thermodepth.monitor.config.MonitorConfig`): its event store must exist
    (InputError otherwise)."""
    from ..monitor.config import MONITOR
    from ..monitor.service import STORE_NAME
    from ..monitor.store import EventStore
    from ..pipeline import Settings

    path = config.storage.path / STORE_NAME
    if not path.is_file():
        raise InputError(f"{path}: no event store there (has the monitor run with this config?)")
    store = EventStore(path)
    try:
        events = store.events_between(period.start_utc, period.end_utc)
        readings = store.readings(period.start_utc, period.end_utc)
    finally:
        store.close()
    rigs: list[RigReport] = []
    for rig in config.rigs:
        settings = Settings.load(rig.settings) if rig.settings else Settings()
        rigs.append(
            RigReport(
                rig.name, rig.location, rig.source,
                settings=None if rig.settings is None else str(rig.settings),
                conditions=_conditions(settings),
                calibration=_calibration(settings.calibration),
                rois=_roi_reports([r for r in readings if r["rig"] == rig.name], settings),
            )
        )  # fmt: skip
    known = {r.name for r in rigs}
    for name in sorted(({e["rig"] for e in events} | {r["rig"] for r in readings}) - known):
        rigs.append(
            RigReport(
                name,
                "the monitor itself (storage faults)" if name == MONITOR else None,
                in_config=False,
                rois=_roi_reports([r for r in readings if r["rig"] == name], None),
            )
        )
    by_name = {r.name: r for r in rigs}
    for event in events:
        by_name[event["rig"]].events.append(
            EventReport(event, _picture(config.storage.path, event))
        )
    for rig_report in rigs:
        _acknowledge(rig_report.events)
    made = datetime.now(timezone.utc).isoformat(timespec="seconds")
    return Report(period, made, config_name, rigs)


def make_report(config_path: Path, start: str, end: str, out: Path) -> Report:
    """Write the report of ``start`` .. ``end`` (``--from``, ``--to``) of the monitor of
    ``config_path`` to ``out`` (``.pdf`` or ``.html``); returns what it holds."""
    from ..monitor import load_config

    kind = out.suffix.lower().lstrip(".")
    if kind not in FORMATS:
        raise FieldError("out", f"{out.name}: a report is a .pdf or an .html file")
    period = parse_period(start, end)
    report = gather(load_config(config_path), period, str(config_path))
    write_report(report, out)
    return report


def write_report(report: Report, out: Path) -> Path:
    """``report`` as a PDF or an HTML file (by ``out``'s suffix)."""
    from .report_render import write_html, write_pdf

    out.parent.mkdir(parents=True, exist_ok=True)
    if out.suffix.lower() == ".html":
        write_html(report, out)
    else:
        write_pdf(report, out)
    return out
