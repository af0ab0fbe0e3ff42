"""The monitor's soak (`make soak`, not in `make test`): two simulated rigs for an hour of real
time (``--minutes``), a fault every few minutes (unplugged, stalled, corrupt frames, the
shutter closing again and again), alarms, clips, rolling recordings deleted by the storage
rule, its HTTP server asked every sample, and a Mosquitto broker of its own where one is
installed. Every ``--every-s`` it samples the process: resident memory (RSS), open files,
threads. It reports the slopes after the first tenth (the warm-up) and fails when threads or
open files grew (a leak), in bench-out/soak_monitor.json.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import yaml

from thermodepth.monitor import Monitor, load_config

from .common import OUT, console

SETTINGS = """\
hotspots: {threshold_c: 50}
alarms:
  - {name: hot, above_c: 67.48, for_s: 0.3}
  - {name: warm, above_c: 60, level: warning, latch: true}
"""


def faults(minutes: float, period_s: float, offsets: dict[str, tuple[float, float | None]]) -> str:
    """A sim:faults= list with each fault of ``offsets`` (kind: at s into each period, for
    s) once every ``period_s`` for ``minutes``."""
    parts = []
    for start in np.arange(0.0, minutes * 60.0, period_s):
        for kind, (at, span) in offsets.items():
            t = start + at
            if t < minutes * 60.0:
                parts.append(f"{kind}@{t:g}s" + (f"+{span:g}s" if span else ""))
    return ",".join(parts)


def sample() -> dict[str, float]:
    """This process: resident memory (MB), open files, threads (the kernel's count)."""
    status = Path("/proc/self/status").read_text()
    rss_kb = next(int(line.split()[1]) for line in status.splitlines() if line.startswith("VmRSS"))
    return {
        "rss_mb": rss_kb / 1024,
        "open_files": len(os.listdir("/proc/self/fd")),
        "threads": len(os.listdir("/proc/self/task")),
        "python_threads": threading.active_count(),
    }


def slope_per_hour(t_s: np.ndarray, y: np.ndarray) -> float:
    return float(np.polyfit(t_s / 3600.0, y, 1)[0]) if len(t_s) > 2 else float("nan")


def run(minutes: float, every_s: float, folder: Path) -> dict[str, Any]:
    (folder / "s.yaml").write_text(SETTINGS)
    a = faults(minutes, 240.0, {"unplug": (30, 10), "stall": (90, None), "corrupt": (150, 5),
                                "ffc-storm": (200, 20)})  # fmt: skip
    b = faults(minutes, 300.0, {"unplug": (120, 5), "stall": (240, None)})
    config: dict[str, Any] = {
        "rigs": [
            {
                "name": name,
                "source": "sim:depth=848x480" + (f",faults={f}" if f else ""),
                "settings": "s.yaml",
            }
            for name, f in (("a", a), ("b", b))
        ],
        "storage": {
            "path": "store",
            "continuous": True,
            "segment_s": 60,
            "retention_days": 10 / 1440,  # ten minutes: the storage rule deletes as it goes
            "pre_s": 5,
            "post_s": 5,
            "clip_max_s": 30,
        },
        "http": {"listen": "127.0.0.1:0"},
    }
    broker = None
    sys.path.insert(0, str(Path(__file__).parents[1] / "tests"))
    from mqtt_broker import Broker, missing

    if missing() is None:
        broker = Broker()
        broker.start()
        os.environ["THERMODEPTH_MQTT_PASSWORD"] = broker.password
        config["mqtt"] = {"url": broker.url("soak")}
    path = folder / "monitor.yaml"
    path.write_text(yaml.safe_dump(config))
    lines: list[str] = []
    monitor = Monitor(load_config(path), lines.append)
    monitor.start()
    samples = []
    t0 = time.monotonic()
    try:
        with httpx.Client(base_url=monitor.http.url, timeout=10) as client:
            while (now := time.monotonic() - t0) < minutes * 60.0:
                rigs = client.get("/api/status").json()["rigs"]
                frames = {r["name"]: r["frames"] for r in rigs}
                samples.append(
                    {"t_s": now, **sample(), "events": monitor.store.count(), "frames": frames}
                )
                console.print(
                    f"{now / 60:5.1f} min  RSS {samples[-1]['rss_mb']:.0f} MB  files "
                    f"{samples[-1]['open_files']}  threads {samples[-1]['threads']}  events "
                    f"{samples[-1]['events']}  frames {samples[-1]['frames']}"
                )
                time.sleep(every_s)
            final = monitor.status()
    finally:
        monitor.stop()
        if broker is not None:
            broker.cleanup()
    after_stop = sample()
    warm = [s for s in samples if s["t_s"] >= 0.1 * minutes * 60.0] or samples
    t = np.array([s["t_s"] for s in warm])
    first, last = warm[: max(1, len(warm) // 10)], warm[-max(1, len(warm) // 10) :]

    def med(rows: list[dict[str, Any]], key: str) -> float:
        return float(np.median([r[key] for r in rows]))

    report = {
        "minutes": minutes,
        "samples": len(samples),
        "rss_mb": {"after_warmup": med(first, "rss_mb"), "end": med(last, "rss_mb"),
                   "slope_mb_per_h": slope_per_hour(t, np.array([s["rss_mb"] for s in warm]))},
        "open_files": {"after_warmup": med(first, "open_files"), "end": med(last, "open_files"),
                       "slope_per_h": slope_per_hour(t, np.array([s["open_files"] for s in warm])),
                       "max": max(s["open_files"] for s in samples)},
        "threads": {"after_warmup": med(first, "threads"), "end": med(last, "threads"),
                    "max": max(s["threads"] for s in samples)},
        "after_stop": after_stop,
        "rigs": {r["name"]: {k: r[k] for k in ("frames", "reconnects", "stalls",
                                                "seconds_without_data", "dropped")}
                 for r in final["rigs"]},
        "events": final["event_counts"],
        "storage": final["storage"],
        "latency_s": final["latency_s"],
        "mqtt": final["mqtt"],
        "sensor_faults": sum("ALARM sensor_fault" in line for line in lines),
    }  # fmt: skip
    return report


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--every-s", type=float, default=10.0)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="soak-") as tmp:
        report = run(args.minutes, args.every_s, Path(tmp))
    OUT.mkdir(exist_ok=True)
    (OUT / "soak_monitor.json").write_text(json.dumps(report, indent=2))
    console.print_json(json.dumps(report))
    leaked = []
    if report["threads"]["end"] > report["threads"]["after_warmup"] + 2:
        leaked.append("threads")
    if report["open_files"]["end"] > report["open_files"]["after_warmup"] + 10:
        leaked.append("open files")
    if leaked:
        console.print(f"[red]leaked: {', '.join(leaked)}[/red]")
        sys.exit(1)


if __name__ == "__main__":
    main()
