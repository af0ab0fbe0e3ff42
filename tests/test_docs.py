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


# -- docs/new-rig.md: every command, in order, on the simulated rig ------------------------------

GUIDE = ROOT / "docs" / "new-rig.md"
LIVE = "realsense+lepton"


def guide_steps() -> list[tuple[list[str], list[str]]]:
    """(commands, expected output lines) of each ```sh block of the guide, in order; the
    expected lines are those of the ```text block right after it (if any)."""
    blocks = re.findall(r"```(sh|text)\n(.*?)```", GUIDE.read_text(), flags=re.S)
    steps: list[tuple[list[str], list[str]]] = []
    for kind, body in blocks:
        if kind == "sh":
            joined = body.replace("\\\n", " ")
            commands = [line.strip() for line in joined.splitlines() if line.strip()]
            steps.append((commands, []))
        else:
            steps[-1][1].extend(line for line in body.splitlines() if line.strip())
    return steps


def stand_in(args: list[str]) -> list[str]:
    """The live cameras of a guide command replaced by the simulator's recordings that the
    guide's rehearsal writes (``run``: the simulated rig, for 8 pairs)."""
    if LIVE not in args:
        return args
    command, out = args[0], args[args.index("-o") + 1] if "-o" in args else None
    source = {
        ("capture-board", "pairs"): "recording:board.zarr",
        ("record", "protocol.zarr"): "recording:sim-protocol.zarr",
        ("record", "check.zarr"): "recording:sim-check.zarr",
        ("run", "run-out"): "sim",
    }[(command, out)]
    replaced = [source if a == LIVE else a for a in args]
    return [*replaced, "--frames", "8"] if command == "run" else replaced


def test_new_rig_guide_runs_on_the_simulated_rig(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import os
    import shlex
    import shutil

    from typer.testing import CliRunner

    from thermodepth.cli import app

    runner = CliRunner()
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("THERMODEPTH", str(ROOT))
    steps = guide_steps()
    assert len(steps) >= 9
    ran = 0
    for commands, expected in steps:
        output = ""
        for line in commands:
            args = shlex.split(os.path.expandvars(line))
            if args[0] == "cp":
                shutil.copy(args[1], args[2])
                continue
            assert args[0] == "thermodepth", line
            result = runner.invoke(app, stand_in(args[1:]))
            assert result.exit_code == 0, f"{line}\n{result.output}"
            output += result.output
            ran += 1
        lines = output.splitlines()
        for want in expected:  # "..." stands for anything
            pattern = ".*".join(re.escape(part) for part in want.split("..."))
            assert any(re.fullmatch(pattern, got.rstrip()) for got in lines), (
                f"{commands}: no line like {want!r} in\n{output}"
            )
    assert ran >= 12


def test_example_settings_hold_every_section() -> None:
    import yaml

    from thermodepth.pipeline import Settings

    path = ROOT / "examples" / "settings.yaml"
    settings = Settings.load(path)
    raw = yaml.safe_load(path.read_text())
    assert {"calibration", "compensation", "radiometry", "registration", "hotspots", "rois",
            "alarms", "viewer", "mqtt"} <= set(raw)  # fmt: skip
    assert settings.viewer.temp_range_c == (15.0, 80.0) and settings.mqtt.max_queued == 10_000
    assert settings.compensation == path.parent / "model.json"
    shapes = {next(k for k in ("rect", "polygon", "depth_range_m") if k in r) for r in raw["rois"]}
    assert shapes == {"rect", "polygon", "depth_range_m"}
    assert {a.what for a in settings.alarms} == {"hotspot", "plate"}
