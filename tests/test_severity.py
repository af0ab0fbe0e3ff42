"""Severity classes (thermodepth.severity): the NETA tables as published, their boundaries,
user tables in the settings, and the class carried by every ROI reading (pipeline,
measurements, MQTT, Modbus, OPC UA) and watched by alarm rules."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from thermodepth.alarms import AlarmRule, event_line
from thermodepth.errors import InputError
from thermodepth.io.measurements import FrameLines
from thermodepth.monitor.outputs.base import RigEntities
from thermodepth.monitor.outputs.modbus import NO_CLASS, priority_raw, register_map
from thermodepth.monitor.outputs.opcua import severity_values
from thermodepth.pipeline import AlarmSettings, Pipeline, RoiSettings, Settings
from thermodepth.severity import BUILT_IN, SeverityRow, check_table, classify
from thermodepth.sim import Rig, camera_pose, constant_fpa, plate_scene
from thermodepth.sinks.mqtt import measurement_message

SIMILAR, AMBIENT = BUILT_IN["neta-similar"], BUILT_IN["neta-ambient"]


@pytest.mark.parametrize(
    ("delta_t_c", "priority", "label"),
    [
        (0.99, None, "no deficiency"),
        (1.0, 4, "possible deficiency"),
        (3.0, 4, "possible deficiency"),
        (3.5, 3, "probable deficiency"),  # between the published 1-3 and 4-15: above 3
        (4.0, 3, "probable deficiency"),
        (15.0, 3, "probable deficiency"),
        (15.01, 1, "major discrepancy"),
        (80.0, 1, "major discrepancy"),
        (-12.0, None, "no deficiency"),
        (math.nan, None, "no reading"),
    ],
)
def test_neta_similar_as_published(delta_t_c: float, priority: int | None, label: str) -> None:
    assert classify(SIMILAR, delta_t_c) == (priority, label)


@pytest.mark.parametrize(
    ("delta_t_c", "priority"),
    [(0.5, None), (1.0, 4), (10.0, 4), (10.5, 3), (11.0, 3), (20.0, 3), (20.2, 2), (21.0, 2),
     (40.0, 2), (40.01, 1), (100.0, 1)],
)  # fmt: skip
def test_neta_ambient_as_published(delta_t_c: float, priority: int | None) -> None:
    assert classify(AMBIENT, delta_t_c)[0] == priority


def test_both_tables_are_valid_and_their_classes_never_grow_less_urgent() -> None:
    for rows in BUILT_IN.values():
        assert check_table(rows) is None
        deltas = np.linspace(-5, 60, 651)
        priorities = [classify(rows, float(d))[0] or 99 for d in deltas]
        assert all(a >= b for a, b in itertools.pairwise(priorities))


bounds = st.lists(
    st.floats(-50, 200, allow_nan=False).map(lambda x: round(x, 2)),
    min_size=1,
    max_size=6,
    unique=True,
)


@settings(max_examples=60, deadline=None)
@given(bounds, st.data())
def test_user_tables_in_rising_order_are_accepted(values: list[float], data: st.DataObject) -> None:
    values.sort()
    priorities = sorted(
        data.draw(st.lists(st.integers(1, 9), min_size=len(values), max_size=len(values))),
        reverse=True,
    )
    keys = data.draw(
        st.lists(st.sampled_from(["from_c", "above_c"]), min_size=len(values), max_size=len(values))
    )
    rows = [
        {k: v, "priority": p, "label": f"class {p}"}
        for k, v, p in zip(keys, values, priorities, strict=True)
    ]
    s = Settings(
        severity_criteria={"mine": rows},  # type: ignore[dict-item]
        rois=[RoiSettings(name="a", rect=(0, 0, 9, 9), severity={"criteria": "mine"})],  # type: ignore[arg-type]
    )
    table = s.severity_criteria["mine"]
    for row in table:
        bound, strict = row.bound
        assert classify(table, bound + 1e-6)[0] is not None
        assert (classify(table, bound)[0] is not None) != (strict and row is table[0])
    assert classify(table, values[0] - 1)[0] is None


@settings(max_examples=40, deadline=None)
@given(bounds.filter(lambda v: len(v) >= 2))
def test_a_table_out_of_order_is_refused_naming_its_row(values: list[float]) -> None:
    values = sorted(values, reverse=True)
    rows = [{"from_c": v, "priority": 1, "label": "x"} for v in values]
    with pytest.raises(ValueError, match=r"severity_criteria\.mine: row 1: its bound"):
        Settings(severity_criteria={"mine": rows})  # type: ignore[dict-item]


def test_severity_settings_are_checked_one_line_each(tmp_path: Path) -> None:
    roi = "rois: [{name: a, rect: [0, 0, 9, 9], severity: {criteria: %s}}]"
    table = "severity_criteria: {%s: [%s]}"
    row = "{from_c: 1, priority: 1, label: x}"
    cases = [
        (roi % "nope", "'a': severity.criteria: unknown 'nope'"),
        (roi % "neta-similar", "severity.relative_to: neta-similar compares"),
        (roi % "neta-ambient, relative_to: a", "'a' is not another ROI"),
        (table % ("neta-ambient", row), "severity_criteria.neta-ambient: a built-in"),
        (table % ("t", row.replace("}", ", above_c: 2}")), "give exactly one of from_c"),
        (table % ("t", row.replace("priority: 1", "priority: 0")), "priority"),
        (
            table % ("t", f"{row}, {{from_c: 2, priority: 5, label: y}}"),
            "row 1: priority 5 is less urgent",
        ),
        (
            "rois: [{name: a, rect: [0, 0, 9, 9]}]\n"
            "alarms: [{name: r, what: a, priority_at_most: 2}]",
            "priority_at_most watches an ROI with a severity",
        ),
    ]
    for i, (text, words) in enumerate(cases):
        path = tmp_path / f"s{i}.yaml"
        path.write_text(text + "\n", encoding="utf-8")
        with pytest.raises(InputError) as caught:
            Settings.load(path)
        line = str(caught.value)
        assert "\n" not in line and line.startswith(str(path)) and words in line, line


def test_a_priority_rule_is_raised_while_the_class_is_as_urgent() -> None:
    rule = AlarmRule("hot-joint", what="joint", priority_at_most=2)
    assert rule.condition() == "severity priority 2 or more urgent for 1 frame"
    assert [rule.met(p) for p in (1.0, 2.0, 3.0, math.nan)] == [True, True, False, False]
    assert [rule.gone(p) for p in (1.0, 3.0, math.nan)] == [False, True, True]
    with pytest.raises(ValueError, match="priority_at_most watches an ROI"):
        AlarmRule("h", priority_at_most=2)


def _rect(rig: Rig, centre: tuple[float, float], half_m: float) -> tuple[int, int, int, int]:
    x, y = centre
    corners = np.array([[x - half_m, y - half_m, 0.0], [x + half_m, y + half_m, 0.0]])
    uv = rig.calibration.depth.project(rig.depth_from_world.apply(corners))
    u0, v0, u1, v1 = (int(v) for v in np.rint(uv).ravel())
    return u0, v0, u1, v1


def test_every_reading_carries_its_class() -> None:
    # a 6 cm chip at 70 C on the 39 C plate, the air at 25 C: against the plate the chip is
    # some 31 C hotter (a major discrepancy), the plate some 14 C above the air (probable)
    rig = Rig(
        plate_scene(chip_temp_c=70.0, chip_size_m=0.06, chip_offset_m=(0.06, -0.05)),
        camera_pose(0.6),
        start_s=1.0,
        fpa=constant_fpa(308.15),
    )
    s = Settings(
        rois=[
            RoiSettings(
                name="chip",
                rect=_rect(rig, (0.06, -0.05), 0.02),
                severity={"criteria": "neta-similar", "relative_to": "plate"},  # type: ignore[arg-type]
            ),
            RoiSettings(
                name="plate",
                rect=_rect(rig, (-0.06, 0.06), 0.04),
                severity={"criteria": "neta-ambient"},  # type: ignore[arg-type]
            ),
            RoiSettings(name="plain", rect=_rect(rig, (-0.06, 0.06), 0.04)),
        ],
        alarms=[
            AlarmSettings(name="chip-p2", what="chip", priority_at_most=2),
            AlarmSettings(name="plate-p2", what="plate", priority_at_most=2),
        ],
    )
    fused = Pipeline(s, rig.calibration).process(rig.frame())
    rois = {r.name: r for r in fused.rois}
    chip, plate = rois["chip"].severity, rois["plate"].severity
    assert chip is not None and plate is not None and rois["plain"].severity is None
    assert chip["delta_t_c"] == pytest.approx(rois["chip"].max_c - rois["plate"].max_c, abs=1e-3)
    assert chip["delta_t_c"] == pytest.approx(31.0, abs=1.5)
    assert (chip["priority"], chip["label"], chip["relative_to"]) == (
        1,
        "major discrepancy",
        "plate",
    )
    assert plate["delta_t_c"] == pytest.approx(14.0, abs=1.0)
    assert (plate["priority"], plate["label"], plate["relative_to"]) == (
        3,
        "probable deficiency",
        "ambient",
    )
    raised = [e for e in fused.events if e["event"] == "alarm"]
    assert [e["rule"] for e in raised] == ["chip-p2"]
    assert raised[0]["priority"] == 1 and raised[0]["severity"] == chip
    assert "chip-p2 [alarm]: priority 1 (severity priority 2 or more urgent" in event_line(
        raised[0]
    )
    # the measurements' line, MQTT's message
    line = json.loads(FrameLines.of(fused).frame)
    assert line["rois"][0]["severity"] == chip and line["rois"][2]["severity"] is None
    assert json.loads(json.dumps(measurement_message(fused)))["rois"]["plate"]["severity"] == plate
    # Modbus: the priority register at offset 3 of each ROI's stride; OPC UA's nodes
    assert [priority_raw(r.severity) for r in fused.rois] == [1, 3, NO_CLASS]
    entities = RigEntities("rig", None, ["chip", "plate", "plain"], [])
    names = {g.name: g.address for g in register_map([entities], False)}
    assert [names[f"roi.{r}.priority"] for r in ("chip", "plate", "plain")] == [19, 29, 39]
    assert severity_values("rig.Rois.chip", chip) == {
        "rig.Rois.chip.Priority": 1.0,
        "rig.Rois.chip.Severity": "major discrepancy",
        "rig.Rois.chip.DeltaT": chip["delta_t_c"],
    }
    assert math.isnan(severity_values("rig.Rois.plain", None)["rig.Rois.plain.Priority"])


def test_below_the_first_row_the_priority_register_reads_zero() -> None:
    cls = {"criteria": "neta-similar", "relative_to": "b", "delta_t_c": 0.4, "priority": None,
           "label": "no deficiency"}  # fmt: skip
    assert priority_raw(cls) == 0
    assert priority_raw({**cls, "delta_t_c": None, "label": "no reading"}) == NO_CLASS
    assert severity_values("r", cls)["r.Priority"] == 0.0
    assert SeverityRow(above_c=3, priority=3, label="x").reached(3.01)
