"""The inspection report (``thermodepth report``, thermodepth.app.report): made from an event
store with known events and readings, its PDF read back with poppler's ``pdftotext``,
``pdftoppm`` and ``pdfimages`` (Debian poppler-utils) and its HTML parsed: the values in them
are the store's."""

from __future__ import annotations

import base64
import json
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from monitor_helpers import monitor_config
from thermodepth.app.report import make_report, parse_period
from thermodepth.cli import app
from thermodepth.errors import FieldError
from thermodepth.monitor.service import STORE_NAME
from thermodepth.monitor.store import EventStore
from thermodepth.sim import default_calibration

POPPLER = all(shutil.which(t) for t in ("pdftotext", "pdftoppm", "pdfimages"))
needs_poppler = pytest.mark.skipif(
    not POPPLER, reason="pdftotext, pdftoppm, pdfimages absent (Debian package poppler-utils)"
)
runner = CliRunner()

SETTINGS = """\
calibration: calib.yaml
radiometry: {emissivity: 0.93, reflected_temp_c: 21.5, ambient_temp_c: 23.5, humidity_pct: 41}
hotspots: {threshold_c: 50}
rois:
  - {name: busbar, rect: [100, 100, 200, 200]}
  - {name: breaker, rect: [300, 100, 400, 200], emissivity: 0.88}
alarms:
  - {name: hot, above_c: 60}
"""


def event(rule: str, kind: str, time_utc: str, **more: Any) -> dict[str, Any]:
    return {"rig": "press7", "rule": rule, "level": "alarm", "event": kind,
            "time_utc": time_utc, **more}  # fmt: skip


def overlay_png() -> bytes:
    """A small picture standing for a clip's overlay (a colour ramp)."""
    ramp = np.linspace(0, 255, 160, dtype=np.uint8)[None, :].repeat(90, axis=0)
    ok, data = cv2.imencode(".png", cv2.applyColorMap(ramp, cv2.COLORMAP_INFERNO))
    assert ok
    return data.tobytes()


@pytest.fixture
def monitored(tmp_path: Path) -> dict[str, Any]:
    """A monitor's config with one rig (press7) and a store holding, in November 2026, a
    raised ``hot`` (61.2 C, its clip kept) acknowledged by alice and cleared, a second raise
    (72.45 C, its clip deleted since) never acknowledged, ten minutes of readings of two ROIs
    and of the whole view; and an event and readings just outside the month."""
    default_calibration().save(tmp_path / "calib.yaml")
    (tmp_path / "s.yaml").write_text(SETTINGS, encoding="utf-8")
    config = monitor_config(
        tmp_path,
        [{"name": "press7", "source": "sim", "settings": "s.yaml", "location": "Hall 2"}],
    )
    store = EventStore(tmp_path / "store" / STORE_NAME)
    clip = "press7/20261103T143501Z-hot"
    (tmp_path / "store" / "clips" / clip).mkdir(parents=True)
    picture = overlay_png()
    (tmp_path / "store" / "clips" / clip / "overlay.png").write_bytes(picture)
    store.add(event("hot", "alarm", "2026-10-31T23:59:59.000+00:00", value_c=99.99))
    ids = [
        store.add(
            event(
                "hot",
                "alarm",
                "2026-11-03T14:35:01.250+00:00",
                value_c=61.2,
                clip=clip,
                condition="max > 60 C",
            )
        )
    ]
    ack = event("hot", "acknowledged", "2026-11-03T14:40:00.000+00:00")
    ack.update(by="alice", at_utc="2026-11-03T14:40:00.000+00:00")
    ids.append(store.add(ack))
    ids.append(store.add(event("hot", "clear", "2026-11-03T15:00:00.000+00:00", value_c=58.1)))
    gone = "press7/20261120T080000Z-hot"
    ids.append(
        store.add(event("hot", "alarm", "2026-11-20T08:00:00.000+00:00", value_c=72.45, clip=gone))
    )
    store.clip_deleted(gone)
    rows = []
    for i in range(10):
        minute = f"2026-11-03T14:{i:02d}:00+00:00"
        rows.append(
            {
                "rig": "press7",
                "roi": "busbar",
                "minute_utc": minute,
                "max_c": 50.0 + i,
                "mean_c": 40.0 + i,
                "min_c": 30.0 + i,
                "frames": 60,
                "distance_m": 1.25,
            }
        )
        rows.append(
            {
                "rig": "press7",
                "roi": "breaker",
                "minute_utc": minute,
                "max_c": 35.5,
                "mean_c": 33.25,
                "min_c": 31.75,
                "frames": 60,
                "distance_m": 1.5,
            }
        )
        rows.append(
            {
                "rig": "press7",
                "roi": "*",
                "minute_utc": minute,
                "max_c": 60.5 + i,
                "mean_c": 60.5 + i,
                "min_c": 60.5 + i,
                "frames": 60,
                "distance_m": 1.1,
            }
        )
    rows.append({"rig": "press7", "roi": "busbar", "minute_utc": "2026-12-01T00:00:00+00:00",
                 "max_c": 999.0, "mean_c": 999.0, "min_c": 999.0, "frames": 1})  # fmt: skip
    store.add_readings(rows)
    store.close()
    return {"config": config, "ids": ids, "picture": picture, "folder": tmp_path}


