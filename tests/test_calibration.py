"""The calibration file: round trips and one-line errors that name the file and field."""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from thermodepth.calibration import Calibration
from thermodepth.camera import rotation_from_euler
from thermodepth.errors import InputError
from thermodepth.radiometry import ThermalOutput

EXAMPLE = Path(__file__).parents[1] / "examples" / "calibration.yaml"


def valid_dict() -> dict[str, Any]:
    return {
        "depth": {
            "width": 1280,
            "height": 720,
            "fx": 645.0,
            "fy": 645.0,
            "cx": 639.5,
            "cy": 359.5,
            "distortion": [0, 0, 0, 0, 0],
            "depth_scale_m": 0.001,
        },
        "thermal": {
            "width": 160,
            "height": 120,
            "fx": 150.5,
            "fy": 150.5,
            "cx": 79.5,
            "cy": 59.5,
            "distortion": [-0.12, 0.05, 0, 0, 0],
        },
        "thermal_from_depth": {
            "rotation": rotation_from_euler(0.01, -0.02, 0.015).tolist(),
            "translation_m": [-0.04, 0.001, 0.002],
        },
    }


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_round_trip_is_exact(tmp_path: Path, suffix: str) -> None:
    cal = Calibration.from_dict(valid_dict())
    path = tmp_path / f"calib{suffix}"
    cal.save(path)
    back = Calibration.load(path)
    np.testing.assert_array_equal(back.thermal_from_depth.rotation, cal.thermal_from_depth.rotation)
    np.testing.assert_array_equal(back.thermal.distortion, cal.thermal.distortion)
    assert back.to_dict() == cal.to_dict()
    assert back.baseline_m == pytest.approx(np.linalg.norm([-0.04, 0.001, 0.002]))


def test_example_file_is_valid() -> None:
    cal = Calibration.load(EXAMPLE)
    assert cal.depth.shape == (720, 1280) and cal.thermal.shape == (120, 160)
    assert cal.thermal_from_depth.name == "thermal_from_depth"


def _set(d: dict[str, Any], path: str, value: Any) -> dict[str, Any]:
    out = copy.deepcopy(d)
    *keys, last = path.split(".")
    node = out
    for k in keys:
        node = node[k]
    if value is _DELETE:
        del node[last]
    else:
        node[last] = value
    return out


_DELETE = object()

BAD_CASES = [
    ("thermal.fx", _DELETE, "thermal.fx: missing"),
    ("depth.depth_scale_m", _DELETE, "depth.depth_scale_m: missing"),
    ("thermal_from_depth", _DELETE, "thermal_from_depth: missing"),
    ("thermal.distortion", [0.1, 0.0, 0.0, 0.0], "thermal.distortion: List should have at least 5"),
    ("depth.distortion", [0, 0, 0, 0, 0, 0], "depth.distortion: List should have at most 5"),
    (
        "thermal_from_depth.rotation",
        [[1, 0, 0], [0, 1, 0.001], [0, 0, 1]],
        "thermal_from_depth: rotation is not orthonormal",
    ),
    (
        "thermal_from_depth.rotation",
        [[1, 0, 0], [0, 1, 0], [0, 0, -1]],
        "thermal_from_depth: rotation is not orthonormal",
    ),
    ("thermal.fx", -150.0, "thermal.fx: Input should be greater than or equal to 1"),
    ("depth.fy", 0, "depth.fy: Input should be greater than or equal to 1"),
    ("thermal.cx", float("nan"), "thermal.cx: Input should be a finite number"),
    (
        "thermal_from_depth.translation_m",
        [0.0, float("inf"), 0.0],
        "thermal_from_depth.translation_m.1: Input should be a finite number",
    ),
    ("thermal.cx", 170.0, "thermal: cx=170.0 is outside the image (width 160)"),
    ("depth.cy", -3.0, "depth: cy=-3.0 is outside the image (height 720)"),
    ("thermal.fxx", 1.0, "thermal.fxx: unknown key"),
    ("depth.width", "wide", "depth.width: Input should be a valid integer"),
    ("thermal.output", {"kind": "celsius"}, "thermal.output.kind: Input should be 'counts' or"),
    ("thermal.output", {"kind": "kelvin"}, "thermal.output: a kelvin output needs scale_k"),
    (
        "thermal.output",
        {"kind": "kelvin", "scale_k": 0.0},
        "thermal.output.scale_k: Input should be greater than 0",
    ),
    (
        "thermal.output",
        {"kind": "counts", "scale_k": 0.01},
        "thermal.output: scale_k and offset_k are for kind: kelvin",
    ),
    ("thermal.output", {"kind": "kelvin", "scale_k": 0.01, "bits": 16}, "thermal.output: bits"),
    ("thermal.output", {"kind": "counts", "gain": 1}, "thermal.output.gain: unknown key"),
]


