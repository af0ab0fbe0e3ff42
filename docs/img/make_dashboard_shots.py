"""Remake docs/img/dashboard-*.png: the monitor's dashboard in a headless browser, on two
simulated rigs in real time (one raising a latched alarm, later acknowledged).

    .venv/bin/python docs/img/make_dashboard_shots.py    # from the repository's root

Needs the `monitor` and `dev` extras and Debian's chromium and chromium-driver (as the
browser tests do: tests/browser.py drives them).
"""

import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))

import browser  # noqa: E402
from monitor_helpers import monitor_config, settings_file, wait_for  # noqa: E402
from thermodepth.monitor import Monitor, load_config  # noqa: E402

OUT = Path(__file__).resolve().parent
SETTINGS = """\
hotspots: {threshold_c: 50}
rois:
  - {name: plate, rect: [548, 266, 734, 452]}
  - {name: chip, rect: [648, 299, 708, 359]}
alarms:
  - {name: chip-hot, above_c: 60, for_s: 2, latch: true}
  - {name: plate-warm, what: plate, stat: mean, above_c: 35, level: warning}
"""
QUIET = "hotspots: {threshold_c: 50}\nrois:\n  - {name: plate, rect: [548, 266, 734, 452]}\n"


def shoot(driver, url: str, name: str, ready: str, height: int = 860) -> None:
    from selenium.webdriver.common.by import By

    driver.set_window_size(driver.get_window_size()["width"], height)
    driver.get(url)
    wait_for(lambda: driver.find_elements(By.CSS_SELECTOR, ready), 15)
    time.sleep(2.5)  # live pictures and tables drawn
    driver.save_screenshot(str(OUT / f"dashboard-{name}.png"))
    print(f"wrote {OUT / f'dashboard-{name}.png'}")


def main() -> None:
    from selenium.webdriver.common.by import By

    if browser.missing():
        sys.exit(browser.missing())
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        settings_file(folder, SETTINGS, "line1.yaml")
        settings_file(folder, QUIET, "line2.yaml")
        (folder / "token").write_text("s3cret\n")
        rigs = [
            {"name": "line1", "source": "sim:pace=real", "settings": "line1.yaml",
             "location": "Transformer bay 1"},
            {"name": "line2", "source": "sim:pace=real", "settings": "line2.yaml",
             "location": "Switchgear room"},
        ]  # fmt: skip
        path = monitor_config(folder, rigs, http={"token_file": "token"})
        monitor = Monitor(load_config(path), lambda line: None)
        monitor.start()
        driver = browser.chromium(1280, 860)
        try:
            url = monitor.http.url
            driver.get(f"{url}/login")
            time.sleep(1.0)
            driver.save_screenshot(str(OUT / "dashboard-login.png"))
            browser.fill_login(driver, "s3cret")
            wait_for(lambda: any(e.get("clip") for e in monitor.store.events(50)), 30)
            time.sleep(32)  # the clip's pictures written, points in the trend (every 10 s)
            shoot(driver, f"{url}/", "overview", "section.card[data-rig=line2] img")
            shoot(driver, f"{url}/rig/line1", "rig", "button[data-ack=chip-hot]", 1300)
            driver.find_element(By.CSS_SELECTOR, "button[data-ack=chip-hot]").click()
            time.sleep(1.0)
            shoot(driver, f"{url}/events", "events", "#events tr[data-event]", 1000)
            shoot(driver, f"{url}/health", "health", "section.card[data-rig=line2]", 1250)
            driver.set_window_size(412, 900)  # a phone
            shoot(driver, f"{url}/", "phone", "section.card[data-rig=line2] img", 1500)
        finally:
            driver.quit()
            monitor.stop()


if __name__ == "__main__":
    main()