def pdf_text(path: Path) -> str:
    done = subprocess.run(["pdftotext", "-layout", str(path), "-"], capture_output=True,
                          text=True, check=True)  # fmt: skip
    return done.stdout


def check_values(text: str, ids: list[int]) -> None:
    """What the store holds for November, in the report's words; nothing from outside it."""
    assert "2026-11-01 to 2026-11-30 (UTC)" in text
    for value in ("61.20 °C", "72.45 °C", "58.10 °C"):  # the events' values
        assert value in text
    # busbar: max of the minutes' max, mean of their means, min of their min; its distance
    assert re.search(r"busbar\s+59\.00 °C\s+44\.50 °C\s+30\.00 °C\s+1\.25 m\s+0\.93\s+10", text)
    assert re.search(r"breaker\s+35\.50 °C\s+33\.25 °C\s+31\.75 °C\s+1\.50 m\s+0\.88\s+10", text)
    assert re.search(r"whole view \(hottest spot\)\s+69\.50 °C", text)
    # the summary: 4 events, 2 alarms, 1 acknowledgement, the hottest reading
    assert re.search(r"press7\s+Hall 2\s+4\s+2\s+1\s+69\.50 °C", text)
    assert "acknowledged by alice at 2026-11-03 14:40:00 UTC" in text
    assert "not acknowledged in the period" in text  # the second raise
    assert "no longer kept" in text  # its clip was deleted
    for event_id in ids:
        assert f"#{event_id} " in text
    assert "#1 " not in text and "99.99" not in text and "999.00" not in text
    # the viewing conditions and the calibration
    for told in ("0.93", "21.5 °C", "23.5 °C", "41 %", "calib.yaml", "valid"):
        assert told in text


@needs_poppler
def test_pdf_holds_the_stores_values_and_its_pictures(monitored: dict[str, Any]) -> None:
    out = monitored["folder"] / "report.pdf"
    result = runner.invoke(
        app,
        [
            "report",
            str(monitored["config"]),
            "--from",
            "2026-11-01",
            "--to",
            "2026-11-30",
            "-o",
            str(out),
        ],
    )
    assert result.exit_code == 0, result.output
    assert "1 rigs, 4 events" in result.output
    text = pdf_text(out)
    check_values(" ".join(text.split("\n")), monitored["ids"])
    assert "How to read this" in text
    images = subprocess.run(["pdfimages", "-list", str(out)], capture_output=True, text=True,
                            check=True).stdout.splitlines()[2:]  # fmt: skip
    assert len(images) == 1  # the one kept evidence picture
    assert images[0].split()[3:5] == ["160", "90"]  # its size, pixels
    pages = monitored["folder"] / "pages"
    pages.mkdir()
    subprocess.run(["pdftoppm", "-r", "40", "-png", str(out), str(pages / "p")], check=True)
    pngs = sorted(pages.glob("p-*.png"))
    assert len(pngs) >= 2  # the summary, the rig (its events may go on)
    for png in pngs:
        image = cv2.imread(str(png))
        assert image is not None and image.shape[0] > image.shape[1]  # portrait
        assert (image < 128).any()  # something is drawn on it


def test_html_holds_the_same_values_and_embeds_the_picture(monitored: dict[str, Any]) -> None:
    out = monitored["folder"] / "report.html"
    report = make_report(monitored["config"], "2026-11-01", "2026-11-30", out)
    assert report.events == 4 and not report.empty
    page = out.read_text(encoding="utf-8")
    text = re.sub(r"<[^>]+>", "  ", page).replace("&#x27;", "'")
    check_values(" ".join(text.split("\n")).replace("  ", " " * 2), monitored["ids"])
    embedded = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    assert len(embedded) == 2  # the trend, the evidence picture
    assert base64.b64decode(embedded[1]) == monitored["picture"]
    assert 'src="http' not in page and "href=" not in page  # self-contained


