"""Reflected temperature from a reflector ROI (ASTM E1862) and emissivity from a reference
emitter (ASTM E1933), through the simulator's radiometric model: patches of known emissivity
and temperature beside each other, the room (what every diffuse surface reflects) at 25 C."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from thermodepth.app.emissivity import write_roi_emissivity
from thermodepth.cli import app
from thermodepth.emissivity import estimate_emissivity
from thermodepth.errors import FieldError, InputError
from thermodepth.materials import MATERIALS
from thermodepth.pipeline import Pipeline, RadiometrySettings, RoiSettings, Settings
from thermodepth.radiometry import ZERO_C_IN_K
from thermodepth.session import record_session
from thermodepth.sim import Material, Rect, Rig, Scene, camera_pose, constant_fpa
from thermodepth.sources.sim import SimSource

ROOM_C = 25.0
HOT_C = 60.0
EX, EY = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])


def patch(name: str, x_m: float, temp_c: float, emissivity: float, half_m: float) -> Rect:
    material = Material(temp_c + ZERO_C_IN_K, emissivity, 0.5, name)
    return Rect(np.array([x_m, 0, 0]), EX, EY, half_m, half_m, material, name=name)


Box = tuple[int, int, int, int]


def bench(distance_m: float, busbar_emissivity: float) -> tuple[Rig, dict[str, Box]]:
    """Tape (0.95) and a busbar (``busbar_emissivity``), both at 60 C, and a crumpled-foil
    card (0.04) at the room's 25 C, side by side on a plane 30 cm before a wall; the rig
    ``distance_m`` away; and each patch's inner rectangle on the depth image."""
    half = 0.05 * distance_m
    xs = {"tape": -2.6 * half, "busbar": 0.0, "foil": 2.6 * half}
    wall_material = Material(ROOM_C + ZERO_C_IN_K, 0.9, 0.5, "wall")
    wall = Rect(np.array([0, 0, 0.3]), EX, EY, 6.0, 4.0, wall_material, name="wall")
    scene = Scene(
        (
            patch("tape", xs["tape"], HOT_C, 0.95, half),
            patch("busbar", xs["busbar"], HOT_C, busbar_emissivity, half),
            patch("foil", xs["foil"], ROOM_C, 0.04, half),
            wall,
        ),
        ROOM_C + ZERO_C_IN_K,
        0.5,
    )
    rig = Rig(scene, camera_pose(distance_m), start_s=1.0, fpa=constant_fpa(35 + ZERO_C_IN_K))
    rects: dict[str, Box] = {}
    for name, x in xs.items():
        inner = 0.6 * half  # clear of the optics' blur at the patch's edges
        corners = np.array([[x - inner, -inner, 0.0], [x + inner, inner, 0.0]])
        uv = rig.calibration.depth.project(rig.depth_from_world.apply(corners))
        u0, v0, u1, v1 = (int(v) for v in np.rint(uv).ravel())
        rects[name] = (u0, v0, u1, v1)
    return rig, rects


def test_a_reflector_sets_the_reflected_temperature_of_the_rois_it_names() -> None:
    # the settings' reflected temperature is wrong (0 C; the room is at 25 C): the busbar
    # (emissivity 0.6) read with it is some 10 C off; read with the foil's reading, within 1 C
    rig, rects = bench(1.0, 0.6)
    settings = Settings(
        radiometry=RadiometrySettings(reflected_temp_c=0.0),
        rois=[
            RoiSettings(name="guessed", rect=rects["busbar"], emissivity=0.6),
            RoiSettings(name="busbar", rect=rects["busbar"], emissivity=0.6),
            RoiSettings(name="foil", rect=rects["foil"], reflector=True, reflects_for=["busbar"]),
        ],
    )
    pipeline = Pipeline(settings, rig.calibration)
    for _ in range(3):
        rois = {r.name: r for r in pipeline.process(rig.frame()).rois}
        assert rois["foil"].mean_c == pytest.approx(ROOM_C, abs=0.5)  # read at emissivity 1
        assert rois["busbar"].mean_c == pytest.approx(HOT_C, abs=1.0)
        assert rois["guessed"].mean_c - HOT_C > 5.0


