"""The dashboard in a real headless browser (Debian's chromium through selenium) against a
monitor of two simulated rigs in real time on a real Mosquitto: logging in (a wrong token
refused), the overview of every rig with live overlays, an alarm rule added while the page
looks (a reload) and its alarm coming onto the screen by itself, acknowledged from the rig's
page into the event store and onto MQTT, and every page drawn from the API. Skipped, naming
what is missing, where chromium, chromium-driver, selenium or mosquitto are absent."""

from __future__ import annotations

import time
from datetime import datetime
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the dashboard needs the monitor extra (starlette)")
pytest.importorskip("paho.mqtt.client", reason="the monitor's MQTT needs the mqtt extra")

import browser
import mqtt_broker
from monitor_helpers import monitor_config, settings_file, wait_for
from thermodepth.monitor import Monitor, load_config
from thermodepth.sinks.mqtt import PASSWORD_ENV

pytestmark = [
    pytest.mark.skipif(browser.missing() is not None, reason=browser.missing() or ""),
    pytest.mark.skipif(mqtt_broker.missing() is not None, reason=mqtt_broker.missing() or ""),
]

WATCHED = """\
hotspots:
  threshold_c: 50
rois:
  - {name: plate, rect: [560, 280, 720, 440], severity: {criteria: neta-ambient}}
"""
SLOW_ALARM = (
    WATCHED
    + """\
alarms:
  - {name: slow, above_c: 60, latch: true}
"""
)
"""The chip reads about 67.5 C: ``slow`` is raised as soon as the rule is there (the config
reloaded while the browser looks) and stays until acknowledged."""


def raise_slow(monitor: Monitor) -> None:
    """Add the rule ``slow`` to both rigs' settings and reload the config (once)."""
    settings = monitor.runners["a"].config.settings
    assert settings is not None
    if "slow" not in settings.read_text():
        settings.write_text(SLOW_ALARM)
        monitor.reload(load_config(settings.parent / "monitor.yaml"))


@pytest.fixture(scope="module")
def plant(tmp_path_factory: pytest.TempPathFactory) -> Any:
    """A broker, a browser, and a monitor of rigs ``a`` and ``b`` (paced simulators) with a
    token, publishing under ``plant/``."""
    folder = tmp_path_factory.mktemp("browser")
    broker = mqtt_broker.Broker()
    broker.start()
    mp = pytest.MonkeyPatch()
    mp.setenv(PASSWORD_ENV, broker.password)
    driver = browser.chromium()
    collector = None
    monitor = None
    try:
        collector = mqtt_broker.Collector(broker, "plant/+/alarms")
        settings_file(folder, WATCHED)
        (folder / "token").write_text("s3cret\n")
        rigs = [{"name": n, "source": "sim:pace=real", "settings": "s.yaml"} for n in "ab"]
        path = monitor_config(
            folder,
            rigs,
            http={"token_file": "token"},
            mqtt={"url": broker.url("plant"), "connect_timeout_s": 2},
        )
        monitor = Monitor(load_config(path))
        monitor.start()
        yield monitor, driver, collector
    finally:
        if monitor is not None:
            monitor.stop()
        if collector is not None:
            collector.close()
        driver.quit()
        mp.undo()
        broker.cleanup()


def log_in(driver: Any, url: str, token: str) -> None:
    driver.get(f"{url}/")
    wait_for(lambda: "/login" in driver.current_url)
    browser.fill_login(driver, token)


def texts(driver: Any, selector: str, attribute: str | None = None) -> list[str]:
    """The text (or an attribute) of each element matching ``selector``, read at once."""
    script = (
        "return [...document.querySelectorAll(arguments[0])]"
        ".map((e) => arguments[1] ? e.getAttribute(arguments[1]) : e.innerText)"
    )
    return list(driver.execute_script(script, selector, attribute))


def click(driver: Any, selector: str) -> None:
    """A user's click on the element, found again if the page drew it anew meanwhile."""
    from selenium.common.exceptions import StaleElementReferenceException
    from selenium.webdriver.common.by import By

    for _ in range(5):
        try:
            driver.find_element(By.CSS_SELECTOR, selector).click()
            return
        except StaleElementReferenceException:
            continue
    raise AssertionError(f"{selector}: drawn anew each time it was clicked")


def cells(driver: Any, selector: str) -> list[list[str]]:
    """The text of each cell of each row matching ``selector``, read at once (the pages
    draw their tables again every second or two)."""
    return list(driver.execute_script(
        "return [...document.querySelectorAll(arguments[0])].map((r) =>"
        " [...r.querySelectorAll('td')].map((c) => c.innerText))", selector))  # fmt: skip


def picture_sum(driver: Any, selector: str) -> Any:
    """The sum of an image's pixels as the page shows it (None: not loaded yet)."""
    return driver.execute_script(
        """const img = document.querySelector(arguments[0]);
        if (!img || !img.complete || !img.naturalWidth) return null;
        const c = document.createElement("canvas");
        c.width = img.naturalWidth; c.height = img.naturalHeight;
        const g = c.getContext("2d"); g.drawImage(img, 0, 0);
        const pixels = g.getImageData(0, 0, c.width, c.height).data;
        return [img.naturalWidth, pixels.reduce((a, b) => a + b, 0)];""",
        selector,
    )