def test_an_empty_period_makes_a_valid_report_that_says_so(monitored: dict[str, Any]) -> None:
    out = monitored["folder"] / "empty.html"
    report = make_report(monitored["config"], "2025-01-01", "2025-01-31", out)
    assert report.empty and report.events == 0
    page = out.read_text(encoding="utf-8")
    assert "Nothing was recorded in this period" in page
    assert "2025-01-01 to 2025-01-31 (UTC)" in page


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["--from", "2026-13-01", "--to", "2026-11-30"], "--from: '2026-13-01' is not a date"),
        (["--from", "2026-11-30", "--to", "2026-11-01"], "--to: '2026-11-01' is before --from"),
        (["--from", "2026-11-01", "--to", "soon"], "--to: 'soon' is not a date"),
        (["--from", "2026-11-01", "--to", "2026-11-30", "-o", "r.docx"], "--out: r.docx: a "),
    ],
)
def test_bad_options_are_one_line(monitored: dict[str, Any], args: list[str], line: str) -> None:
    result = runner.invoke(app, ["report", str(monitored["config"]), *args])
    assert result.exit_code == 2
    lines = [x for x in result.output.splitlines() if x.strip()]
    assert len(lines) == 1 and line in lines[0], result.output


def test_a_config_whose_monitor_never_ran_is_one_line(tmp_path: Path) -> None:
    config = monitor_config(tmp_path, [{"name": "a", "source": "sim"}])
    result = runner.invoke(app, ["report", str(config), "--from", "2026-11-01",
                                 "--to", "2026-11-02", "-o", str(tmp_path / "r.pdf")])  # fmt: skip
    assert result.exit_code == 2
    assert "no event store there" in result.output
    assert not (tmp_path / "store" / STORE_NAME).exists()  # nothing made by asking


def test_periods() -> None:
    day = parse_period("2026-11-05", "2026-11-05")
    assert (day.start_utc, day.end_utc) == (
        "2026-11-05T00:00:00+00:00",
        "2026-11-06T00:00:00+00:00",
    )
    assert day.label() == "2026-11-05 (UTC)"
    span = parse_period("2026-11-05T10:00", "2026-11-05T12:30+01:00")
    assert span.end_utc == "2026-11-05T11:30:00+00:00"
    with pytest.raises(FieldError, match="to"):
        parse_period("2026-11-05T10:00", "2026-11-05T10:00")


# -- scheduled by the monitor -------------------------------------------------------------------


class Mailbox:
    """aiosmtpd's handler: keeps every message."""

    def __init__(self) -> None:
        self.messages: list[bytes] = []

    async def handle_DATA(self, server: Any, session: Any, envelope: Any) -> str:  # noqa: N802
        self.messages.append(envelope.content)
        return "250 OK"


def test_the_monitor_makes_sends_keeps_and_deletes_its_reports(
    monitored: dict[str, Any],
) -> None:
    pytest.importorskip("aiosmtpd", reason="the e-mail test's SMTP server is aiosmtpd")
    import email
    import socket

    import yaml
    from aiosmtpd.controller import Controller

    from test_monitor_notify import SECRET, Receiver
    from thermodepth.monitor import Monitor, load_config
    from thermodepth.monitor.storage import Retention

    folder = monitored["folder"]
    hook = Receiver()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    box = Mailbox()
    smtp = Controller(box, hostname="127.0.0.1", port=port)
    smtp.start()
    (folder / "hook.key").write_text(SECRET + "\n", encoding="utf-8")
    data = yaml.safe_load(monitored["config"].read_text(encoding="utf-8"))
    data["http"]["public_url"] = "https://monitor.example/thermo"
    data["notify"] = [
        {"kind": "webhook", "name": "ops", "url": hook.url(), "secret_file": "hook.key"},
        {"kind": "email", "name": "desk", "smtp": f"127.0.0.1:{port}", "starttls": False,
         "from": "monitor@plant.example", "to": ["maintenance@plant.example"]},
    ]  # fmt: skip
    data["reports"] = [
        {"every": "month", "to": "ops"},
        {"every": "month", "to": "email:desk", "format": "html"},
    ]
    monitored["config"].write_text(yaml.safe_dump(data), encoding="utf-8")
    monitor = Monitor(load_config(monitored["config"]))
    now_s = datetime_s("2026-12-01T00:30:00+00:00")
    monitor.reports.started_s = now_s
    try:
        made = monitor.reports.run(now_s)
        names = sorted(p.name for p in made)
        assert names == ["20261201T000000Z-month.html", "20261201T000000Z-month.pdf"]
        pdf, page = sorted(made, key=lambda p: p.suffix != ".pdf")
        if POPPLER:
            check_values(" ".join(pdf_text(pdf).split("\n")), monitored["ids"])
        # the webhook: one signed POST naming the file, with its link
        [request] = hook.requests()
        assert request["ok"] and request["id"] == f"report-{pdf.name}"
        told = json.loads(request["body"])["report"]
        assert told["file"] == pdf.name and told["path"] == str(pdf)
        assert told["period"] == "2026-11-01 to 2026-11-30 (UTC)"
        assert told["summary"] == "1 rigs, 4 events"
        assert told["link"] == f"https://monitor.example/thermo/api/reports/{pdf.name}"
        # the e-mail: the HTML attached, byte for byte
        [raw] = box.messages
        message = email.message_from_bytes(raw)
        assert "inspection report 2026-11-01 to 2026-11-30" in message["Subject"]
        [attached] = [p for p in message.walk() if p.get_filename() == page.name]
        assert attached.get_payload(decode=True) == page.read_bytes()
        # looked again: nothing made or sent twice; the route serves only kept reports' names
        assert monitor.reports.run(now_s + 60) == []
        assert len(hook.requests()) == 1 and len(box.messages) == 1
        assert monitor.reports.status()["sent"] == 2
        assert monitor.report_file(pdf.name) == pdf
        assert monitor.report_file("../events.sqlite") is None
        # the storage rule: gone with their markers once older than retention_days (30)
        rule = Retention(monitor.config.storage, set, lambda clip: None)
        rule.sweep(now_s + 29 * 86400)
        assert pdf.exists() and page.exists()
        rule.sweep(now_s + 31 * 86400)
        assert not any((folder / "store" / "reports").iterdir())
        assert rule.deleted["reports"] == 4  # two reports, two markers
    finally:
        monitor.stop()
        smtp.stop()
        hook.close()


