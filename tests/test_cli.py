"""The command line: version, one-line errors, thin commands over plain functions."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from conftest import CliProcess
from thermodepth import __version__
from thermodepth.app.temperature import counts_to_celsius
from thermodepth.cli import app
from thermodepth.conditions import Conditions
from thermodepth.errors import InputError, ThermodepthError

EXAMPLE = Path(__file__).parents[1] / "examples" / "calibration.yaml"
runner = CliRunner()


def test_version() -> None:
    result = runner.invoke(app, ["--version"])
    assert result.exit_code == 0
    assert __version__ in result.output


def test_check_calibration_json_summary() -> None:
    result = runner.invoke(app, ["check-calibration", str(EXAMPLE), "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["baseline_mm"] == pytest.approx(40.0)
    assert summary["thermal"] == "160x120"
    assert summary["thermal_hfov_deg"] == pytest.approx(55.99, abs=0.01)


def test_bad_calibration_is_one_line_without_traceback(
    tmp_path: Path, cli_process: CliProcess
) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(EXAMPLE.read_text().replace("fx: 150.5", "fx: -150.5"))
    proc = cli_process("check-calibration", str(bad))
    assert proc.returncode == 2
    assert proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert f"{bad}: thermal.fx: Input should be greater than or equal to 1" in lines[0]
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize(
    ("name", "args"),
    [
        ("calib.yaml", ["check-calibration", "{bad}"]),
        ("sweep.csv", ["fit-compensation", "{bad}", "-o", "{tmp}/m.json"]),
        ("model.json", ["compensate", "{bad}", "{bad}", "-o", "{tmp}/out.csv"]),
    ],
)
def test_a_file_that_is_not_utf8_is_one_line(tmp_path: Path, name: str, args: list[str]) -> None:
    bad = tmp_path / name
    bad.write_bytes(b"distance_m: 1\nnote: caf\xe9\n")
    result = runner.invoke(app, [a.format(bad=bad, tmp=tmp_path) for a in args])
    assert result.exit_code == 2
    assert result.output.strip() == f"error: {bad}: not UTF-8 text (byte 0xe9 at offset 23)"


def test_error_lines_print_brackets_as_they_are(tmp_path: Path) -> None:
    # rich would read "[/red]" as markup (a crash) and "[final]" as a style (eaten)
    folder = tmp_path / "data[final]"
    folder.mkdir()
    sweep = folder / "s.csv"
    sweep.write_text("distance_m,vox_temp_c,measured_temp_c,reference_temp_c\n1,30,[/red],39\n")
    result = runner.invoke(app, ["fit-compensation", str(sweep)])
    assert result.exit_code == 2
    assert result.output.strip() == (
        f"error: {sweep}: line 2, column measured_temp_c: not a number: '[/red]'"
    )


def test_a_frame_line_names_the_flags_of_its_readings(capsys: pytest.CaptureFixture[str]) -> None:
    from types import SimpleNamespace

    from thermodepth.cli import print_frame
    from thermodepth.pipeline import PixelFlag

    spot = SimpleNamespace(
        max_c=201.9, distance_m=2.05, area_m2=0.5, resolvable=True,
        flags=int(PixelFlag.VOX_OUTSIDE | PixelFlag.NO_DISTANCE),
    )  # fmt: skip
    rois = [SimpleNamespace(name="[pump]", n=10, mean_c=50.0, flags=0)]
    frame = SimpleNamespace(
        in_ffc=False, index=3, thermal_time_s=0.34, vox_label="-273.15 C", hotspots=[spot],
        rois=rois, events=[{"event": "alarm", "rule": "[hot]", "value_c": 201.9, "above_c": 60,
                            "for_frames": 1, "level": "alarm",
                            "condition": "above 60 C for 1 frame", "frame": 3}],
    )  # fmt: skip
    print_frame(frame)
    lines = [" ".join(line.split()) for line in capsys.readouterr().out.splitlines()]
    assert lines == [
        "frame 3 t= 0.34 s VOx -273.15 C hottest 201.90 C at 2.05 m (5000.0 cm2) "
        "[vox_outside, no_distance] [pump] 50.00 C",
        "ALARM [hot] [alarm]: 201.9 C (above 60 C for 1 frame), frame 3",
    ]


def test_temperature_command() -> None:
    result = runner.invoke(app, ["temperature", "8502.1", "--emissivity", "1", "--distance-m", "0"])
    assert result.exit_code == 0, result.output
    assert "39.000 C" in result.output


def test_temperature_command_says_why_not() -> None:
    result = runner.invoke(app, ["temperature", "--", "-5", "20000", "8502.1"])
    assert result.exit_code == 0, result.output
    assert result.output.splitlines() == [
        "-5 counts -> none (invalid, or no signal above the surroundings)",
        "20000 counts -> none (invalid, or no signal above the surroundings)",
        "8502.1 counts -> 39.000 C",
    ]
    for option, value, message in (
        ("--ambient-temp-c", "-300", "--ambient-temp-c: -300 is outside -273.15 < T <= 5000 C"),
        ("--humidity-pct", "150", "--humidity-pct: 150 is outside 0-100 %"),
        ("--emissivity", "nan", "--emissivity: nan is outside 0 < emissivity <= 1"),
        ("--distance-m", "-1", "--distance-m: -1 is outside 0-1000 m"),
    ):
        result = runner.invoke(app, ["temperature", "8502", option, value])
        assert result.exit_code == 2 and result.output.strip() == f"error: {message}"


def test_counts_to_celsius_applies_emissivity_and_distance() -> None:
    bare = counts_to_celsius([8502.1])[0]
    corrected = counts_to_celsius([8502.1], Conditions(emissivity=0.95), distance_m=2.0)[0]
    assert bare == pytest.approx(39.0, abs=1e-3)
    assert corrected > bare + 0.5  # a grey body far away is hotter than its counts suggest


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"preset": "nope"}, "preset: unknown 'nope'"),
        ({"method": "nope"}, "method: unknown 'nope'"),
        ({"distance_m": -1.0}, "distance_m: -1 is outside 0-1000 m"),
    ],
)
def test_counts_to_celsius_bad_options(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(InputError, match=message):
        counts_to_celsius([8500.0], **kwargs)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="humidity_pct: 500 is outside 0-100 %"):
        counts_to_celsius([8500.0], Conditions(humidity_pct=500.0))


# -- devices and record ----------------------------------------------------------------------


def test_describe_devices_says_clearly_when_nothing_is_attached() -> None:
    from thermodepth.app.devices import describe_devices

    lines = describe_devices(
        {
            "realsense": [],
            "thermal": [],
            "video": [{"index": 0, "name": "Integrated Camera", "kind": None}],
        }
    )
    assert lines == [
        "no RealSense device found",
        "no thermal camera found (PureThermal Lepton, InfiRay P2 Pro / Topdon TC001, FLIR "
        "Boson); other video devices: /dev/video0 (Integrated Camera)",
    ]
    thermal = [
        {"index": 2, "name": "PureThermal (fw:v1.3.0)", "kind": "lepton"},
        {"index": 4, "name": "USB Camera", "kind": "p2pro"},
        {"index": 6, "name": "Boson: FLIR Video", "kind": "boson"},
    ]
    found = describe_devices(
        {
            "realsense": [
                {"name": "Intel RealSense D435", "serial": "123", "firmware": "5.16", "usb": "3.2"}
            ],
            "thermal": thermal,
            "video": thermal,
        }
    )
    assert found[0].endswith("-> --source realsense:123")
    assert found[1].startswith("PureThermal (Lepton) /dev/video2")
    assert found[1].endswith("-> --source lepton:2 (with a depth camera: realsense+lepton:2)")
    assert found[2].startswith("InfiRay P2 Pro / Topdon TC001 /dev/video4")
    assert found[2].endswith("-> --source p2pro:4 (with a depth camera: realsense+p2pro:4)")
    assert found[3].endswith("-> --source boson:6 (with a depth camera: realsense+boson:6)")


def test_devices_command_runs() -> None:
    result = runner.invoke(app, ["devices", "--json"])
    assert result.exit_code == 0, result.output
    listed = json.loads(result.output)
    assert set(listed) == {"realsense", "realsense_unavailable", "thermal", "video"}


def test_devices_says_why_realsense_cannot_be_listed(monkeypatch: pytest.MonkeyPatch) -> None:
    from thermodepth.sources import realsense

    def unavailable() -> None:
        raise ThermodepthError("pyrealsense2 is not available (libusb-1.0.so.0: cannot open)")

    monkeypatch.setattr(realsense, "import_realsense", unavailable)
    result = runner.invoke(app, ["devices"])
    assert result.exit_code == 0, result.output
    assert result.output.splitlines()[0] == (
        "RealSense devices cannot be listed: pyrealsense2 is not available "
        "(libusb-1.0.so.0: cannot open)"
    )


def test_record_sim_command(tmp_path: Path) -> None:
    from thermodepth.io.recording import Recording

    out = tmp_path / "s.zarr"
    result = runner.invoke(app, ["record", "--source", "sim", "-o", str(out), "--frames", "3"])
    assert result.exit_code == 0, result.output
    assert "recorded 3 pairs (3 depth, 3 thermal frames), dropped 0" in result.output
    assert "stopped: frames" in result.output
    assert Recording(out).n_pairs == 3
    small = tmp_path / "z.zarr"
    args = ["record", "--source", f"recording:{out}", "-o", str(small), "--codec", "zstd"]
    assert runner.invoke(app, args).exit_code == 0
    assert Recording(small)._arrays["depth/image"].metadata.codecs[1].cname.value == "zstd"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--source", "sim"], "--source: sim never ends: give frames or a duration"),
        (["--source", "sim", "--frames", "0"], "--frames: must be at least 1"),
        (["--source", "sim", "--duration", "-1"], "--duration: must be > 0 seconds"),
        (["--source", "nope", "--frames", "1"], "--source: unknown 'nope'"),
        (
            ["--source", "recording:{tmp}/none.zarr", "--frames", "1"],
            "{tmp}/none.zarr: no such recording",
        ),
        (
            ["--source", "sim", "--frames", "1", "--max-skew-ms", "-2"],
            "--max-skew-ms: must be >= 0",
        ),
        (
            ["--source", "sim", "--frames", "1", "--thermal-latency-ms", "-5"],
            "--thermal-latency-ms: must be >= 0",
        ),
        (["--source", "sim", "--frames", "1", "--codec", "gzip"], "--codec: expected one of lz4"),
    ],
)
def test_record_bad_input_is_one_line(tmp_path: Path, args: list[str], message: str) -> None:
    out = tmp_path / "o.zarr"
    args = [a.format(tmp=tmp_path) for a in args]
    result = runner.invoke(app, ["record", *args, "-o", str(out)])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("error: ")
    assert message.format(tmp=tmp_path) in lines[0]


def test_record_refuses_to_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "o.zarr"
    out.mkdir()
    result = runner.invoke(app, ["record", "--source", "sim", "--frames", "1", "-o", str(out)])
    assert result.exit_code == 2
    assert f"{out}: already exists (choose another output, or --overwrite" in result.output


def test_record_overwrite_keeps_what_is_not_a_recording(tmp_path: Path) -> None:
    data = tmp_path / "data"  # `record -o ~/data --overwrite`
    data.mkdir()
    (data / "notes.txt").write_text("keep me")
    result = runner.invoke(
        app, ["record", "--source", "sim", "--frames", "1", "-o", str(data), "--overwrite"]
    )
    assert result.exit_code == 2
    assert f"{data}: not a thermodepth recording; --overwrite replaces recordings only" in (
        result.output
    )
    assert (data / "notes.txt").read_text() == "keep me"


def test_record_over_its_own_source_is_refused(tmp_path: Path) -> None:
    from thermodepth.io.recording import Recording

    a = tmp_path / "a.zarr"
    assert runner.invoke(app, ["record", "-s", "sim", "--frames", "2", "-o", str(a)]).exit_code == 0
    result = runner.invoke(
        app, ["record", "--source", f"recording:{a}", "-o", str(a), "--overwrite"]
    )
    assert result.exit_code == 2
    assert f"{a}: the source reads {a}; write the recording somewhere else" in result.output
    assert len(list(Recording(a).pairs())) == 2


def test_record_checks_the_output_before_opening_the_source(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import thermodepth.sources

    def must_not_open(*args: object, **kwargs: object) -> None:
        raise AssertionError("the cameras were started before the output was checked")

    monkeypatch.setattr(thermodepth.sources, "open_source", must_not_open)
    (tmp_path / "o.zarr").mkdir()
    result = runner.invoke(app, ["record", "-s", "lepton", "-o", str(tmp_path / "o.zarr")])
    assert result.exit_code == 2
    assert "already exists" in result.output


def test_record_prints_and_stores_the_source_counters(tmp_path: Path) -> None:
    from thermodepth.io.recording import Recording

    a, b = tmp_path / "a.zarr", tmp_path / "b.zarr"
    runner.invoke(app, ["record", "-s", "sim", "--frames", "2", "-o", str(a)])
    result = runner.invoke(app, ["record", "-s", f"recording:{a}", "-o", str(b)])
    assert result.exit_code == 0, result.output
    assert "source: replay_skipped 0" in result.output
    assert Recording(b).attrs["source_counters"] == {"replay_skipped": 0}


def test_missing_lepton_is_one_line_without_opencv_warnings(
    tmp_path: Path, cli_process: CliProcess
) -> None:
    if Path("/dev/video57").exists():
        pytest.skip("/dev/video57 exists")
    proc = cli_process("record", "-s", "lepton:57", "-o", str(tmp_path / "l.zarr"))
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == ["error: /dev/video57: cannot open (no such device)"]


# -- what a new user found --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["run", "--frames", "-1"], "--frames: must be at least 1, got -1"),
        (["run", "--frames", "0"], "--frames: must be at least 1, got 0"),
        (["simulate", "sweep", "-o", "{tmp}/s.csv", "--samples", "0"], "--samples: must be"),
        (["simulate", "frames", "-o", "{tmp}/f", "--frames", "-2"], "--frames: must be at"),
        (["simulate", "targets", "-o", "{tmp}/t", "--poses", "0"], "--poses: must be at least"),
    ],
)
def test_every_count_option_is_checked_the_same_way(
    tmp_path: Path, args: list[str], message: str
) -> None:
    result = runner.invoke(app, [a.format(tmp=tmp_path) for a in args])
    assert result.exit_code == 2, result.output
    assert result.output.strip().startswith(f"error: {message}")
    assert not any(tmp_path.iterdir())  # nothing written


def test_a_calibration_cut_short_names_no_internal_class(tmp_path: Path) -> None:
    text = EXAMPLE.read_text()
    cut = tmp_path / "cut.yaml"
    cut.write_text(text[: text.index("thermal:") + len("thermal:")] + "\n")
    result = runner.invoke(app, ["check-calibration", str(cut)])
    assert result.exit_code == 2
    assert result.output.strip() == (
        f"error: {cut}: thermal: expected a mapping of keys, got nothing [and 1 more problem]"
    )


def test_sim_and_recording_runs_end_with_their_pairs_skew(tmp_path: Path) -> None:
    out = tmp_path / "r.zarr"
    rec = runner.invoke(app, ["record", "-s", "sim", "-o", str(out), "--frames", "3"])
    assert rec.exit_code == 0, rec.output
    run = runner.invoke(app, ["run", "--source", f"recording:{out}", "--quiet"])
    assert run.exit_code == 0, run.output
    lines = []
    for output, who in ((rec.output, "the simulator"), (run.output, "the recorded run")):
        line = next(x for x in output.splitlines() if x.startswith("pairing"))
        assert line.startswith(f"pairing (paired by {who}): pairs 3, |skew| median ")
        lines.append(line.split(": ", 1)[1])
    assert lines[0] == lines[1]  # the replay's skews are the recording's


@pytest.mark.parametrize(
    "command", ["run", "record", "calibrate", "fit-compensation", "temperature"]
)
def test_help_reads_as_text(command: str) -> None:
    result = runner.invoke(app, [command, "--help"], env={"COLUMNS": "80"})
    assert result.exit_code == 0
    assert "<bool>" not in result.output
    assert max(len(line) for line in result.output.splitlines()) <= 80
    words = " ".join(result.output.split())
    # a help text wrapped at words reads whole once the line breaks are joined
    helps = {
        "run": "hotspots.csv here (with line or isotherm ROIs, lines.csv and isotherms.csv too).",
        "record": "Replace an existing recording (nothing else).",
        "calibrate": "Hold the depth camera's intrinsics fixed: a calibration file (its depth",
        "fit-compensation": "paper: the reference temperature (C) to fit at (default 39 if",
        "temperature": "Reflected apparent temperature, C (default: the air's).",
    }
    assert helps[command] in words


def test_every_cli_module_stays_thin() -> None:
    """The CLI is typer signatures over app/: no file of it over 400 lines."""
    import thermodepth.cli

    folder = Path(thermodepth.cli.__file__).parent
    lines = {p.name: len(p.read_text(encoding="utf-8").splitlines()) for p in folder.glob("*.py")}
    assert {"__init__.py", "measure.py", "monitor.py"} <= set(lines)
    assert {name: n for name, n in lines.items() if n > 400} == {}


def test_compile_readies_each_part_s_kernels_and_refuses_an_unknown_part() -> None:
    # in a fresh interpreter: nothing compiled or loaded before, both parts' kernels after
    script = """
from thermodepth.cli import app
from thermodepth.registration import kernels as reg
from thermodepth.sim import kernels as sim
ready = lambda: [bool(k.signatures) for k in (reg.sample, reg.zbuffer, sim.render_radiance)]
print(ready())
try:
    app(["compile"])
except SystemExit as end:
    print(end.code, ready())
"""
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True, timeout=600
    )
    lines = done.stdout.splitlines()
    assert len(lines) == 4 and lines[0] == "[False, False, False]"
    assert lines[1].startswith("pipeline: kernels ready in ")
    assert lines[2].startswith("sim: kernels ready in ") and lines[3] == "0 [True, True, True]"
    result = runner.invoke(app, ["compile", "--only", "maps"])
    assert result.exit_code == 2
    assert result.output.strip() == "error: --only: 'maps' is not one of pipeline, sim"