def test_reflector_settings_are_checked_one_line_each() -> None:
    rect = (0, 0, 10, 10)
    bad = [
        ({"reflector": True, "emissivity": 0.5}, "read at emissivity 1"),
        ({"reflects_for": ["x"]}, "reflects_for is for a reflector"),
    ]
    for extra, words in bad:
        with pytest.raises(ValueError, match=words):
            RoiSettings(name="foil", rect=rect, **extra)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="'nothing' is not an ROI"):
        Settings(rois=[RoiSettings(name="f", rect=rect, reflector=True, reflects_for=["nothing"])])
    with pytest.raises(ValueError, match="reflected_temp_c and reflector 'f' both set it"):
        Settings(
            rois=[
                RoiSettings(name="f", rect=rect, reflector=True, reflects_for=["t"]),
                RoiSettings(name="t", rect=rect, reflected_temp_c=20.0),
            ]
        )


def test_material_sets_an_rois_emissivity_and_an_explicit_one_wins() -> None:
    rect = (0, 0, 10, 10)
    taped = RoiSettings(name="a", rect=rect, material="electrical-tape")
    assert taped.own_emissivity == MATERIALS["electrical-tape"].emissivity == 0.96
    both = RoiSettings(name="b", rect=rect, material="oxidised-copper", emissivity=0.7)
    assert both.own_emissivity == 0.7
    assert all(0 < m.emissivity <= 1 and m.source for m in MATERIALS.values())
    with pytest.raises(ValueError, match="choose from"):
        RoiSettings(name="c", rect=rect, material="unobtainium")


@pytest.mark.parametrize(("distance_m", "emissivity"), [(1.0, 0.6), (2.0, 0.3)])
def test_emissivity_from_a_reference_tape_is_recovered(
    distance_m: float, emissivity: float
) -> None:
    rig, rects = bench(distance_m, emissivity)
    settings = Settings(
        rois=[
            RoiSettings(name="tape", rect=rects["tape"]),
            RoiSettings(name="busbar", rect=rects["busbar"]),
        ]
    )
    pairs = [rig.frame() for _ in range(4)]
    found = estimate_emissivity(settings, rig.calibration, pairs, "tape", "busbar", 0.95, 0.02)
    assert found.emissivity == pytest.approx(emissivity, abs=0.02)
    assert found.temp_c == pytest.approx(HOT_C, abs=0.5)
    assert found.frames == 4 and len(found.per_frame) == 4
    # the target's emissivity scales with the reference's (radiances in proportion): the
    # tolerance's rectangular +-0.02 carries over as (e / 0.95) 0.02 / sqrt(3)
    assert found.from_reference == pytest.approx(emissivity / 0.95 * 0.02 / math.sqrt(3), rel=0.1)
    assert found.uncertainty == pytest.approx(math.hypot(found.from_frames, found.from_reference))


def test_emissivity_names_a_missing_roi() -> None:
    rig, rects = bench(1.0, 0.6)
    settings = Settings(rois=[RoiSettings(name="tape", rect=rects["tape"])])
    with pytest.raises(FieldError, match="target: 'busbar' is no ROI"):
        estimate_emissivity(settings, rig.calibration, [], "tape", "busbar", 0.95)
    two = Settings(
        rois=[
            RoiSettings(name="tape", rect=rects["tape"]),
            RoiSettings(name="busbar", rect=rects["busbar"]),
        ]
    )
    with pytest.raises(InputError, match="no frame gives 'busbar' an emissivity"):
        estimate_emissivity(two, rig.calibration, [], "tape", "busbar", 0.95)


