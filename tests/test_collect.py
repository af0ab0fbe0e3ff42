"""collect-sweep: the reference plate found in frames, sweep rows from a recording of the
paper's protocol on the simulated rig checked against its truth, fits on them, and bad input."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from typer.testing import CliRunner

from thermodepth.app.collect import CollectOptions, collect_sweep
from thermodepth.cli import app
from thermodepth.collect import SweepCollector
from thermodepth.compensation import PaperModel, RadianceModel, apply_to_table, overall
from thermodepth.conditions import Conditions, Radiometry
from thermodepth.errors import FieldError, InputError
from thermodepth.frames import FramePair, match_of
from thermodepth.io.recording import RecordingWriter
from thermodepth.sim.lepton import (
    LeptonModel,
    counts_from_radiance,
    measured_radiance,
    radiance_table,
)
from thermodepth.sim.protocols import (
    ProtocolConfig,
    SweepConfig,
    simulate_protocol,
    simulate_sweep,
)
from thermodepth.sim.rig import Rig, default_calibration
from thermodepth.sim.scene import camera_pose, plate_scene
from thermodepth.sweep import SweepTable, read_sweep_csv
from thermodepth.target import TargetSpec

runner = CliRunner()
# pairs every 2 s while the camera warms 15 K in 24 s: FFCs every ~2.4 s, some of them seen
PROTOCOL = ProtocolConfig(
    distances_m=(0.5, 1.5, 2.5), pairs_per_distance=12, interval_s=2.0, move_s=6.0, seed=3
)
EMISSIVITY = 0.95


def words(text: str) -> str:
    return " ".join(text.split())


def time_s(table: SweepTable) -> np.ndarray:
    return np.array([float(t) for t in table.extra["time_s"]])


@pytest.fixture(scope="module")
def protocol(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return simulate_protocol(tmp_path_factory.mktemp("protocol") / "protocol.zarr", PROTOCOL)


@pytest.fixture(scope="module")
def collected(protocol: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    out = tmp_path_factory.mktemp("sweep") / "sweep.csv"
    args = ["collect-sweep", "--source", f"recording:{protocol}", "--reference-temp-c", "39"]
    result = runner.invoke(app, [*args, "-o", str(out)])
    assert result.exit_code == 0, result.output
    return out, result.output


# -- the target in a frame --------------------------------------------------------------------


def frame_view(rig: Rig) -> tuple[np.ndarray, np.ndarray]:
    """Z per thermal pixel and the apparent temperature of one frame of ``rig``."""
    from thermodepth.registration import Registration

    pair = rig.frame()
    z = Registration(rig.calibration).depth_to_thermal(pair.depth).z_m
    return z, Radiometry(Conditions(emissivity=EMISSIVITY)).celsius(pair.thermal)


@pytest.mark.parametrize(
    ("distance_m", "chip_temp_c"), [(0.5, 70.0), (1.2, 70.0), (2.5, 70.0), (4.0, None)]
)
def test_auto_target_is_the_plate_inside_its_border(
    distance_m: float, chip_temp_c: float | None
) -> None:
    scene = plate_scene(39.0, chip_temp_c=chip_temp_c)  # a hot chip: the plate not uniform
    rig = Rig(scene, camera_pose(distance_m), start_s=1.0)
    truth = rig.truth()
    plate = truth.thermal_rect == scene.index("plate")
    z, temp = frame_view(rig)
    mask = TargetSpec.parse("auto").find(z, temp, 39.0)
    assert mask is not None
    assert not (mask & ~plate).any()  # never off the plate (nor on the chip's faces)
    chip = np.isin(truth.thermal_rect, [i for i, r in enumerate(scene.rects) if "chip" in r.name])
    # most of the plate, once the pixels that see its border or the chip through the blur
    # are left out
    inside = cv2.erode(plate.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    chip_zone = cv2.dilate(chip.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    assert (mask & inside).sum() >= 0.9 * (inside & ~chip_zone).sum()


def test_auto_target_not_found_far_from_the_reference() -> None:
    z, temp = frame_view(Rig(plate_scene(39.0), camera_pose(1.0), start_s=1.0))
    assert TargetSpec().find(z, temp, 39.0) is not None
    # the wall and floor are flat and uniform too, but at the room's 25 C
    assert TargetSpec().find(z, temp, 60.0) is None
    assert TargetSpec().find(np.full_like(z, np.nan), temp, 39.0) is None  # no depth


def test_rect_and_depth_range_targets() -> None:
    rig = Rig(plate_scene(39.0), camera_pose(1.0), start_s=1.0)
    z, temp = frame_view(rig)
    rect = TargetSpec.parse("rect:75,55,85,65").find(z, temp, 39.0)
    assert rect is not None and rect.sum() == 100 and rect[55:65, 75:85].all()
    near = TargetSpec.parse("depth-range:0.9,1.1").find(z, temp, 39.0)
    plate = rig.truth().thermal_rect == rig.scene.index("plate")
    assert near is not None and (near & plate).sum() >= 0.95 * near.sum()
    assert TargetSpec.parse("depth-range:5,6").find(z, temp, 39.0) is None
    with pytest.raises(FieldError, match="outside the 160x120 thermal image"):
        TargetSpec.parse("rect:200,0,210,10").check_inside((120, 160))


@given(st.integers(0, 500), st.integers(0, 500), st.integers(1, 500), st.integers(1, 500))
def test_rect_specs_read_back(u0: int, v0: int, du: int, dv: int) -> None:
    spec = TargetSpec.parse(f"rect:{u0},{v0},{u0 + du},{v0 + dv}")
    assert spec.rect == (u0, v0, u0 + du, v0 + dv)
    assert TargetSpec.parse(str(spec)) == spec


@given(st.text(max_size=30))
def test_any_target_text_parses_or_names_the_option(text: str) -> None:
    try:
        spec = TargetSpec.parse(text)
    except FieldError as exc:
        assert exc.field == "target"
        assert "\n" not in exc.message
    else:
        assert TargetSpec.parse(str(spec)) == spec


# -- rows against the simulator's truth --------------------------------------------------------


def test_rows_agree_with_the_truth(collected: tuple[Path, str]) -> None:
    path, output = collected
    rows = read_sweep_csv(path)
    t = time_s(rows)
    # the VOx is the telemetry's, the camera's FPA at that moment (centikelvin)
    want_vox = np.array([PROTOCOL.fpa_k(x) for x in t]) - 273.15
    np.testing.assert_allclose(rows["vox_temp_c"], want_vox, atol=0.006)
    assert rows["vox_temp_c"].min() < 27 and rows["vox_temp_c"].max() > 38
    lepton, table = LeptonModel(), radiance_table()
    radiometry = Radiometry(Conditions(emissivity=EMISSIVITY))
    scene = plate_scene(39.0)
    for d in PROTOCOL.distances_m:
        rig = Rig(scene, camera_pose(d))
        truth = rig.truth()
        plate = truth.thermal_rect == scene.index("plate")
        inside = cv2.erode(plate.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
        here = np.abs(rows["distance_m"] / d - 1) < 0.1
        assert here.sum() >= PROTOCOL.pairs_per_distance - 3  # FFC frames are skipped
        # distance: the plate's range from the thermal camera, to 0.3 %
        np.testing.assert_allclose(
            rows["distance_m"][here], np.median(truth.thermal_range_m[inside]), rtol=3e-3
        )
        # reading: the noise-free camera's at that FPA temperature, within its noise
        for i in np.flatnonzero(here):
            radiance = measured_radiance(rig.aperture, PROTOCOL.fpa_k(t[i]), lepton, table)
            want = radiometry.celsius(counts_from_radiance(radiance, lepton, table))[inside]
            assert rows["measured_temp_c"][i] == pytest.approx(want.mean(), abs=0.02)
    assert set(rows["reference_temp_c"]) == {39.0} and set(rows["n"]) == {1.0}
    assert set(rows["emissivity"]) == {EMISSIVITY}
    lines = words(output)
    assert "frame 1: target found: 6696 px at 0.52 m" in lines
    assert lines.count("target moved") == 2
    assert f"wrote {len(rows)} rows to {path} from {PROTOCOL.pairs} pairs (" in lines
    for n in range(1, 4):
        assert path.with_name(f"sweep_target_{n:02d}.png").exists()


def test_ffc_and_moving_frames_are_not_read(protocol: Path, collected: tuple[Path, str]) -> None:
    from thermodepth.io.recording import Recording

    rec = Recording(protocol)
    pairs = [m.pair for m in rec.matches()]
    ffc = {p.index for p in pairs if p.telemetry.in_ffc}
    assert ffc  # the protocol has FFC frames, flagged by the telemetry
    frames = {int(f) for f in read_sweep_csv(collected[0]).extra["frame"]}
    assert not frames & ffc
    assert "in FFC" in collected[1] and f"{len(ffc)} in FFC" in words(collected[1])
    # pairs taken while the plate moved between distances are not rows
    moving = [
        p.index
        for p in pairs
        if not any(
            abs(p.thermal_time_s - (PROTOCOL.start_s + k * (PROTOCOL.hold_s + PROTOCOL.move_s)))
            <= PROTOCOL.hold_s
            and p.thermal_time_s >= PROTOCOL.start_s + k * (PROTOCOL.hold_s + PROTOCOL.move_s)
            for k in range(len(PROTOCOL.distances_m))
        )
    ]
    assert moving and not frames & set(moving)


def test_a_fit_on_collected_rows_scores_as_one_on_a_simulated_sweep(
    collected: tuple[Path, str],
) -> None:
    rows = read_sweep_csv(collected[0])
    sweep = simulate_sweep(SweepConfig(distances_m=PROTOCOL.distances_m, samples=60, seed=4))
    held_out = {
        "distances": simulate_sweep(SweepConfig(distances_m=(1.0, 2.0), samples=100, seed=8)),
        "targets": simulate_sweep(SweepConfig(plate_temps_c=(45.0, 60.0), samples=80, seed=9)),
    }
    for name, test in held_out.items():
        got = overall(apply_to_table(RadianceModel.fit(rows), test).temp_c, test)
        base = overall(apply_to_table(RadianceModel.fit(sweep), test).temp_c, test)
        assert got["rmse_c"] <= 1.3 * base["rmse_c"] + 0.005, name
        assert got["max_abs_error_c"] <= 1.3 * base["max_abs_error_c"] + 0.01, name
        assert got["rmse_c"] < 0.05, name
    # the paper's method takes each placement's wandering distance as one calibrated distance
    paper = PaperModel.fit(rows)
    assert len(paper.distances_m) == len(PROTOCOL.distances_m)
    np.testing.assert_allclose(paper.distances_m, PROTOCOL.distances_m, rtol=0.04)


def test_average_makes_rows_of_n_readings(
    protocol: Path, collected: tuple[Path, str], tmp_path: Path
) -> None:
    out = tmp_path / "avg.csv"
    result = collect_sweep(
        CollectOptions(
            f"recording:{protocol}",
            out,
            39.0,
            average=4,
            conditions=Conditions(emissivity=EMISSIVITY),
        )
    )
    single, avg = read_sweep_csv(collected[0]), read_sweep_csv(out)
    assert avg["n"].sum() == len(single) and avg["n"].max() == 4 and result.rows == len(avg)
    # each row is the mean of its readings, and never spans two distances
    first = {int(f): i for i, f in enumerate(single.extra["frame"])}
    for j, f in enumerate(avg.extra["frame"]):
        i = first[int(f)]
        n = int(avg["n"][j])
        assert avg["measured_temp_c"][j] == pytest.approx(
            single["measured_temp_c"][i : i + n].mean(),
            abs=1e-4,  # 6 digits each
        )
        d = single["distance_m"][i : i + n]
        assert d.max() / d.min() < 1.01


def test_target_lost_and_found_again() -> None:
    rig = Rig(plate_scene(39.0), camera_pose(1.0), start_s=1.0)
    lines: list[str] = []
    collector = SweepCollector(
        rig.calibration,
        TargetSpec(),
        39.0,
        Conditions(emissivity=EMISSIVITY),
        3,
        say=lines.append,
    )
    rows = []
    for pair in rig.frames(10):
        if 4 <= pair.index <= 5:  # someone walks in front: a uniform 25 C, nothing at 39 C
            pair = replace(pair, thermal=np.full_like(pair.thermal, int(pair.thermal.min())))
        rows += collector.add(pair)
    rows += collector.close()
    assert lines[0].startswith("frame 1: target found")  # told once it held still
    assert lines[1:] == ["frame 4: target lost", "frame 7: target found again (lost at frame 4)"]
    # rows: frames 0-2, 3 (ended by the loss); 6-8, 9
    assert [r["n"] for r in rows] == [3, 1, 3, 1]
    assert [r["frame"] for r in rows] == [0, 3, 6, 9]
    assert collector.stats.missing_pairs == 2 and collector.stats.placements == 1


def test_rows_are_on_disk_as_they_are_made(protocol: Path, tmp_path: Path) -> None:
    out = tmp_path / "killed.csv"
    proc = subprocess.Popen(
        [sys.executable, "-m", "thermodepth.cli", "collect-sweep", "--source",
         f"recording:{protocol}", "--reference-temp-c", "39", "-o", str(out)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    seen = 0
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        if out.exists() and (seen := out.read_text().count("\n")) >= 4:
            break
        time.sleep(0.01)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert seen >= 4
    rows = read_sweep_csv(out)  # every row written is whole
    assert len(rows) >= seen - 1
    # and the run goes on from there
    more = runner.invoke(app, [
        "collect-sweep", "--source", f"recording:{protocol}", "--reference-temp-c", "39",
        "-o", str(out), "--append", "--frames", "3",
    ])  # fmt: skip
    assert more.exit_code == 0, more.output
    assert len(read_sweep_csv(out)) > len(rows)


# -- bad input ---------------------------------------------------------------------------------


def collect(*args: str) -> tuple[int, str]:
    result = runner.invoke(app, ["collect-sweep", *args])
    return result.exit_code, words(result.output)


def collect_from(recording: Path, out: Path, *more: str, reference: str = "39") -> tuple[int, str]:
    """collect-sweep of a recording into ``out``: (exit code, output as one line)."""
    return collect("--source", f"recording:{recording}", "--reference-temp-c", reference,
                   "-o", str(out), *more)  # fmt: skip


def test_target_never_found(protocol: Path, tmp_path: Path) -> None:
    out = tmp_path / "s.csv"
    code, text = collect_from(protocol, out, reference="80")
    assert code == 2
    assert text.startswith(
        f"error: recording:{protocol}: the target auto was never found in {PROTOCOL.pairs} pairs"
    )
    assert "within 5 C of 80 C" in text and "no rows written" in text
    assert not out.exists()
    assert (tmp_path / "s_target_none.png").exists()  # what the camera saw instead


def test_reference_temperature_missing(protocol: Path, tmp_path: Path) -> None:
    code, text = collect("--source", f"recording:{protocol}", "-o", str(tmp_path / "s.csv"))
    assert code == 2
    assert text == (
        "error: --reference-temp-c: give the plate's true temperature (C), as its contact "
        "thermometer reads it"
    )


def test_output_exists_without_append(protocol: Path, tmp_path: Path) -> None:
    out = tmp_path / "s.csv"
    out.write_text("mine\n")
    code, text = collect_from(protocol, out)
    assert code == 2
    assert text == (
        f"error: --out: {out} exists; add --append to add rows to it, or choose another file"
    )
    assert out.read_text() == "mine\n"
    code, text = collect_from(protocol, out, "--append")
    assert code == 2
    assert text == (
        f"error: {out}: cannot append: its header lacks distance_m, vox_temp_c, "
        "measured_temp_c, reference_temp_c (not a sweep CSV?)"
    )
    out.write_text("distance_m,vox_temp_c,measured_temp_c,reference_temp_c\n1,30,37,39\n1,3")
    code, text = collect_from(protocol, out, "--append")
    assert code == 2 and "its last line is unfinished" in text
    assert out.read_text().endswith("1,3")


def test_appended_rows_follow_the_file_header(protocol: Path, tmp_path: Path) -> None:
    out = tmp_path / "s.csv"
    out.write_text("site,distance_m,vox_temp_c,measured_temp_c,reference_temp_c\nlab,1,30,37,39\n")
    code, text = collect_from(protocol, out, "--append", "--frames", "4")
    assert code == 0, text
    table = read_sweep_csv(out)
    assert table.names == ["site", "distance_m", "vox_temp_c", "measured_temp_c",
                           "reference_temp_c"]  # fmt: skip
    assert table.extra["site"][0] == "lab" and set(table.extra["site"][1:]) == {""}
    assert len(table) >= 3


def recording_of(pairs: list[FramePair], path: Path) -> Path:
    with RecordingWriter(path, default_calibration(), {}, source="test") as writer:
        for pair in pairs:
            writer.add_match(match_of(pair))
    return path


def test_a_source_without_telemetry(tmp_path: Path) -> None:
    rig = Rig(plate_scene(39.0), camera_pose(1.0), start_s=1.0)
    pairs = list(rig.frames(6))
    pairs[4:] = [
        replace(p, telemetry=replace(p.telemetry, fpa_temp_k=float("nan"))) for p in pairs[4:]
    ]
    rec = recording_of(pairs, tmp_path / "no-telemetry.zarr")
    out = tmp_path / "s.csv"
    code, text = collect_from(rec, out)
    assert code == 2
    assert text.endswith(
        f"error: recording:{rec}: frame 4: no VOx (FPA) temperature in the telemetry (nan K); "
        f"a sweep needs the Lepton's telemetry: enable it and record again; {out} keeps the "
        "4 rows before it"
    )
    assert len(read_sweep_csv(out)) == 4  # every row before it is kept


def test_tlinear_and_depth_only_sources(tmp_path: Path) -> None:
    rig = Rig(plate_scene(39.0), camera_pose(1.0), start_s=1.0)
    pairs = [replace(p, telemetry=replace(p.telemetry, tlinear=True)) for p in rig.frames(2)]
    rec = recording_of(pairs, tmp_path / "tlinear.zarr")
    code, text = collect_from(rec, tmp_path / "s.csv")
    # raw counts read as kelvin x 100 are no temperature: no target in them
    assert code == 2 and "the target auto was never found" in text
    code, text = collect("--source", "sim", "--reference-temp-c", "39",
                         "-o", str(tmp_path / "s.csv"))  # fmt: skip
    assert code == 2 and text == "error: --source: sim never ends: give frames"


@pytest.mark.parametrize(
    ("target", "message"),
    [
        ("box", "error: --target: 'box': expected auto, rect:U0,V0,U1,V1"),
        ("rect:1,2,3", "error: --target: 'rect:1,2,3': expected rect:U0,V0,U1,V1 (4 integers)"),
        ("rect:5,5,5,9", "error: --target: 'rect:5,5,5,9': expected U0 < U1 and V0 < V1"),
        ("depth-range:2,1", "error: --target: 'depth-range:2,1': expected 0 <= NEAR < FAR"),
        ("rect:300,0,310,10", "error: --target: rect:300,0,310,10 lies outside the 160x120"),
    ],
)
def test_bad_targets(protocol: Path, tmp_path: Path, target: str, message: str) -> None:
    code, text = collect_from(protocol, tmp_path / "s.csv", "--target", target)
    assert code == 2 and text.startswith(message), text


def test_collect_options_are_checked_before_anything_opens(tmp_path: Path) -> None:
    code, text = collect("--reference-temp-c", "39", "-o", str(tmp_path / "s.csv"))
    assert code == 2 and text == (
        "error: --calibration: realsense+lepton needs the rig's calibration file "
        "(thermodepth calibrate) to register depth to thermal pixels"
    )
    with pytest.raises(FieldError, match="must be"):
        collect_sweep(CollectOptions("recording:/nowhere", tmp_path / "s.csv", 39.0, average=0))
    with pytest.raises(InputError, match="nowhere"):
        collect_sweep(CollectOptions("recording:/nowhere", tmp_path / "s.csv", 39.0))
