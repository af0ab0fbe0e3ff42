"""The simulator's heavy workloads, timed once each (what the test suite and the docs run):

    python -m bench.sim_workloads board-session|targets|source|source-paced|walk

board-session: ``thermodepth simulate board-session --poses 10 --seed 1`` as the new-rig guide
runs it (a new process: start-up and imports included); targets: ``simulate_targets``, 40
views of a 9x6 checkerboard; source: the ``sim`` source's pairs (a held pose: the sensors'
noise and counts), 50 of them; source-paced: ``sim:pace=real``, 20 pairs, the CPU time each
costs; walk: a 5 s walk round the machine (1280x720, every frame, with its truth). Prints one
JSON line: the workload and its seconds (per pair for the sources). Run it against two
checkouts in turn (PYTHONPATH) to compare them on a shared machine.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def board_session(tmp: Path) -> float:
    code = "import sys; from thermodepth.cli import main; sys.argv[0] = 'thermodepth'; main()"
    args = ["simulate", "board-session", "-o", str(tmp / "b.zarr"), "--poses", "10", "--seed", "1"]
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code, *args], check=True, capture_output=True)
    return time.perf_counter() - t0


def targets(tmp: Path) -> float:
    from thermodepth.board import BoardSpec
    from thermodepth.sim.protocols import simulate_targets

    board = BoardSpec.parse("checkerboard:9x6", 0.03)
    simulate_targets(tmp / "warm", board, 1, seed=4)  # imports, caches
    t0 = time.perf_counter()
    simulate_targets(tmp / "views", board, 40, seed=4)
    return time.perf_counter() - t0


def source(tmp: Path, paced: bool = False) -> float:
    from thermodepth.sources import open_source

    n = 20 if paced else 50
    src = open_source("sim:pace=real" if paced else "sim", frames=n)
    events = src.events()
    next(events)  # the first pair renders the pose
    clock = time.process_time if paced else time.perf_counter  # paced: CPU, not waiting
    t0 = clock()
    for _ in events:
        pass
    return (clock() - t0) / (n - 1)


def walk(tmp: Path) -> float:
    from thermodepth.sim.walkaround import simulate_walkaround

    t0 = time.perf_counter()
    simulate_walkaround(tmp / "w.zarr", "machine", 5.0, seed=0)
    return time.perf_counter() - t0


WORKLOADS = {
    "board-session": board_session,
    "targets": targets,
    "source": source,
    "source-paced": lambda tmp: source(tmp, paced=True),
    "walk": walk,
}


def main(args: list[str]) -> None:
    if len(args) != 1 or args[0] not in WORKLOADS:
        sys.exit(__doc__)
    with tempfile.TemporaryDirectory() as tmp:
        seconds = WORKLOADS[args[0]](Path(tmp))
    print(json.dumps({"workload": args[0], "seconds": seconds}))


if __name__ == "__main__":
    main(sys.argv[1:])