def datetime_s(text: str) -> float:
    from datetime import datetime

    return datetime.fromisoformat(text).timestamp()


def test_a_report_to_an_unknown_target_is_one_line(monitored: dict[str, Any]) -> None:
    import yaml

    from thermodepth.errors import InputError
    from thermodepth.monitor import load_config

    data = yaml.safe_load(monitored["config"].read_text(encoding="utf-8"))
    data["reports"] = [{"every": "week", "to": "nobody"}]
    monitored["config"].write_text(yaml.safe_dump(data), encoding="utf-8")
    with pytest.raises(InputError, match=r"reports\.0\.to: 'nobody': no notify target"):
        load_config(monitored["config"])


def test_the_periods_just_ended() -> None:
    from datetime import datetime, timezone

    from thermodepth.monitor.reports import last_period

    now = datetime(2026, 11, 26, 9, 15, tzinfo=timezone.utc)  # a Thursday
    assert last_period("day", now).label() == "2026-11-25 (UTC)"
    assert last_period("week", now).label() == "2026-11-16 to 2026-11-22 (UTC)"
    assert last_period("month", now).label() == "2026-10-01 to 2026-10-31 (UTC)"
    assert last_period("month", datetime(2027, 1, 1, tzinfo=timezone.utc)).label() == (
        "2026-12-01 to 2026-12-31 (UTC)"
    )


def test_a_running_monitor_keeps_its_readings_a_row_a_minute(tmp_path: Path) -> None:
    from monitor_helpers import FLAPPING, settings_file, wait_for
    from thermodepth.monitor import Monitor, load_config

    rois = "rois:\n  - {name: left, rect: [0, 0, 320, 480]}\n"
    settings = settings_file(tmp_path, FLAPPING + rois)
    config = monitor_config(tmp_path, [{"name": "sim1", "source": "sim",
                                        "settings": settings.name}])  # fmt: skip
    monitor = Monitor(load_config(config))
    monitor.start()
    try:
        wait_for(lambda: monitor.status()["rigs"][0]["frames"] >= 20)
    finally:
        monitor.stop()  # the minute so far is written at the stop
    frames = monitor.status()["rigs"][0]["frames"]
    store = EventStore(tmp_path / "store" / STORE_NAME)
    rows = store.readings("2000-01-01", "2100-01-01")
    store.close()
    assert {r["roi"] for r in rows} <= {"*", "left"} and rows
    hottest = [r for r in rows if r["roi"] == "*"]
    # every frame with a hottest reading counted once (a shutter frame has none)
    assert 0 < sum(r["frames"] for r in hottest) <= frames
    # the simulated chip (70 C at 1 m) reads 67.42-67.59 C (monitor_helpers.FLAPPING)
    assert all(67.3 <= r["min_c"] <= r["mean_c"] <= r["max_c"] <= 67.7 for r in hottest)
    assert all(r["rig"] == "sim1" and r["minute_utc"].endswith(":00+00:00") for r in rows)
    assert all(0.5 < r["distance_m"] < 2.0 for r in hottest)
