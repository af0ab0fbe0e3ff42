"""The pictures of a rig, on their pixels: the monitor's live overlay (OpenCV) and an event's
evidence overlay (matplotlib): a hotspot's label beside its box, never under it; the ROI
that an alarm rule watches outlined in red and labelled while the rule is raised, in the
live overlay, in the event's snapshot, and in `run --snapshots`' picture of an alarm."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from thermodepth.alarms import AlarmRule, AlarmTracker
from thermodepth.figures import ALARM_RGB, alarm_rois, roi_outlines
from thermodepth.measure import DepthRangeRoi, RectRoi, RoiStats, hotspot_box_on_depth
from thermodepth.monitor.evidence import Evidence, PreTrigger
from thermodepth.monitor.live import ALARM_BGR, WHITE, LiveView, label_place, overlay_image
from thermodepth.pipeline import (
    AlarmSettings,
    FusedFrame,
    HotspotSettings,
    Pipeline,
    RoiSettings,
    Settings,
)
from thermodepth.sim import Rig, camera_pose, constant_fpa, plate_scene
from thermodepth.sinks.base import RunContext
from thermodepth.sinks.snapshots import SnapshotSink
from thermodepth.sources import open_source

PLATE = RoiSettings(name="plate", rect=(560, 280, 720, 440))
"""Around the simulated chip (its hotspot) at 1 m, on the 1280x720 depth image."""
BESIDE = RoiSettings(name="beside", rect=(300, 300, 400, 400))
NEAR = RoiSettings(name="near", depth_range_m=(0.9, 1.1))
ALARMS = [
    AlarmSettings(name="hot", above_c=60.0),  # the hotspot: no ROI
    AlarmSettings(name="plate-hot", what="plate", above_c=60.0),
    AlarmSettings(
        name="plate-vs", what="plate", delta_c=5.0, relative_to="beside", level="warning"
    ),
    AlarmSettings(name="near-hot", what="near", above_c=60.0),
    AlarmSettings(name="never", what="beside", above_c=500.0),
]


def fused_frame(
    rois: list[RoiSettings], alarms: list[AlarmSettings]
) -> tuple[Pipeline, FusedFrame]:
    """The simulated chip (70 C) on its plate at 1 m, fused: the pipeline and its frame."""
    rig = Rig(plate_scene(chip_temp_c=70.0), camera_pose(1.0), start_s=1.0,
              fpa=constant_fpa(35.0 + 273.15))  # fmt: skip
    settings = Settings(hotspots=HotspotSettings(threshold_c=50.0), rois=rois, alarms=alarms)
    pipe = Pipeline(settings, rig.calibration)
    return pipe, pipe.process(rig.frame())


@pytest.fixture(scope="module")
def scene() -> tuple[Pipeline, FusedFrame]:
    return fused_frame([PLATE, BESIDE, NEAR], ALARMS)


def colour_mask(img: NDArray[np.uint8], bgr: tuple[int, ...], tol: int = 0) -> NDArray[np.bool_]:
    return np.all(np.abs(img.astype(int) - np.asarray(bgr)) <= tol, axis=-1)


def overlaps(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> bool:
    """Two pixel rectangles (x0, y0, x1, y1), ends inside, share a pixel."""
    return a[0] <= b[2] and b[0] <= a[2] and a[1] <= b[3] and b[1] <= a[3]


def black_boxes(img: NDArray[np.uint8]) -> list[tuple[int, int, int, int]]:
    """The rectangles of pure black pieces of 50 pixels or more (the labels' boxes: the
    overlay's own pure black pixels are lone ones), each (x0, y0, x1, y1)."""
    n, _, stats, _ = cv2.connectedComponentsWithStats(colour_mask(img, (0, 0, 0)).astype(np.uint8))
    return [(x, y, x + w - 1, y + h - 1) for x, y, w, h, area in stats[1:n] if area >= 50]


# -- the hotspot's label ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("box", "where"),
    [
        (None, "above"),  # where the frame's hotspot is (the simulated chip at 1 m)
        ((600, 1, 630, 30), "below"),  # at the top edge
        ((1250, 300, 1270, 316), "above"),  # at the right edge: moved left
        ((20, 690, 50, 718), "above"),  # at the bottom edge
        ((600, 10, 630, 712), "right"),  # as tall as the image: no room above or below
        ((1230, 10, 1270, 712), "left"),  # ... and at the right edge
    ],
)
def test_the_hotspots_label_is_beside_its_box_never_under_it(
    scene: Any, monkeypatch: pytest.MonkeyPatch, box: Any, where: str
) -> None:
    import thermodepth.monitor.live as live

    _, frame = scene
    cal = frame.calibration
    hs = frame.hotspots[0]
    if box is None:
        box = hotspot_box_on_depth(
            hs, frame.z_thermal_m, cal.thermal, cal.depth, cal.thermal_from_depth
        )
    else:  # the same hotspot, drawn where its box would be elsewhere
        monkeypatch.setattr(live, "hotspot_box_on_depth", lambda *_: box)
    img = overlay_image(frame, (15.0, 80.0), [])
    u0, v0, u1, v1 = box
    color = (255, 255, 0) if hs.resolvable else (0, 255, 255)
    outer = (u0 - 3, v0 - 3, u1 + 3, v1 + 3)  # the box's line: 2 px wide, 2 px off its pixels
    # the box's line is whole: nothing drawn over it
    line = np.zeros(img.shape[:2], np.uint8)
    cv2.rectangle(line, (u0 - 2, v0 - 2), (u1 + 2, v1 + 2), 1, 2)
    assert colour_mask(img, color)[line.astype(bool)].all()
    # its label: one black box, whole in the image, with its text in the box's colour
    (label,) = black_boxes(img)
    x0, y0, x1, y1 = label
    assert 0 <= x0 and x1 < img.shape[1] and 0 <= y0 and y1 < img.shape[0]
    assert colour_mask(img[y0 : y1 + 1, x0 : x1 + 1], color).sum() > 50
    # beside the box, not touching its line (3 px clear: still clear at half size)
    assert not overlaps(label, (outer[0] - 2, outer[1] - 2, outer[2] + 2, outer[3] + 2))
    if where == "above":
        assert outer[1] - 8 <= y1 < outer[1]
    elif where == "below":
        assert outer[3] < y0 <= outer[3] + 8
    elif where == "right":
        assert outer[2] < x0 <= outer[2] + 8
    else:
        assert outer[0] - 8 <= x1 < outer[0]
    if where in ("above", "below"):  # from the box's left edge, moved left to stay whole
        assert x0 == min(outer[0], img.shape[1] - (x1 - x0 + 1))


