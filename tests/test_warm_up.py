"""Pipeline.warm_up: after it, a rig's frames compile no kernel (a compile holds Python's lock
and would stall every rig of a monitor); the pipeline it warms keeps its state."""

from __future__ import annotations

import json
import subprocess
import sys

from thermodepth.alarms import RuleState
from thermodepth.pipeline import AlarmSettings, Pipeline, RoiSettings, Settings
from thermodepth.sources import open_source

# in a process of its own: this one's kernels may have been compiled by other tests already
PROBE = """
import json, sys
from numba.core.registry import CPUDispatcher
from thermodepth.pipeline import Pipeline, Settings
from thermodepth.sources import open_source

def signatures():
    return {f"{name}.{k}": len(v.signatures) for name, m in list(sys.modules.items())
            if name.startswith("thermodepth") for k, v in vars(m).items()
            if isinstance(v, CPUDispatcher) and v.__module__ == name}

settings = Settings.model_validate(json.loads(sys.argv[1]))
with open_source(sys.argv[2], frames=20) as source:
    pipe = Pipeline(settings, source.calibration)
    pairs = list(source)
pipe.warm_up()
warm = signatures()
for pair in pairs:
    pipe.process(pair).on_depth
after = signatures()
print(json.dumps({k: n for k, n in after.items() if n != warm.get(k, 0)}))
"""

SETTINGS = Settings(
    rois=[
        RoiSettings(name="plate", rect=(560, 280, 720, 440)),
        RoiSettings(name="shiny", rect=(0, 0, 1280, 100), emissivity=0.8),
        RoiSettings(name="near", depth_range_m=(0.5, 1.5)),
    ],
    alarms=[AlarmSettings(name="plate hot", what="plate", above_c=20.0)],
)


def compiled_after_warm_up(spec: str) -> dict[str, int]:
    """The kernels (and how many signatures) that a source's frames still compiled after
    the pipeline's warm-up, in a fresh process."""
    done = subprocess.run(
        [sys.executable, "-c", PROBE, SETTINGS.model_dump_json(), spec],
        capture_output=True,
        text=True,
        check=True,
    )
    return dict(json.loads(done.stdout.splitlines()[-1]))


def test_the_frames_of_a_rig_compile_nothing_after_the_warm_up() -> None:
    assert compiled_after_warm_up("sim") == {}  # raw counts
    assert compiled_after_warm_up("sim:thermal=lepton3.5") == {}  # TLinear kelvin


def test_the_warm_up_leaves_the_pipeline_as_it_was() -> None:
    lines: list[str] = []
    with open_source("sim", frames=20) as source:
        pipe = Pipeline(SETTINGS, source.calibration, warn=lines.append)
        pair = next(p for p in source if not p.telemetry.in_ffc)  # it starts with an FFC
    pipe.warm_up()  # its made-up wall at 30 C is above the rule's 20 C
    assert pipe.alarms.raised == [] and lines == []
    assert all(state == RuleState() for state in pipe.alarms.states.values())
    pipe.process(pair)  # the plate (39 C) raises it in the pipeline itself
    assert pipe.alarms.raised == ["plate hot"]
