"""Remake docs/img/report-page.png: a rig's page of the inspection report of a short run of
the monitor on the simulated rig (its alarms' clips and overlays real).

    .venv/bin/python docs/img/make_report_page.py    # from the repository's root

Needs poppler's pdftoppm (Debian package poppler-utils).
"""

import shutil
import subprocess
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import yaml

from thermodepth.app.report import make_report
from thermodepth.monitor import Monitor, load_config

SETTINGS = """\
hotspots: {threshold_c: 50}
rois:
  - {name: chip, rect: [560, 280, 720, 440]}
  - {name: panel, rect: [400, 200, 880, 520], emissivity: 0.9}
alarms:
  - {name: hot, above_c: 60, latch: true}
  - {name: chip-warm, what: chip, level: warning, above_c: 67.58, clear_below_c: 67.4}
"""
OUT = Path(__file__).resolve().parent / "report-page.png"
RUN_S = 130  # three minutes of readings (the first and last partial)


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "s.yaml").write_text(SETTINGS, encoding="utf-8")
        config = {
            "rigs": [{"name": "press7", "source": "sim", "settings": "s.yaml",
                      "location": "Hall 2, panel 3"}],
            "storage": {"path": "store", "pre_s": 1, "post_s": 1, "clip_max_s": 3},
            "http": {"listen": None},
        }  # fmt: skip
        (folder / "monitor.yaml").write_text(yaml.safe_dump(config), encoding="utf-8")
        monitor = Monitor(load_config(folder / "monitor.yaml"))
        monitor.start()
        rig = monitor.runners["press7"]
        acked = False
        end = time.monotonic() + RUN_S
        while time.monotonic() < end:
            time.sleep(1)
            if not acked and any(a["rule"] == "hot" for a in rig.raised()):
                monitor.acknowledge("press7", "hot", "alice")
                acked = True
        monitor.stop()
        today = datetime.now(timezone.utc).date().isoformat()
        pdf = folder / "report.pdf"
        make_report(folder / "monitor.yaml", today, today, pdf)
        subprocess.run(["pdftoppm", "-r", "70", "-png", "-f", "2", "-l", "2", str(pdf),
                        str(folder / "page")], check=True)  # fmt: skip
        shutil.copy(next(folder.glob("page*.png")), OUT)
        print(OUT)


if __name__ == "__main__":
    main()