def test_label_place_over_the_box_only_where_nothing_else_has_room() -> None:
    assert label_place((10, 0, 180, 99), (30, 12), (100, 200)) == (10, 0)


# -- an alarm's ROI -----------------------------------------------------------------------------


def test_alarm_rois_are_the_subject_and_the_reference_of_the_raised_rules(scene: Any) -> None:
    pipe, _ = scene
    rules = pipe.alarms.rules
    assert alarm_rois(rules, {"hot"}) == {}
    assert alarm_rois(rules, {"plate-hot"}) == {"plate": "alarm"}
    assert alarm_rois(rules, {"plate-vs", "near-hot"}) == {
        "plate": "warning", "beside": "warning", "near": "alarm"}  # fmt: skip
    assert alarm_rois(rules, {"plate-vs", "plate-hot"})["plate"] == "alarm"  # the higher
    assert alarm_rois(rules, set()) == {}


def test_the_live_overlay_outlines_a_raised_rules_roi_in_red(scene: Any) -> None:
    pipe, frame = scene
    rois = pipe.rois
    (plate,) = [r for r in rois if r.name == "plate"]
    assert isinstance(plate, RectRoi)
    # the rules raised by this frame: every one but "never"
    assert set(pipe.alarms.raised) == {"hot", "plate-hot", "plate-vs", "near-hot"}
    live = LiveView(rois, (15.0, 80.0))
    live.wanted()
    live.fused(frame, pipe.alarms)
    assert live.marked == {"plate": "alarm", "beside": "warning", "near": "alarm"}
    picture = live.picture("overlay")
    assert picture is not None
    shown = np.asarray(cv2.imdecode(np.frombuffer(picture.data, np.uint8), cv2.IMREAD_COLOR))
    drawn = overlay_image(frame, (15.0, 80.0), rois, live.marked)
    red = colour_mask(drawn, ALARM_BGR)
    # the plate's outline, 3 px wide: red along its left edge (below its label) ...
    assert red[plate.v0 + 30 : plate.v1 - 1, plate.u0].all()
    # ... and so in the JPEG the screens get (near enough: JPEG)
    assert colour_mask(shown, ALARM_BGR, 60)[plate.v0 + 30 : plate.v1 - 1, plate.u0].mean() > 0.9
    # labelled: a red box with white text at its top left corner
    corner = drawn[plate.v0 + 2 : plate.v0 + 18, plate.u0 + 2 : plate.u0 + 60]
    assert colour_mask(corner, ALARM_BGR).mean() > 0.4 and colour_mask(corner, WHITE).sum() > 30
    # a depth range in alarm: its pixels' outline (the plate at 1 m), red
    (near,) = [r for r in rois if r.name == "near"]
    outline = roi_outlines(near, frame.depth_m)
    assert outline and all(red[v, u] for pts in outline for u, v in pts[::7])
    # none raised: white, thin, no red anywhere; no depth range outlined
    calm = overlay_image(frame, (15.0, 80.0), rois)
    assert not colour_mask(calm, ALARM_BGR).any()
    assert colour_mask(calm, WHITE)[plate.v0 + 30 : plate.v1 - 1, plate.u0].all()
    assert not colour_mask(calm, WHITE)[plate.v0 + 30 : plate.v1 - 1, plate.u0 + 1].all()


