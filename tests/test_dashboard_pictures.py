"""The dashboard's pictures in a real headless browser (Debian's chromium through selenium):
a rig that never sent a frame shows "no picture yet" (never a broken image) and is not asked
for one; a stale rig's last picture is dimmed and dated, and not asked for again; the ROI
trend's sparkline has its scale. Skipped, naming what is missing, where chromium,
chromium-driver or selenium are absent."""

from __future__ import annotations

import math
import re
import threading
import time
from collections import Counter
from functools import partial
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the dashboard needs the monitor extra (starlette)")

import browser
from monitor_helpers import monitor_config, settings_file, wait_for
from thermodepth.monitor import Monitor, load_config

pytestmark = pytest.mark.skipif(browser.missing() is not None, reason=browser.missing() or "")

SETTINGS = """\
hotspots:
  threshold_c: 50
rois:
  - {name: plate, rect: [560, 280, 720, 440]}
"""
GONE_S = 15
"""``gone`` is unplugged for good this long after it first opened (the fixture has made sure
its monitor keeps a picture of it by then)."""


@pytest.fixture(scope="module")
def rigs(tmp_path_factory: pytest.TempPathFactory) -> Any:
    """A browser, logged in, and a monitor of three simulated rigs in real time: ``live``,
    ``gone`` (unplugged after GONE_S: stale) and ``never`` (unplugged from the start: no
    frame, ever); with the picture and status requests its server answered, by rig."""
    folder = tmp_path_factory.mktemp("pictures")
    settings_file(folder, SETTINGS)
    (folder / "token").write_text("s3cret\n")
    sources = {
        "live": "sim:pace=real",
        "gone": f"sim:pace=real,faults=unplug@{GONE_S}s+100000s",
        "never": "sim:pace=real,faults=unplug@0s+100000s",
    }
    rigs = [{"name": n, "source": s, "settings": "s.yaml"} for n, s in sources.items()]
    path = monitor_config(folder, rigs, http={"token_file": "token"})
    monitor = Monitor(load_config(path))
    asked: Counter[str] = Counter()
    lock = threading.Lock()
    picture, status = monitor.picture, monitor.status

    def counted_picture(rig: str, what: str, width: int | None = None) -> Any:
        with lock:
            asked[rig] += 1
        return picture(rig, what, width)

    def counted_status() -> Any:
        with lock:
            asked["status"] += 1
        return status()

    monitor.picture = counted_picture  # type: ignore[method-assign]
    monitor.status = counted_status  # type: ignore[method-assign]
    monitor.start()
    driver = browser.chromium()
    try:
        # the monitor keeps a rig's frames for the screens only while someone looks: look at
        # gone until it has one, so that it has a last picture when it goes
        wait_for(lambda: picture("gone", "overlay", None), GONE_S)
        driver.get(f"{monitor.http.url}/")
        wait_for(lambda: "/login" in driver.current_url)
        browser.fill_login(driver, "s3cret")
        wait_for(lambda: driver.find_elements("css selector", "section.card[data-rig=never]"))
        yield monitor, driver, asked, lock
    finally:
        driver.quit()
        monitor.stop()


def shown(driver: Any, box: str) -> Any:
    """What a picture's frame shows: whether its image is displayed and loaded, its CSS
    filter, the note over it, and its classes (None: not on the page)."""
    return driver.execute_script(
        """const box = document.querySelector(arguments[0]);
        if (!box) return null;
        const img = box.querySelector("img");
        return {displayed: getComputedStyle(img).display !== "none" && img.offsetWidth > 0,
                loaded: img.complete && img.naturalWidth > 0,
                filter: getComputedStyle(img).filter,
                note: box.querySelector(".note").innerText.trim(),
                classes: [...box.classList]};""",
        box,
    )


def polls(asked: Counter[str], lock: threading.Lock, n: int, timeout_s: float) -> Counter[str]:
    """The picture requests by rig while the page asked for its status ``n`` more times."""
    with lock:
        before = Counter(asked)
    wait_for(lambda: asked["status"] >= before["status"] + n, timeout_s, every_s=0.1)
    with lock:
        return Counter({k: asked[k] - before[k] for k in asked})


def test_a_rig_that_never_sent_a_frame_shows_no_picture_yet_and_is_not_asked(rigs: Any) -> None:
    monitor, driver, asked, lock = rigs
    driver.get(f"{monitor.http.url}/")
    card = "section.card[data-rig=never] .pic"
    seen = wait_for(lambda: (s := shown(driver, card)) and "no picture yet" in s["note"] and s)
    assert not seen["displayed"], "no image shown, so no broken one"
    # the live rig's picture comes meanwhile: the page does ask for pictures
    wait_for(lambda: shown(driver, "section.card[data-rig=live] .pic")["loaded"])
    during = polls(asked, lock, 6, 60)  # the overview asks for the status every second
    assert during["never"] == 0, during
    assert during["live"] >= 3, during
    assert asked["never"] == 0
    assert "no picture yet" in shown(driver, card)["note"]
    assert not shown(driver, card)["displayed"]


