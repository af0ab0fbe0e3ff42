"""Exporting a recording to ROS bags (``thermodepth export``): how much faster than the
recording's own duration, and how large a minute of rig is, for each format and compression.

The recording: bench_monitor's take (a D435 at 1280x720 beside a Lepton 3, 8.7 pairs/s,
10 s, a chip heating and cooling), its clouds at most 100,000 points (the default). The
recording is replayed and fused as ``run`` does; the time is the whole export's wall time
(median of 3), against the take's own duration.
"""

from __future__ import annotations

import json
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from thermodepth.app.run import RunOptions, run
from thermodepth.sinks.bag import BagSink

from .bench_monitor import SETTINGS, write_take
from .common import OUT, console

CASES = (("mcap", "none"), ("mcap", "lz4"), ("mcap", "zstd"), ("rosbag2", "none"))
TAKE_S = 10.0
REPEAT = 3


def size_of(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*")) if path.is_dir() else path.stat().st_size


def main() -> None:
    from rich.table import Table

    results: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="bench-export-") as tmp:
        folder = Path(tmp)
        take = folder / "take.zarr"
        write_take(take, TAKE_S)
        settings = folder / "s.yaml"
        settings.write_text(SETTINGS)
        run(RunOptions(f"recording:{take}", settings, frames=3))  # numba, caches
        for fmt, compression in CASES:
            walls, size = [], 0
            for i in range(REPEAT):
                out = folder / f"{fmt}-{compression}-{i}{'.mcap' if fmt == 'mcap' else ''}"
                t0 = time.perf_counter()
                result = run(
                    RunOptions(f"recording:{take}", settings), [BagSink(out, fmt, compression)]
                )
                walls.append(time.perf_counter() - t0)
                size = size_of(out)
            wall = statistics.median(walls)
            results.append({
                "format": fmt, "compression": compression, "frames": result.frames,
                "wall_s": wall, "times_real_time": TAKE_S / wall,
                "mb_per_minute": size / 1e6 * 60.0 / TAKE_S,
            })  # fmt: skip
            console.print(results[-1])
    table = Table(title=f"export of a {TAKE_S:g} s recording (median of {REPEAT})")
    for col in ("format", "compression", "frames", "wall s", "x real time", "MB per minute"):
        table.add_column(col, justify="right")
    for r in results:
        table.add_row(r["format"], r["compression"], str(r["frames"]), f"{r['wall_s']:.2f}",
                      f"{r['times_real_time']:.1f}", f"{r['mb_per_minute']:.0f}")  # fmt: skip
    console.print(table)
    OUT.mkdir(exist_ok=True)
    (OUT / "export.json").write_text(json.dumps({"results": results}, indent=2))


if __name__ == "__main__":
    main()
