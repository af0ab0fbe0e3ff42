"""What an open dashboard costs the monitor, and how old a live picture is when the browser
has it: one rig replaying a recording at its recorded pace (as bench_monitor: a D435 at
1280x720 beside a Lepton 3, 8.7 pairs/s), its monitor's HTTP server, and Debian's chromium
(headless, through selenium) on the overview (one overlay 640 px wide twice a second, the
status every second) or on the rig's page (the overlay at full size and the thermal image
twice a second, the status, trend and events every 2 s).

CPU: the monitor's process (every thread: the rig, the pictures, uvicorn) in cores, over
alternating phases of nobody looking and a page open (medians of the phases). Age: from the
capture time of a picture's frame (its X-Capture-Time) to the moment the browser has it
decoded, for pictures fetched twice a second as the page does; the page shows each until the
next, so what is on screen is up to 0.5 s older.
"""

from __future__ import annotations

import json
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

from thermodepth.monitor import Monitor, load_config

from .bench_monitor import SETTINGS, write_take
from .common import OUT, console

WARMUP_S = 10.0
PHASE_S = 20.0
ROUNDS = 3
AGES = """
const [url, seconds] = arguments, done = arguments[arguments.length - 1], ages = [];
const end = Date.now() + seconds * 1000;
while (Date.now() < end) {
  const asked = Date.now();
  const r = await fetch(url, { cache: "no-store" });
  const captured = Number(r.headers.get("X-Capture-Time"));
  await createImageBitmap(await r.blob());
  ages.push(Date.now() / 1000 - captured);
  await new Promise((ok) => setTimeout(ok, Math.max(0, 500 - (Date.now() - asked))));
}
done(ages);
"""


def cores_over(seconds: float) -> float:
    cpu0, wall0 = time.process_time(), time.monotonic()
    time.sleep(seconds)
    return (time.process_time() - cpu0) / (time.monotonic() - wall0)


def quantile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))]


def main() -> None:
    from rich.table import Table

    sys.path.insert(0, str(Path(__file__).parents[1] / "tests"))
    import browser

    if browser.missing() is not None:
        console.print(f"bench_dashboard: skipped: {browser.missing()}")
        return
    with tempfile.TemporaryDirectory(prefix="bench-dashboard-") as tmp:
        folder = Path(tmp)
        take = folder / "take.zarr"
        write_take(take)
        (folder / "s.yaml").write_text(SETTINGS)
        config = {
            "rigs": [{"name": "r0", "source": f"recording:{take}", "settings": "s.yaml"}],
            "storage": {"path": "store"},
            "http": {"listen": "127.0.0.1:0"},
        }
        (folder / "monitor.yaml").write_text(yaml.safe_dump(config))
        monitor = Monitor(load_config(folder / "monitor.yaml"))
        monitor.start()
        driver = browser.chromium(1280, 900)
        phases: dict[str, list[float]] = {"nobody": [], "overview": [], "rig page": []}
        try:
            url = monitor.http.url
            time.sleep(WARMUP_S)
            for _ in range(ROUNDS):
                for name, page in (("nobody", "about:blank"), ("overview", f"{url}/"),
                                   ("rig page", f"{url}/rig/r0")):  # fmt: skip
                    driver.get(page)
                    time.sleep(2.0)  # the page loaded, the rig's pictures wanted
                    phases[name].append(cores_over(PHASE_S))
                    console.print(f"  {name}: {phases[name][-1]:.3f} cores")
            driver.get(f"{url}/")
            driver.set_script_timeout(PHASE_S + 30)
            ages = {
                what: driver.execute_async_script(AGES, f"{url}/api/rigs/r0/{what}", PHASE_S)
                for what in ("overlay.jpg?width=640", "overlay.jpg", "thermal.png")
            }
        finally:
            driver.quit()
            monitor.stop()
    cost = {name: statistics.median(v) for name, v in phases.items()}
    table = Table(title="dashboard: the monitor's CPU (cores, median of phases) with a page open")
    for col in ("page", "cores", "more than nobody"):
        table.add_column(col, justify="right")
    for name, value in cost.items():
        table.add_row(name, f"{value:.3f}", f"{value - cost['nobody']:+.3f}")
    console.print(table)
    table = Table(title="a live picture's age when the browser has it decoded (ms)")
    for col in ("picture", "median", "p99", "n"):
        table.add_column(col, justify="right")
    for what, values in ages.items():
        ms = [1e3 * v for v in values]
        table.add_row(
            what, f"{statistics.median(ms):.0f}", f"{quantile(ms, 0.99):.0f}", str(len(ms))
        )
    console.print(table)
    OUT.mkdir(exist_ok=True)
    result: dict[str, Any] = {"cores": phases, "ages_s": ages}
    (OUT / "dashboard.json").write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
