"""The Python examples in README.md and docs/ run, and print what they say they print."""

from __future__ import annotations

import contextlib
import io
import re
from dataclasses import dataclass, field
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


@dataclass
class Step:
    """A step of the guide: the files its ```yaml blocks write (those that begin with a
    ``# NAME`` line), then its ```sh block's commands, and the lines their output holds
    (the ```text block right after it, if any)."""

    files: dict[str, str] = field(default_factory=dict)
    commands: list[str] = field(default_factory=list)
    expected: list[str] = field(default_factory=list)


def guide_steps() -> list[Step]:
    """The guide's steps, in order (:class:`Step`)."""
    blocks = re.findall(r"```(sh|text|yaml)\n(.*?)```", GUIDE.read_text(), flags=re.S)
    steps: list[Step] = [Step()]
    for kind, body in blocks:
        if kind == "yaml":
            name = re.match(r"# (\S+)\n", body)
            assert name, f"a yaml block of the guide names its file first: {body[:40]!r}"
            steps[-1].files[name.group(1)] = body
        elif kind == "sh":
            joined = body.replace("\\\n", " ")
            steps[-1].commands = [line.strip() for line in joined.splitlines() if line.strip()]
            steps.append(Step())
        else:
            steps[-2].expected.extend(line for line in body.splitlines() if line.strip())
    return [step for step in steps if step.commands]


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


def like(want: str, lines: list[str]) -> bool:
    """Whether a line of ``lines`` reads as ``want``, where "..." stands for anything."""
    pattern = ".*".join(re.escape(part) for part in want.split("..."))
    return any(re.fullmatch(pattern, got.rstrip()) for got in lines)


def run_monitor(config: Path, expected: list[str]) -> str:
    """``thermodepth monitor CONFIG`` as a process, as it is run, on the simulated rig (the
    config's live cameras replaced by ``sim``, its HTTP port by a free one) until its log
    holds every expected line and its dashboard answers; then SIGTERM. Its log."""
    import signal
    import subprocess
    import sys
    import time

    import httpx

    text = config.read_text()
    config.write_text(text.replace(f"source: {LIVE}", "source: sim")
                      .replace("listen: 127.0.0.1:8088", "listen: 127.0.0.1:0"))  # fmt: skip
    log = config.with_suffix(".log")
    with open(log, "wb") as out:
        proc = subprocess.Popen(
            [sys.executable, "-m", "thermodepth.cli", "monitor", str(config)],
            stdout=out,
            stderr=out,
        )
    try:
        end = time.monotonic() + 120  # far beyond the ~10 s it takes
        while True:
            lines = log.read_text(errors="replace").splitlines()
            url = next((m.group(1) for line in lines
                        if (m := re.search(r"HTTP on (http://\S+)", line))), None)  # fmt: skip
            if url and all(like(want, lines) for want in expected):
                break
            assert proc.poll() is None, f"the monitor stopped:\n{log.read_text()}"
            assert time.monotonic() < end, f"not every line of the guide came:\n{log.read_text()}"
            time.sleep(0.2)
        with httpx.Client(base_url=url, timeout=60) as http:
            assert http.get("/healthz").status_code == 200  # the rig's data are fresh
            assert "app.js" in http.get("/").text  # the dashboard, open on this machine
    finally:
        proc.send_signal(signal.SIGTERM)
        code = proc.wait(120)
    assert code == 0, log.read_text()
    assert "monitor: stopped" in log.read_text()
    return log.read_text()


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
    assert len(steps) >= 11
    ran = 0
    for step in steps:
        for name, text in step.files.items():
            (tmp_path / name).write_text(text)
        output = ""
        for line in step.commands:
            args = shlex.split(os.path.expandvars(line))
            if args[0] == "cp":
                shutil.copy(args[1], args[2])
                continue
            assert args[0] == "thermodepth", line
            if args[1:2] == ["monitor"] and "--check" not in args:  # until it is stopped
                output += run_monitor(tmp_path / args[2], step.expected)
                ran += 1
                continue
            result = runner.invoke(app, stand_in(args[1:]))
            assert result.exit_code == 0, f"{line}\n{result.output}"
            output += result.output
            ran += 1
        lines = output.splitlines()
        for want in step.expected:  # "..." stands for anything
            assert like(want, lines), f"{step.commands}: no line like {want!r} in\n{output}"
    assert ran >= 16


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
