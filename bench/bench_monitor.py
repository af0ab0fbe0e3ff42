"""The monitor's alarm latency and capacity: N rigs each replaying one recording at its recorded
pace, as live cameras (a D435 at 1280x720 beside a Lepton 3, 8.7 pairs/s; an 8 cm chip on the
plate that heats to 85 C and cools to 45 C every 5 s, so that an alarm raises and clears),
with the monitor's clips, event store and, where Mosquitto is installed, a broker of its own.

Latency: from the capture time of the thermal frame that raised an event (its Unix time) to
its row in the event store, and to the broker's acknowledgement of its publication (median,
p99, n), with 1, 4 and 8 rigs, after a warm-up. Capacity: more rigs, until pairs are dropped
(a pair reached more than a second after its time, as a live camera's driver drops it), and
the pairs dropped in the first WARMUP_S (12 s) apart: the start, kernels compiled or loaded.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

from thermodepth.io.recording import RecordingWriter
from thermodepth.monitor import Monitor, load_config
from thermodepth.sim import Rig, camera_pose, plate_scene

from .common import OUT, console

SETTINGS = """\
hotspots: {threshold_c: 50}
alarms:
  - {name: chip-hot, above_c: 70}
"""
LATENCY_RIGS = (1, 4, 8)
CAPACITY_RIGS = (12, 16)
WARMUP_S = 12.0
RUN_S = 45.0


def write_take(path: Path, seconds: float = 10.0) -> None:
    """The recording every rig replays: the chip cold for 5 s, hot for 5 s."""
    cold = Rig(plate_scene(chip_temp_c=45.0, chip_size_m=0.08), camera_pose(1.0), seed=1)
    hot = Rig(plate_scene(chip_temp_c=85.0, chip_size_m=0.08), camera_pose(1.0), seed=1)
    n = int(seconds * 8.7)
    with RecordingWriter(path, cold.calibration, {"source": "sim"}, source="sim") as writer:
        for c, h in zip(cold.frames(n), hot.frames(n), strict=True):
            writer.add_pair(h if c.thermal_time_s % seconds >= seconds / 2 else c)


def run(n_rigs: int, take: Path, folder: Path, mqtt_url: str | None) -> dict[str, Any]:
    (folder / "s.yaml").write_text(SETTINGS)
    config: dict[str, Any] = {
        "rigs": [
            {"name": f"r{i}", "source": f"recording:{take}", "settings": "s.yaml"}
            for i in range(n_rigs)
        ],
        "storage": {"path": "store"},
        "http": {"listen": None},
    }
    if mqtt_url is not None:
        config["mqtt"] = {"url": mqtt_url}
    path = folder / "monitor.yaml"
    path.write_text(yaml.safe_dump(config))
    monitor = Monitor(load_config(path))
    monitor.start()
    try:
        time.sleep(WARMUP_S)  # numba, the first clips, the broker
        for figures in monitor.latency_s.values():
            figures.clear()
        dropped0 = sum(r.status.dropped for r in monitor.runners.values())
        frames0 = sum(r.status.frames for r in monitor.runners.values())
        cpu0, wall0 = time.process_time(), time.monotonic()
        time.sleep(RUN_S)
        cpu, wall = time.process_time() - cpu0, time.monotonic() - wall0
        status = monitor.status()
        dropped = sum(r.status.dropped for r in monitor.runners.values()) - dropped0
        frames = sum(r.status.frames for r in monitor.runners.values()) - frames0
    finally:
        monitor.stop()
    lag_p99 = max(r["pace_lag_ms"]["p99"] or 0.0 for r in status["rigs"])
    return {
        "rigs": n_rigs,
        "latency_s": status["latency_s"],
        "dropped": dropped,
        "dropped_at_start": dropped0,
        "pairs_per_s": frames / wall,
        "pace_lag_p99_ms": lag_p99,
        "pipeline_ms_median": max(r["pipeline_ms"]["median"] or 0.0 for r in status["rigs"]),
        "cpu_cores": cpu / wall,
    }


def ms(figures: dict[str, Any], key: str) -> str:
    value = figures[key]
    return "-" if value is None else f"{1e3 * value:.1f}"


def main() -> None:
    from rich.table import Table

    sys.path.insert(0, str(Path(__file__).parents[1] / "tests"))
    from mqtt_broker import Broker, missing

    broker = None
    if missing() is None:
        broker = Broker()
        broker.start()
        os.environ["THERMODEPTH_MQTT_PASSWORD"] = broker.password
    results = []
    try:
        with tempfile.TemporaryDirectory(prefix="bench-monitor-") as tmp:
            take = Path(tmp) / "take.zarr"
            write_take(take)
            for n in (*LATENCY_RIGS, *CAPACITY_RIGS):
                folder = Path(tmp) / f"n{n}"
                folder.mkdir()
                results.append(run(n, take, folder, broker.url("bench") if broker else None))
                console.print(results[-1])
    finally:
        if broker is not None:
            broker.cleanup()
    table = Table(
        title="monitor: from a thermal frame's capture to its event's row and to the broker "
        f"(median, p99 ms); pairs dropped (and in the first {WARMUP_S:g} s), how late pairs were "
        "reached (p99 ms), pipeline "
        "(median ms), CPU"
    )
    for col in ("rigs", "row", "row p99", "broker", "broker p99", "events", "pairs/s",
                "dropped", "at start", "lag p99", "pipeline", "cores"):  # fmt: skip
        table.add_column(col, justify="right")
    for r in results:
        row, broker_fig = r["latency_s"]["event_row"], r["latency_s"]["broker"]
        table.add_row(
            str(r["rigs"]),
            ms(row, "median"),
            ms(row, "p99"),
            ms(broker_fig, "median"),
            ms(broker_fig, "p99"),
            str(row["n"]),
            f"{r['pairs_per_s']:.1f}",
            str(r["dropped"]),
            str(r["dropped_at_start"]),
            f"{r['pace_lag_p99_ms']:.0f}",
            f"{r['pipeline_ms_median']:.1f}",
            f"{r['cpu_cores']:.2f}",
        )
    console.print(table)
    held = [r["rigs"] for r in results if r["dropped"] == 0]
    console.print(f"  the most rigs with no pair dropped: {max(held) if held else 0}")
    OUT.mkdir(exist_ok=True)
    (OUT / "monitor.json").write_text(json.dumps({"results": results}, indent=2))


if __name__ == "__main__":
    main()
