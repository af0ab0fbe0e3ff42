"""Run every benchmark and print its table (`make bench`); JSON copies go to bench-out/."""

from __future__ import annotations

import importlib
import sys

BENCHMARKS = [
    "bench_sim",
    "bench_registration",
    "bench_compensation",
    "bench_pipeline",
    "bench_cameras",
    "bench_recording",
    "bench_replay",
    "bench_codecs",
    "bench_batch",
    "bench_detection",
    "bench_monitor",
    "bench_monitor_memory",
    "bench_dashboard",
    "bench_video",
    "bench_export",
    "bench_odometry",
    "bench_map",
]


def main(names: list[str]) -> None:
    for name in names or BENCHMARKS:
        importlib.import_module(f"bench.{name}").main()


if __name__ == "__main__":
    main(sys.argv[1:])
