"""The Python examples in README.md and docs/ run, and print what they say they print."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
BLOCKS = [
    pytest.param(block, doc, id=f"{doc.name}-{i}")
    for doc in DOCS
    for i, block in enumerate(re.findall(r"```python\n(.*?)```", doc.read_text(), flags=re.S))
]


@pytest.mark.parametrize(("block", "doc"), BLOCKS)
def test_doc_python_example(block: str, doc: Path) -> None:
    # each top-level `print(...)  # value` line documents the value it prints
    claims = re.findall(r"^print\(.*\)[ \t]*#[ \t]*(.+)$", block, flags=re.M)
    assert claims, "the example documents its output"
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(block, str(doc), "exec"), {})
    assert out.getvalue().splitlines() == claims