def test_the_overview_shows_every_rig_live_and_an_alarm_as_it_comes(plant: Any) -> None:
    from selenium.webdriver.common.by import By

    monitor, driver, _ = plant
    log_in(driver, monitor.http.url, "s3cret")
    wait_for(lambda: driver.find_elements(By.CSS_SELECTOR, "section.card[data-rig=b] img"))
    assert texts(driver, "section.card", "data-rig") == ["a", "b"]

    # the alarm comes onto the page by itself, after it was raised (how soon: bench_dashboard)
    assert not monitor.store.events(10)  # no rule yet
    raise_slow(monitor)
    shown = "section.card[data-rig=a] li[data-alarm=slow]"
    wait_for(lambda: texts(driver, shown), every_s=0.02)
    seen_s = time.time()
    raised = [e for e in monitor.store.events(10) if e["rule"] == "slow" and e["rig"] == "a"]
    assert seen_s > datetime.fromisoformat(raised[-1]["time_utc"]).timestamp()
    assert texts(driver, shown)[0].lower().split() == ["alarm", "slow"]

    # the overlays: each card's picture loaded, 640 px wide, and a new one each time asked
    for rig in "ab":
        img = f"section.card[data-rig={rig}] img.live"
        # (a busy machine may take seconds to hand chromium a picture: the bounds are loose)
        first = wait_for(lambda img=img: picture_sum(driver, img))
        assert first[0] == 640
        wait_for(lambda img=img, first=first: picture_sum(driver, img) not in (None, first))
    assert 60 < float(texts(driver, "section.card[data-rig=a] .hottest", "data-hottest")[0]) < 75
    # the healthy rig reads ok (a busy machine can leave it stale a moment: waited for)
    wait_for(lambda: texts(driver, "section.card[data-rig=b] .state")[0].lower() == "ok")


def test_acknowledge_on_the_rig_page_reaches_the_event_store_and_mqtt(plant: Any) -> None:

    monitor, driver, collector = plant
    raise_slow(monitor)
    wait_for(lambda: any(e["rule"] == "slow" for e in monitor.store.events(10_000, rig="a")))
    driver.get(f"{monitor.http.url}/rig/a")
    wait_for(lambda: texts(driver, "button[data-ack=slow]"))
    collector.drain(0.2)
    click(driver, "button[data-ack=slow]")

    def acknowledged() -> Any:
        return [e for e in monitor.store.events(10_000, rig="a", state="acknowledged")
                if e["rule"] == "slow"]  # fmt: skip

    stored = wait_for(acknowledged)[0]
    assert stored["by"] == "operator jane"
    published = wait_for(
        lambda: [m for t, m, _ in collector.drain(0.2)
                 if t == "plant/a/alarms" and m.get("event") == "acknowledged"],
    )  # fmt: skip
    assert published[0]["by"] == "operator jane" and published[0]["rule"] == "slow"
    # still hot, so still raised: shown acknowledged, without its button
    note = wait_for(lambda: texts(driver, "[data-alarm=slow] [data-acknowledged]"))
    assert note == ["acknowledged by operator jane"]
    assert not texts(driver, "button[data-ack=slow]")
    # the ROI table and its trend
    row = wait_for(lambda: cells(driver, "#rois tr[data-roi=plate]"))[0]
    assert row[0] == "plate" and 60 < float(row[1]) < 75
    # its severity class: the chip's max (some 67 C) is over 40 C above the 25 C air
    words = row[4].lower()  # (the badge's letters are shown in capitals)
    assert words.startswith("p1 major discrepancy δt 4") and words.endswith("°c vs ambient")
    assert texts(driver, "#rois tr[data-roi=plate] [data-priority='1'] .badge.p1")
    assert wait_for(lambda: picture_sum(driver, "#thermal"))[0] > 0


def test_the_events_and_health_pages(plant: Any) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    monitor, driver, _ = plant
    raise_slow(monitor)
    wait_for(lambda: {e["rig"] for e in monitor.store.events(100)} == {"a", "b"})
    driver.get(f"{monitor.http.url}/events")
    rows = wait_for(lambda: {r[1] for r in cells(driver, "#events tr[data-event]")} == {"a", "b"})
    assert rows  # both rigs raised "slow"
    Select(driver.find_element(By.ID, "state")).select_by_visible_text("acknowledged")

    def only_acknowledged() -> list[list[str]]:
        rows = cells(driver, "#events tr[data-event]")
        return rows if rows and all(r[4].lower() == "acknowledged" for r in rows) else []

    acked = wait_for(only_acknowledged)  # the filtered page, not the one before it
    assert acked[0][1:3] == ["a", "slow"] and "by operator jane" in acked[0][6]
    driver.get(f"{monitor.http.url}/health")
    cards = wait_for(lambda: texts(driver, "section.card[data-rig]", "data-rig"))
    assert cards == ["a", "b"]
    assert texts(driver, "a[href='/metrics']") == ["Prometheus metrics"]
    workers = set(wait_for(lambda: texts(driver, "#workers tr[data-worker]", "data-worker")))
    assert workers == {"clock", "storage", "evidence pictures", "http", "mqtt outbox",
                       "mqtt snapshots"}  # fmt: skip
    assert not texts(driver, "#workers tr.unwell")
    assert "connected true" in texts(driver, "#outputs")[0]


def test_a_wrong_token_is_refused(plant: Any) -> None:
    from selenium.webdriver.common.by import By

    monitor, driver, _ = plant
    driver.delete_all_cookies()
    log_in(driver, monitor.http.url, "wrong")
    error = wait_for(lambda: driver.find_element(By.ID, "error").text)
    assert "token" in error.lower()
    assert "/login" in driver.current_url
    status = driver.execute_script(
        "return (await fetch('/api/status', {headers: {Authorization: 'Bearer wrong'}})).status"
    )
    assert status == 401
    driver.get(f"{monitor.http.url}/rig/a")
    assert "/login?next=/rig/a" in driver.current_url
