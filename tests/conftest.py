"""Fixtures shared by several test files."""

from __future__ import annotations

import pytest

from thermodepth.evaluation import Generalisation, compensation_generalisation


@pytest.fixture(scope="session")
def generalisation() -> Generalisation:
    """Both compensation methods fitted on a simulated sweep, with the held-out sweeps."""
    return compensation_generalisation(samples=200, seed=1)
