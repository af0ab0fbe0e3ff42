"""The inspection report (:mod:`.report`) drawn: a PDF through matplotlib's PDF backend (A4
pages laid out top to bottom, text, tables, the trend charts and the evidence pictures) or a
self-contained HTML file (pictures and charts embedded as PNG data URIs).

matplotlib's object API only (a :class:`~matplotlib.figure.Figure` per page, no pyplot):
the monitor makes its scheduled reports on a worker thread of its own.
"""

from __future__ import annotations

import base64
import html
import io
import math
import textwrap
from collections.abc import Callable, Sequence
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

from .report import SEVERITY_NOTE, EventReport, Report, RigReport, RoiReport, when

PAGE_IN = (8.27, 11.69)  # A4 portrait
MARGIN = 0.06  # of the page's width and height
GAP = timedelta(minutes=2)
"""Minutes further apart than this are not joined in a trend (the monitor was off)."""

HOW_TO_READ = (
    "This report tells what the thermodepth monitor saw of each camera rig during the period. "
    "A rig is a depth camera and a thermal camera looking at the same equipment; an ROI "
    "(region of interest) is a named part of the view, such as one busbar or one breaker. "
    "For each ROI the monitor kept, every minute, the highest (max), average (mean) and lowest "
    "(min) surface temperature it measured, in degrees Celsius (°C); 'whole view' is the "
    "hottest spot anywhere in the picture. Distance is from the camera to the surface, in "
    "metres (m). An event is an alarm rule changing state: 'alarm' (a limit was crossed), "
    "'escalated' (a warning became an alarm), 'acknowledged' (a person confirmed seeing it: "
    "their name is given) and 'clear' (back within the limit). The picture of an alarm is the "
    "thermal image laid over the depth image at that moment: warmer colours are hotter. A "
    "thermal camera's temperature depends on the surface's emissivity (how well it radiates, "
    "0 to 1) and on the reflected temperature of its surroundings; both are listed under the "
    "viewing conditions, as the rig's settings give them now. The calibration is the file "
    "that tells how the two cameras see the same scene; 'valid' means it passed its check."
)


def deg(value: float | None, digits: int = 2) -> str:
    """A temperature with its unit: ``61.20 °C`` (``-``: none)."""
    return "-" if value is None or value != value else f"{value:.{digits}f} °C"


def metres(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f} m"


def plain(value: Any) -> str:
    return "-" if value is None else str(value)


def conditions_rows(rig: RigReport) -> list[tuple[str, str]]:
    c = rig.conditions
    if not c:
        return [("viewing conditions", "unknown: the rig is not in the config now")]
    reflected = c.get("reflected_temp_c")
    return [
        ("emissivity (0-1)", plain(c.get("emissivity"))),
        ("reflected temperature", deg(reflected, 1) if reflected is not None else "the air's"),
        ("air temperature", deg(c.get("ambient_temp_c"), 1)),
        ("air humidity", f"{c.get('humidity_pct'):g} %"),
        ("window transmission (0-1)", plain(c.get("window_transmission"))),
    ]


def calibration_rows(rig: RigReport) -> list[tuple[str, str]]:
    cal = rig.calibration
    if not cal:
        return []
    rows = [("calibration file", plain(cal.get("file"))), ("check", plain(cal.get("check")))]
    if cal.get("date_utc"):
        rows.insert(1, ("file date", cal["date_utc"]))
    facts = cal.get("facts") or {}
    if facts:
        rows.append(("baseline", f"{facts['baseline_mm']} mm"))
        rows.append(("rotation", f"{facts['rotation_deg']} °"))
    return rows


def roi_table(rig: RigReport) -> tuple[list[str], list[list[str]]]:
    """The readings table's header and rows (a severity column only when one is known)."""
    severity = any(r.severity for r in rig.rois)  # SEVERITY_NOTE
    head = ["ROI", "max", "mean", "min", "distance", "emissivity", "minutes"]
    rows = []
    for r in rig.rois:
        eps = r.emissivity if r.emissivity is not None else rig.conditions.get("emissivity")
        row = [r.label, deg(r.max_c), deg(r.mean_c), deg(r.min_c), metres(r.distance_m),
               plain(eps), str(len(r.points))]  # fmt: skip
        rows.append([*row, plain(r.severity)] if severity else row)
    return ([*head, "severity"] if severity else head), rows