def test_a_stale_rigs_last_picture_is_dimmed_dated_and_not_asked_again(rigs: Any) -> None:
    monitor, driver, asked, lock = rigs
    driver.get(f"{monitor.http.url}/")
    card = "section.card[data-rig=gone] .pic"

    def stale(box: str) -> Any:
        """What the frame shows once its picture is loaded and marked stale (else None)."""
        s = shown(driver, box)
        return s if s and "stale" in s["classes"] and s["loaded"] else None

    seen = wait_for(lambda: stale(card), GONE_S + 30)
    assert seen["displayed"] and "grayscale(1)" in seen["filter"]
    assert re.fullmatch(r"stale · last frame \d+ (s|min) ago", seen["note"]), seen["note"]
    # asked once more at most, for the frames it had when it went stale; then no more
    assert polls(asked, lock, 2, 60)["gone"] <= 1
    during = polls(asked, lock, 4, 60)
    assert during["gone"] == 0, during  # its last picture is shown: it cannot change
    # the rig's page: both of its pictures dimmed and dated
    driver.get(f"{monitor.http.url}/rig/gone")
    for box in (".pic.wide", ".pic.thermal"):
        seen = wait_for(partial(stale, box))
        assert "grayscale(1)" in seen["filter"]
        assert seen["note"].startswith("stale · last frame ")
    hottest = driver.execute_script("return document.querySelector('#reading .hottest').innerText")
    assert re.search(r"the last, \d+ (s|min) ago", hottest), hottest


def scale(values: list[float]) -> tuple[float, float]:
    """A sparkline's scale (C): its values' lowest and highest, 0.1 C outward, at least
    1 C apart (about their middle)."""
    mid = (min(values) + max(values)) / 2
    return math.floor(min(*values, mid - 0.5) * 10) / 10, math.ceil(
        max(*values, mid + 0.5) * 10
    ) / 10


def test_the_roi_trend_has_its_scale(rigs: Any) -> None:
    monitor, driver, _, _ = rigs
    driver.get(f"{monitor.http.url}/rig/live")

    def agree() -> Any:
        """The sparkline's labels and the trend fetched now, once they tell the same."""
        got = driver.execute_script(
            """const t = document.querySelector("#rois tr[data-roi=plate] .trend");
            if (!t) return null;
            const trend = await (await fetch("/api/rigs/live/trend")).json();
            const box = (s) => t.querySelector(s).getBoundingClientRect();
            const when = [...t.querySelectorAll(".when span")].map((e) => e.innerText);
            const text = (s) => t.querySelector(s).innerText;
            return {trend, n: Number(t.dataset.points), hi: text(".hi"), lo: text(".lo"),
                    when, size: parseFloat(getComputedStyle(t.querySelector(".hi")).fontSize),
                    svg: box("svg"), hiBox: box(".hi"), loBox: box(".lo")};"""
        )
        if not got:
            return None
        points = [p for p in got["trend"] if p["rois"].get("plate") is not None]
        values = [p["rois"]["plate"] for p in points]
        # the page drawn from the trend as fetched here (a point comes every 10 s)
        return (got, points, values) if len(values) >= 2 and got["n"] == len(values) else None

    got, points, values = wait_for(agree, every_s=0.5)  # a point every 10 s
    lo, hi = scale(values)
    assert (got["lo"], got["hi"]) == (f"{lo:.1f} °C", f"{hi:.1f} °C")
    assert lo <= min(values) and max(values) <= hi and hi - lo > 0.999
    t0, t1 = points[0]["time_s"], points[-1]["time_s"]
    start, span, end = got["when"]
    assert start == time.strftime("%H:%M", time.localtime(t0))
    assert end == time.strftime("%H:%M", time.localtime(t1))
    seconds = t1 - t0
    assert span == (f"{int(seconds)} s" if seconds < 60 else f"{int(seconds // 60)} min")
    # readable: 12 px type, max at the top of the line, min at its bottom, beside it
    assert got["size"] >= 12
    svg, top, bottom = got["svg"], got["hiBox"], got["loBox"]
    assert top["left"] >= svg["right"] and bottom["left"] >= svg["right"]
    assert abs(top["top"] - svg["top"]) < 6 and abs(bottom["bottom"] - svg["bottom"]) < 6