def test_the_live_overlay_forgets_a_latched_rule_once_acknowledged(scene: Any) -> None:
    _, frame = scene
    tracker = AlarmTracker([AlarmRule("plate-latched", above_c=60.0, what="plate", latch=True)])
    live = LiveView([PLATE.roi()], (15.0, 80.0))
    live.wanted()

    def shown(plate_max_c: float) -> dict[str, str]:
        tracker.update(frame.thermal_time_s, frame.index, [],
                       [RoiStats("plate", 100, 40.0, plate_max_c, 30.0, 1.0)])  # fmt: skip
        live.last_s = 0.0  # the next frame is kept, however soon
        live.fused(frame, tracker)
        return live.marked

    assert shown(50.0) == {}
    assert shown(70.0) == {"plate": "alarm"}
    assert shown(50.0) == {"plate": "alarm"}  # back, but latched: raised until acknowledged
    events = tracker.acknowledge("plate-latched", "jane")
    assert [e["event"] for e in events] == ["acknowledged", "clear"]  # not a frame's events
    assert shown(50.0) == {}


# -- an event's evidence ----------------------------------------------------------------------


def red_pixels(png: Path) -> NDArray[np.bool_]:
    rgb = np.asarray(cv2.imread(str(png)))[..., ::-1]
    want = np.round(np.asarray(ALARM_RGB) * 255)
    return np.all(np.abs(rgb.astype(int) - want) <= 12, axis=-1)


@pytest.mark.parametrize(("rule", "red"), [("plate-hot", True), ("hot", False)])
def test_an_roi_alarms_snapshot_outlines_its_roi(
    scene: Any, tmp_path: Path, rule: str, red: bool
) -> None:
    pipe, frame = scene
    lines: list[str] = []
    evidence = Evidence(tmp_path, 0.0, 1.0, 10.0, lines.append)
    evidence.painter.start()  # a worker the monitor starts with the others
    with open_source("sim") as source:
        context = RunContext(source, pipe.calibration, pipe)
        event = {"event": "alarm", "rule": rule}
        clip, new = evidence.trigger("a", event, frame.thermal_time_s, context, PreTrigger(0, 0))
        assert new
        evidence.draw(frame, clip, event, (15.0, 80.0))
        evidence.close()
    assert not lines
    found = red_pixels(clip.folder / "overlay.png")
    if not red:  # a hotspot's rule: every ROI in white, none in red
        assert not found.any()
        return
    v, u = np.nonzero(found)
    assert found.sum() > 500  # the outline and its label
    # the plate's square (160 x 160 depth pixels) drawn at the figure's scale
    assert abs((u.max() - u.min()) / (v.max() - v.min()) - 1) < 0.1


def test_a_depth_range_outline_leaves_out_specks() -> None:
    depth = np.full((100, 100), 3.0, np.float32)
    depth[20:60, 30:80] = 1.0  # a plate
    depth[90:92, 5:7] = 1.0  # 4 pixels of noise
    (outline,) = roi_outlines(DepthRangeRoi("near", 0.5, 1.5), depth)
    assert outline[:, 0].min() == 30 and outline[:, 0].max() == 79
    assert outline[:, 1].min() == 20 and outline[:, 1].max() == 59


def test_runs_alarm_snapshot_outlines_the_roi_of_the_rule_raised(
    scene: Any, tmp_path: Path
) -> None:
    pipe, frame = scene
    sink = SnapshotSink(tmp_path, every=1, range_c=(15.0, 80.0))
    with open_source("sim") as source:
        sink.open(RunContext(source, pipe.calibration, pipe))
    assert {e["rule"] for e in frame.events} >= {"plate-hot", "near-hot"}  # raised here
    sink.frame(frame)
    (png,) = (tmp_path / "snapshots").glob("*.png")
    assert red_pixels(png).sum() > 500
    # a frame that raised nothing (written: every=1): its ROIs in white only
    sink.frame(replace(frame, index=frame.index + 1000, events=[]))
    calm = tmp_path / "snapshots" / f"frame_{frame.index + 1000:06d}.png"
    assert not red_pixels(calm).any()