def event_lines(e: EventReport) -> list[str]:
    """An event in a few lines: when, what, value, acknowledgement."""
    ev = e.event
    value = "" if ev.get("value_c") is None else f", value {deg(ev['value_c'])}"
    first = (
        f"#{ev.get('id')}  {when(ev.get('time_utc'))}  {ev.get('rule')} "
        f"[{ev.get('level')}]: {str(ev.get('event')).upper()}{value}"
    )
    lines = [first]
    if ev.get("condition"):
        lines.append(f"condition: {ev['condition']}")
    if ev.get("event") == "acknowledged":
        lines.append(f"acknowledged by {ev.get('by')} at {when(ev.get('at_utc'))}")
    elif e.ack_by is not None:
        lines.append(f"acknowledged by {e.ack_by} at {when(e.ack_at_utc)}")
    elif ev.get("event") in ("alarm", "escalated"):
        lines.append("not acknowledged in the period")
    if e.severity is not None:  # SEVERITY_NOTE
        lines.append(f"severity: {e.severity}")
    if ev.get("clip") and e.picture is None:
        lines.append("its evidence is no longer kept (the storage rule deleted it)")
    return lines


def summary_rows(report: Report) -> list[list[str]]:
    rows = []
    for rig in report.rigs:
        counts = rig.counts()
        hottest = max((r.max_c for r in rig.rois if r.max_c is not None), default=None)
        rows.append([rig.name, plain(rig.location), str(len(rig.events)),
                     str(counts.get("alarm", 0) + counts.get("escalated", 0)),
                     str(counts.get("acknowledged", 0)), deg(hottest)])  # fmt: skip
    return rows


SUMMARY_HEAD = ["rig", "location", "events", "alarms", "acknowledged", "hottest"]


def draw_trend(ax: Any, rois: Sequence[RoiReport]) -> None:
    """Each ROI's max (solid) and mean (dashed) over the period, °C against UTC time."""
    import matplotlib.dates as mdates

    for i, roi in enumerate(r for r in rois if r.points):
        times: list[datetime] = []
        maxes: list[float] = []
        means: list[float] = []
        for minute, max_c, mean_c, _ in roi.points:
            t = datetime.fromisoformat(minute)
            if times and t - times[-1] > GAP:
                times.append(times[-1] + GAP / 2)
                maxes.append(math.nan)
                means.append(math.nan)
            times.append(t)
            maxes.append(max_c)
            means.append(mean_c)
        colour = f"C{i % 10}"
        ax.plot(times, maxes, "-", color=colour, lw=1.2, label=f"{roi.label} max")
        ax.plot(times, means, "--", color=colour, lw=0.8, label=f"{roi.label} mean")
    ax.set_ylabel("temperature (°C)")
    ax.set_xlabel("time (UTC)")
    ax.grid(alpha=0.3)
    ax.xaxis.set_major_formatter(mdates.ConciseDateFormatter(ax.xaxis.get_major_locator()))
    if ax.lines:
        ax.legend(fontsize=6, ncol=2, loc="best")


def trend_png(rois: Sequence[RoiReport]) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 2.8), dpi=110, layout="constrained")
    draw_trend(fig.add_subplot(), rois)
    buf = io.BytesIO()
    FigureCanvasAgg(fig).print_png(buf)
    return buf.getvalue()


# -- PDF ---------------------------------------------------------------------------------------