@pytest.mark.parametrize(
    ("field", "value", "message"),
    BAD_CASES,
    ids=[f"{c[0]}={'del' if c[1] is _DELETE else c[1]}" for c in BAD_CASES],
)
@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_bad_file_names_file_and_field(
    tmp_path: Path, suffix: str, field: str, value: Any, message: str
) -> None:
    path = tmp_path / f"calib{suffix}"
    data = _set(valid_dict(), field, value)
    if suffix == ".json":
        path.write_text(json.dumps(data))  # NaN/Infinity are written as JSON extensions
    else:
        path.write_text(yaml.safe_dump(data))
    with pytest.raises(InputError) as info:
        Calibration.load(path)
    text = str(info.value)
    assert text.startswith(f"{path}: {message}")
    assert "\n" not in text


@pytest.mark.parametrize(
    ("section", "want"),
    [
        (None, ThermalOutput()),  # files written before thermal.output: raw 14-bit counts
        ({"kind": "counts"}, ThermalOutput()),
        ({"kind": "counts", "bits": 16}, ThermalOutput(bits=16)),
        ({"kind": "kelvin", "scale_k": 0.01}, ThermalOutput.kelvin_per(0.01)),
        ({"kind": "kelvin", "scale_k": 0.015625, "offset_k": 0}, ThermalOutput.kelvin_per(1 / 64)),
        (
            {"kind": "kelvin", "scale_k": 0.1, "offset_k": 273.15},
            ThermalOutput.kelvin_per(0.1, 273.15),
        ),
    ],
)
def test_thermal_output_is_read_and_written(
    tmp_path: Path, section: dict[str, Any] | None, want: ThermalOutput
) -> None:
    data = valid_dict() if section is None else _set(valid_dict(), "thermal.output", section)
    path = tmp_path / "calib.yaml"
    path.write_text(yaml.safe_dump(data))
    cal = Calibration.load(path)
    assert cal.thermal_output == want
    cal.save(path)  # written with the keys other tools write: kind, scale_k, offset_k
    assert yaml.safe_load(path.read_text())["thermal"]["output"] == want.as_dict()
    assert Calibration.load(path).thermal_output == want


def test_rotation_within_tolerance_is_accepted() -> None:
    d = valid_dict()
    d["thermal_from_depth"]["rotation"][0][0] += 4e-7  # inside the 1e-6 tolerance
    Calibration.from_dict(d)


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("empty.yaml", "", "expected a mapping"),
        ("list.yaml", "- 1\n- 2\n", "expected a mapping"),
        ("broken.yaml", "depth: {width: 1280\n", "not valid YAML"),
        ("broken.json", '{"depth": ', "not valid JSON"),
        ("deep.json", "[" * 100_000 + "]" * 100_000, "nested too deeply to read"),
        ("twice.json", '{"depth": {}, "depth": {}}', "not valid JSON: key 'depth' given twice"),
        ("big.yaml", "depth: {width: " + "9" * 5000 + "}\n", "not valid YAML: Exceeds the limit"),
    ],
)
def test_malformed_files(tmp_path: Path, name: str, content: str, message: str) -> None:
    path = tmp_path / name
    path.write_text(content)
    with pytest.raises(InputError, match=message) as info:
        Calibration.load(path)
    assert str(info.value).startswith(str(path)) and "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("change", "sees"),
    [
        (lambda d: None, True),
        # turned 180 deg about y: the thermal camera looks backwards
        (
            lambda d: d["thermal_from_depth"].update(
                rotation=rotation_from_euler(0, np.pi, 0).tolist()
            ),
            False,
        ),
        (
            lambda d: d["thermal_from_depth"].update(translation_m=[40.0, 0.0, 0.0]),
            False,
        ),  # mm as m
        (lambda d: d["thermal"].update(distortion=[1e10, 1e10, 0, 0, 0]), False),
    ],
)
def test_cameras_that_share_no_view_are_refused(
    tmp_path: Path, change: Callable[[dict[str, Any]], None], sees: bool
) -> None:
    data = valid_dict()
    change(data)
    path = tmp_path / "c.json"
    path.write_text(json.dumps(data))
    view = Calibration.from_dict(data).shared_view
    assert list(view) == [0.5, 1.0, 2.0, 5.0]
    if sees:
        assert all(0.3 < f < 0.5 for f in view.values())  # a 57 deg camera beside an 89 deg one
        Calibration.load(path)
        return
    assert not any(view.values())
    with pytest.raises(InputError) as info:
        Calibration.load(path)
    assert str(info.value) == (
        f"{path}: the thermal camera sees none of the depth image at 0.5-5 m: check "
        "thermal_from_depth (its direction, the translation in metres) and the thermal distortion"
    )


def test_another_schema_version_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "c.json"
    path.write_text(json.dumps({**valid_dict(), "schema_version": 2}))
    with pytest.raises(InputError) as info:
        Calibration.load(path)
    assert str(info.value) == f"{path}: schema_version: Input should be 1 (got 2)"


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="cannot read"):
        Calibration.load(tmp_path / "nope.yaml")


def test_depth_unit_must_be_finite_and_positive() -> None:
    cal = Calibration.from_dict(valid_dict())
    for bad in (0.0, -0.001, float("inf"), float("nan")):
        with pytest.raises(ValueError, match="depth_scale_m must be a finite number > 0"):
            Calibration(cal.depth, cal.thermal, bad, cal.thermal_from_depth)