SETTINGS_YAML = """\
# the switchboard
radiometry:
  ambient_temp_c: 25.0   # the room
rois:
  - {name: tape, rect: RECT_TAPE}
  - name: busbar
    rect: RECT_BUSBAR
    material: oxidised-copper  # a guess until measured
"""


def test_the_command_measures_a_recording_and_writes_the_settings(tmp_path: Path) -> None:
    rig, rects = bench(1.0, 0.6)
    record_session(SimSource(rig), tmp_path / "rec.zarr", frames=4)
    path = tmp_path / "settings.yaml"
    text = SETTINGS_YAML.replace("RECT_TAPE", str(list(rects["tape"])))
    path.write_text(text.replace("RECT_BUSBAR", str(list(rects["busbar"]))), encoding="utf-8")
    args = [
        "emissivity", str(tmp_path / "rec.zarr"), "--reference", "tape", "--target",
        "busbar", "--reference-emissivity", "0.95", "--settings", str(path), "--frames", "3",
    ]  # fmt: skip
    result = CliRunner().invoke(app, [*args, "--write"])
    assert result.exit_code == 0, result.output
    printed = re.search(r"busbar: emissivity (\d\.\d+) \+- (\d\.\d+)", result.output)
    assert printed is not None, result.output
    assert float(printed[1]) == pytest.approx(0.6, abs=0.02) and float(printed[2]) > 0
    assert "roi 'busbar': emissivity" in result.output and "added" in result.output
    written = path.read_text(encoding="utf-8")
    assert "# a guess until measured" in written and "# the room" in written
    busbar = next(r for r in Settings.load(path).rois if r.name == "busbar")
    assert busbar.emissivity == pytest.approx(0.6, abs=0.02)
    assert busbar.material == "oxidised-copper"  # kept; the explicit emissivity wins
    # again: the value is replaced, not added twice
    again = CliRunner().invoke(app, [*args, "--write"])
    assert again.exit_code == 0, again.output
    assert "->" in again.output
    assert path.read_text(encoding="utf-8").count("emissivity:") == 1


def test_writing_an_emissivity_keeps_the_rest_of_the_file(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text(
        "rois:\n  - {name: tape, rect: [0, 0, 10, 10]}  # flow style\n"
        "  - name: bar\n    rect: [20, 0, 30, 10]\n    emissivity: 0.5\n",
        encoding="utf-8",
    )
    line = write_roi_emissivity(path, "tape", 0.9512)
    assert line.endswith("roi 'tape': emissivity 0.951 added")
    line = write_roi_emissivity(path, "bar", 0.25)
    assert line.endswith("roi 'bar': emissivity 0.5 -> 0.250")
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    assert data["rois"][0] == {"emissivity": 0.951, "name": "tape", "rect": [0, 0, 10, 10]}
    assert data["rois"][1]["emissivity"] == 0.25
    assert "# flow style" in path.read_text(encoding="utf-8")
    with pytest.raises(FieldError, match="no ROI named 'nope'"):
        write_roi_emissivity(path, "nope", 0.5)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--frames", "0"], "--frames: must be at least 1, got 0"),
        (["--reference-emissivity", "1.5"], "--reference-emissivity: 1.5 is outside (0, 1]"),
        (["--tolerance", "0.99"], "--tolerance: 0.99: expected 0 <= tolerance < the emissivity"),
        (["--target", "nope"], "--target: 'nope' is no ROI of"),
    ],
)
def test_the_command_says_what_is_wrong_in_one_line(
    tmp_path: Path, extra: list[str], message: str
) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("rois: [{name: tape, rect: [0, 0, 9, 9]}, {name: bar, rect: [9, 0, 19, 9]}]\n")
    args = ["emissivity", "sim", "--reference", "tape", "--target", "bar",
            "--reference-emissivity", "0.95", "--settings", str(path), *extra]  # fmt: skip
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2, result.output
    assert result.output.strip().startswith(f"error: {message}"), result.output
    assert len(result.output.strip().splitlines()) == 1