class Pages:
    """A4 pages filled top to bottom; a new page when the next part does not fit."""

    def __init__(self, pdf: Any, footer: str) -> None:
        self.pdf, self.footer = pdf, footer
        self.fig: Any = None
        self.y = 0.0
        self.number = 0

    def _new(self) -> None:
        from matplotlib.figure import Figure

        self.finish()
        self.fig = Figure(figsize=PAGE_IN)
        self.number += 1
        self.y = 1 - MARGIN

    def finish(self) -> None:
        if self.fig is not None:
            self.fig.text(MARGIN, MARGIN / 2, self.footer, fontsize=7, color="0.4")
            self.fig.text(1 - MARGIN, MARGIN / 2, f"page {self.number}", fontsize=7,
                          color="0.4", ha="right")  # fmt: skip
            self.pdf.savefig(self.fig)
            self.fig = None

    def room(self, height: float) -> None:
        """A new page unless ``height`` (of the page) fits below."""
        if self.fig is None or self.y - height < MARGIN:
            self._new()

    def new_page(self) -> None:
        self._new()

    def text(self, text: str, size: float = 9, weight: str = "normal", width: int = 100) -> None:
        lines = textwrap.wrap(text, width) or [""]
        step = size * 1.45 / 72 / PAGE_IN[1]
        for line in lines:
            self.room(step)
            self.fig.text(MARGIN, self.y - step, line, fontsize=size, weight=weight)
            self.y -= step

    def gap(self, fraction: float = 0.01) -> None:
        self.y -= fraction

    def table(self, head: Sequence[str], rows: Sequence[Sequence[str]], size: float = 8) -> None:
        step = size * 1.6 / 72 / PAGE_IN[1]
        width = 1 - 2 * MARGIN
        cols = len(head)
        first = 0.28 if cols > 2 else 0.38

        def x(i: int) -> float:
            return MARGIN + (0 if i == 0 else width * (first + (1 - first) * (i - 1) / (cols - 1)))

        for r, row in enumerate([list(head), *map(list, rows)]):
            self.room(step * (2 if r == 0 else 1))
            for i, cell in enumerate(row):
                self.fig.text(x(i), self.y - step, cell, fontsize=size,
                              weight="bold" if r == 0 else "normal")  # fmt: skip
            self.y -= step

    def figure(self, height: float, draw: Callable[[Any], None]) -> None:
        """Axes ``height`` (of the page) high across the page, drawn by ``draw(ax)``."""
        self.room(height + 0.02)
        ax = self.fig.add_axes((MARGIN + 0.07, self.y - height, 1 - 2 * MARGIN - 0.08, height))
        draw(ax)
        self.y -= height + 0.045

    def picture(self, png: bytes, height: float) -> None:
        import matplotlib.image as mpimg

        image = mpimg.imread(io.BytesIO(png), format="png")
        h, w = image.shape[:2]
        width = height * PAGE_IN[1] / PAGE_IN[0] * w / h
        self.room(height + 0.01)
        ax = self.fig.add_axes((MARGIN, self.y - height, width, height))
        ax.imshow(image, interpolation="none")  # embedded as it is, not resampled
        ax.set_axis_off()
        self.y -= height + 0.01


def write_pdf(report: Report, out: Path) -> None:
    from matplotlib.backends.backend_pdf import PdfPages

    meta = {"Title": f"thermodepth inspection report {report.period.label()}",
            "Creator": "thermodepth"}  # fmt: skip
    with PdfPages(out, metadata=meta) as pdf:
        p = Pages(pdf, f"thermodepth inspection report, {report.period.label()}")
        p.text("Inspection report", 18, "bold")
        p.text(f"Period: {report.period.label()}", 11)
        p.text(f"Made {when(report.made_utc)} from the monitor of {report.config}", 8)
        p.gap()
        p.text("How to read this", 11, "bold")
        p.text(HOW_TO_READ, 8.5, width=110)
        p.gap()
        p.text("Summary", 11, "bold")
        if report.empty:
            p.text("Nothing was recorded in this period: no reading and no event.", 9)
        p.table(SUMMARY_HEAD, summary_rows(report))
        for rig in report.rigs:
            p.new_page()
            _rig_pdf(p, rig)
        p.finish()


