"""The monitor's resident memory per rig: N rigs replaying bench_monitor's recording (a D435 at
1280x720 beside a Lepton 3, 8.7 pairs/s, an alarm raised and cleared every 10 s, so clips are
written all the time), default ``pre_s`` (10 s), no HTTP or broker. Each count of rigs runs in
a process of its own (resident memory is never given back to a parent's later run), sampled
every 10 s for 40 s; the threads and the pairs dropped (all of them, from the start) with it.

``python -m bench.bench_monitor_memory [N ...]`` (default 1 2 4 8).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import yaml

from .common import OUT, console

RIGS = (1, 2, 4, 8)
SAMPLE_S = 10.0
SAMPLES = 4


def resident_mb() -> float:
    """This process's resident memory (MB, 1e6 bytes)."""
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * 4096 / 1e6


def child(n_rigs: int, take: Path, folder: Path) -> dict[str, Any]:
    from thermodepth.monitor import Monitor, load_config

    from .bench_monitor import SETTINGS

    (folder / "s.yaml").write_text(SETTINGS)
    rigs = [{"name": f"r{i}", "source": f"recording:{take}", "settings": "s.yaml"}
            for i in range(n_rigs)]  # fmt: skip
    config = {"rigs": rigs, "storage": {"path": "store"}, "http": {"listen": None}}
    (folder / "monitor.yaml").write_text(yaml.safe_dump(config))
    before = resident_mb()
    monitor = Monitor(load_config(folder / "monitor.yaml"))
    monitor.start()
    samples = []
    try:
        for _ in range(SAMPLES):
            time.sleep(SAMPLE_S)
            samples.append(round(resident_mb(), 1))
        threads = threading.active_count()
        dropped = sum(r.status.dropped for r in monitor.runners.values())
    finally:
        monitor.stop()
    return {"rigs": n_rigs, "before_mb": round(before, 1), "resident_mb": samples,
            "threads": threads, "dropped": dropped}  # fmt: skip


def main(counts: list[int] | None = None) -> None:
    from rich.table import Table

    from .bench_monitor import write_take

    results = []
    with tempfile.TemporaryDirectory(prefix="bench-monitor-memory-") as tmp:
        take = Path(tmp) / "take.zarr"
        write_take(take)
        for n in counts or RIGS:
            folder = Path(tmp) / f"n{n}"
            folder.mkdir()
            done = subprocess.run(
                [sys.executable, "-m", "bench.bench_monitor_memory", "--child", str(n),
                 str(take), str(folder)],
                capture_output=True, text=True, check=True,
            )  # fmt: skip
            results.append(json.loads(done.stdout.strip().splitlines()[-1]))
            console.print(results[-1])
    table = Table(
        title="monitor: resident memory (MB) with N rigs at 1280x720 + Lepton 3, pre_s 10, "
        f"every {SAMPLE_S:g} s; threads; pairs dropped since the start"
    )
    for col in ("rigs", "imports", *(f"{SAMPLE_S * (i + 1):g} s" for i in range(SAMPLES)),
                "per further rig", "threads", "dropped"):  # fmt: skip
        table.add_column(col, justify="right")
    one = next((r for r in results if r["rigs"] == 1), None)
    for r in results:
        more = (
            f"{(r['resident_mb'][-1] - one['resident_mb'][-1]) / (r['rigs'] - 1):.0f}"
            if one is not None and r["rigs"] > 1
            else "-"
        )
        table.add_row(str(r["rigs"]), f"{r['before_mb']:.0f}",
                      *(f"{m:.0f}" for m in r["resident_mb"]), more, str(r["threads"]),
                      str(r["dropped"]))  # fmt: skip
    console.print(table)
    OUT.mkdir(exist_ok=True)
    (OUT / "monitor_memory.json").write_text(json.dumps({"results": results}, indent=2))


if __name__ == "__main__":
    if sys.argv[1:2] == ["--child"]:
        print(json.dumps(child(int(sys.argv[2]), Path(sys.argv[3]), Path(sys.argv[4]))))
    else:
        main([int(a) for a in sys.argv[1:]] or None)
