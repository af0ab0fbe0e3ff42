"""Fixtures shared by several test files."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable

import pytest

if os.environ.get("PYTEST_XDIST_WORKER"):  # `make test`: two workers, one core each
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")

from hypothesis import settings

from thermodepth.app.kernels import PARTS
from thermodepth.evaluation import Generalisation, compensation_generalisation

# `make test` (--hypothesis-profile=ci): the same examples every run, so that the suite that
# guards main fails for a change, not for a draw; plain `pytest` explores anew each time
settings.register_profile("ci", derandomize=True, database=None)


# numba compiles a kernel on its first call (cached on disk after): in a fresh clone each
# `make test` worker would compile the pipeline's and the simulator's at once, one core each,
# and a subprocess started meanwhile a third time. Compiled once, side by side, first.


def pytest_sessionstart(session: pytest.Session) -> None:
    """`make test` (xdist's controller only): the kernels most tests run compiled first
    (`thermodepth compile`, a process a part). A compile that fails is left for the tests to
    show."""
    config = session.config
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    warming = [
        subprocess.Popen([sys.executable, "-m", "thermodepth.cli", "compile", "--only", part])
        for part in PARTS
    ]
    for process in warming:
        process.wait()


# `make test` hands whole files to its two workers, in this order first (the longest first, as
# measured: `pytest --durations`), then the rest as collected: a long file started last would
# keep one worker busy while the other has nothing left to do
LONGEST_FIRST = (
    "test_capture.py",
    "test_docs.py",
    "test_calibrate.py",
    "test_cameras_end_to_end.py",
    "test_monitor_workers.py",
    "test_monitor.py",
    "test_monitor_process.py",
    "test_batch.py",
    "test_folder.py",
    "test_dashboard_pictures.py",
    "test_monitor_opcua.py",
    "test_recording.py",
    "test_pipeline.py",
    "test_collect.py",
    "test_board_detection.py",
    "test_monitor_mqtt.py",
    "test_demo.py",
    "test_dashboard.py",
    "test_dashboard_browser.py",
    "test_registration.py",
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The files of :data:`LONGEST_FIRST` first, in its order (sorting keeps each file's own
    order and the order of the other files)."""
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


@pytest.fixture(scope="session")
def generalisation() -> Generalisation:
    """Both compensation methods fitted on a simulated sweep, with the held-out sweeps."""
    return compensation_generalisation(samples=200, seed=1)


CliProcess = Callable[..., "subprocess.CompletedProcess[str]"]


@pytest.fixture
def cli_process() -> CliProcess:
    """Runs ``thermodepth`` with the given arguments in a real process (so that the console
    script's own error path is what is checked); returns it finished, output captured."""

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "thermodepth.cli", *args],
            capture_output=True,
            text=True,
            check=False,
            env={**os.environ, "COLUMNS": "1000"},  # no line folded, however long its path
        )

    return run
