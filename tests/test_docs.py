"""The README's Python examples run and print what the README says they print."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import pytest

README = Path(__file__).parents[1] / "README.md"
BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)


@pytest.mark.parametrize("block", BLOCKS)
def test_readme_python_example(block: str) -> None:
    # each top-level `print(...)  # value` line documents the value it prints
    claims = re.findall(r"^print\(.*\)\s*#\s*(.+)$", block, flags=re.M)
    assert claims, "the example documents its output"
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(block, str(README), "exec"), {})
    assert out.getvalue().splitlines() == claims
