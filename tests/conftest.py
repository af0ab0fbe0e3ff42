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

from thermodepth.evaluation import Generalisation, compensation_generalisation

# `make test` (--hypothesis-profile=ci): the same examples every run, so that the suite that
# guards main fails for a change, not for a draw; plain `pytest` explores anew each time
settings.register_profile("ci", derandomize=True, database=None)


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
