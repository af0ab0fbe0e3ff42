"""Remake docs/img/dashboard-*.png: the monitor's dashboard in a headless browser, on four
simulated rigs in real time: one raising a latched alarm (later acknowledged) and a warning
on an ROI, one quiet, one unplugged for good after 30 s (stale, its last picture dimmed) and
one that never sent a frame (no picture yet); and an event's snapshot.

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

import cv2  # noqa: E402
import httpx  # noqa: E402
import numpy as np  # noqa: E402

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
GONE_S = 30  # line3 is unplugged for good this long after it first opened


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
            {"name": "line3", "source": f"sim:pace=real,faults=unplug@{GONE_S}s+100000s",
             "settings": "line2.yaml", "location": "Cable tunnel"},
            {"name": "spare", "source": "sim:pace=real,faults=unplug@0s+100000s",
             "settings": "line2.yaml", "location": "Not wired yet"},
        ]  # fmt: skip
        path = monitor_config(folder, rigs, http={"token_file": "token"})
        monitor = Monitor(load_config(path))
        monitor.start()
        driver = browser.chromium(1280, 860)
        try:
            url = monitor.http.url
            driver.get(f"{url}/login")
            time.sleep(1.0)
            driver.save_screenshot(str(OUT / "dashboard-login.png"))
            browser.fill_login(driver, "s3cret")
            wait_for(lambda: any(e.get("clip") for e in monitor.store.events(50)), 30)
            time.sleep(75)  # the clip's pictures written, a minute of trend (every 10 s)
            shoot(driver, f"{url}/", "overview", ".pic.stale", 1250)
            shoot(driver, f"{url}/rig/line1", "rig", "button[data-ack=chip-hot]", 1300)
            driver.find_element(By.CSS_SELECTOR, "button[data-ack=chip-hot]").click()
            time.sleep(1.0)
            shoot(driver, f"{url}/events", "events", "#events tr[data-event]", 1000)
            # an ROI's warning: its snapshot (a download), the plate outlined in red
            raised = next(e for e in monitor.store.events(100) if e["rule"] == "plate-warm")
            snapshot = httpx.get(f"{url}/api/events/{raised['id']}/snapshot.png",
                                 headers={"Authorization": "Bearer s3cret"})  # fmt: skip
            png = np.frombuffer(snapshot.raise_for_status().content, np.uint8)
            img = np.asarray(cv2.imdecode(png, cv2.IMREAD_COLOR))  # at 2/3: a page needs no more
            small = cv2.resize(img, None, fx=2 / 3, fy=2 / 3, interpolation=cv2.INTER_AREA)
            cv2.imwrite(
                str(OUT / "dashboard-snapshot.png"), small, [cv2.IMWRITE_PNG_COMPRESSION, 9]
            )
            print(f"wrote {OUT / 'dashboard-snapshot.png'}")
            shoot(driver, f"{url}/health", "health", "section.card[data-rig=line2]", 1250)
            driver.set_window_size(412, 900)  # a phone
            shoot(driver, f"{url}/", "phone", "section.card[data-rig=line2] img", 1500)
        finally:
            driver.quit()
            monitor.stop()


if __name__ == "__main__":
    main()