def _rig_pdf(p: Pages, rig: RigReport) -> None:
    where = f" at {rig.location}" if rig.location else ""
    p.text(f"Rig {rig.name}{where}", 14, "bold")
    if rig.source:
        p.text(f"source: {rig.source}; settings: {plain(rig.settings)}", 8)
    p.gap()
    p.text("Viewing conditions and calibration", 11, "bold")
    p.table(["", ""], [*conditions_rows(rig), *calibration_rows(rig)])
    p.gap()
    p.text("Readings", 11, "bold")
    head, rows = roi_table(rig)
    if rows:
        p.table(head, rows)
    else:
        p.text("No reading in this period.", 9)
    if any(r.points for r in rig.rois):
        p.gap()
        p.figure(0.2, lambda ax: draw_trend(ax, rig.rois))
    p.text(f"Events ({len(rig.events)})", 11, "bold")
    if not rig.events:
        p.text("No event in this period.", 9)
    for e in rig.events:
        p.gap(0.005)
        for i, line in enumerate(event_lines(e)):
            p.text(line, 8.5 if i == 0 else 8, "bold" if i == 0 else "normal")
        if e.picture is not None:
            p.picture(e.picture, 0.16)


# -- HTML --------------------------------------------------------------------------------------

STYLE = """
body { font-family: sans-serif; max-width: 60em; margin: 2em auto; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0; }
td, th { border: 1px solid #ccc; padding: 0.2em 0.6em; text-align: left; }
.event { margin: 1em 0; padding-top: 0.5em; border-top: 1px solid #ddd; }
.event img { max-width: 100%; height: auto; }
p.note { color: #555; font-size: 0.9em; }
"""


def _table(head: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    e = html.escape
    header = "".join(f"<th>{e(h)}</th>" for h in head) if any(head) else ""
    body = "".join("<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table>{f'<tr>{header}</tr>' if header else ''}{body}</table>"


def _png(data: bytes, alt: str) -> str:
    b64 = base64.b64encode(data).decode("ascii")
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{b64}">'


def write_html(report: Report, out: Path) -> None:
    e = html.escape
    label = report.period.label()
    parts = [
        f"<!doctype html><html lang='en'><head><meta charset='utf-8'>"
        f"<title>thermodepth inspection report {e(label)}</title><style>{STYLE}</style>"
        f"</head><body><h1>Inspection report</h1><p>Period: {e(label)}</p>"
        f"<p class='note'>Made {e(when(report.made_utc))} from the monitor of "
        f"{e(report.config)}</p><h2>How to read this</h2><p>{e(HOW_TO_READ)}</p><h2>Summary</h2>"
    ]
    if report.empty:
        parts.append("<p>Nothing was recorded in this period: no reading and no event.</p>")
    parts.append(_table(SUMMARY_HEAD, summary_rows(report)))
    for rig in report.rigs:
        where = f" at {rig.location}" if rig.location else ""
        parts.append(f"<h2>Rig {e(rig.name)}{e(where)}</h2>")
        if rig.source:
            parts.append(f"<p class='note'>source: {e(rig.source)}; settings: "
                         f"{e(plain(rig.settings))}</p>")  # fmt: skip
        parts.append("<h3>Viewing conditions and calibration</h3>")
        parts.append(_table(["", ""], [*conditions_rows(rig), *calibration_rows(rig)]))
        parts.append("<h3>Readings</h3>")
        head, rows = roi_table(rig)
        parts.append(_table(head, rows) if rows else "<p>No reading in this period.</p>")
        if any(r.points for r in rig.rois):
            parts.append(_png(trend_png(rig.rois), f"trend of {rig.name}'s readings"))
        parts.append(f"<h3>Events ({len(rig.events)})</h3>")
        if not rig.events:
            parts.append("<p>No event in this period.</p>")
        for ev in rig.events:
            lines = event_lines(ev)
            body = f"<b>{e(lines[0])}</b>" + "".join(f"<br>{e(x)}" for x in lines[1:])
            picture = "" if ev.picture is None else _png(ev.picture, f"event {ev.event['id']}")
            parts.append(f"<div class='event'>{body}<br>{picture}</div>")
    parts.append(f"<!-- {e(SEVERITY_NOTE)} --></body></html>\n")
    out.write_text("".join(parts), encoding="utf-8")
