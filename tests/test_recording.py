"""Recordings: bit-for-bit replay, crash safety (SIGKILL), corrupt chunks, bad input."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import zarr

from thermodepth.errors import InputError
from thermodepth.frames import DepthFrame, FfcState, FramePair, Telemetry, ThermalFrame
from thermodepth.io.recording import (
    Recorder,
    Recording,
    RecordingWarning,
    RecordingWriter,
)
from thermodepth.session import record_session
from thermodepth.sim import Rig, camera_pose, plate_scene
from thermodepth.sources import open_source
from thermodepth.sources.sim import SimSource


def sim_rig(with_ir: bool = False) -> Rig:
    # the default of `--source sim`: plate with a 70 C chip at 1 m, seed 0
    return Rig(plate_scene(chip_temp_c=70.0), camera_pose(1.0), with_ir=with_ir)


def same_telemetry(a: Telemetry, b: Telemetry) -> bool:
    fields = a.__dataclass_fields__
    for name in fields:
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y):
            continue
        if x != y or type(x) is not type(y):
            return False
    return True


def assert_same_pair(a: FramePair, b: FramePair) -> None:
    assert np.array_equal(a.depth, b.depth) and b.depth.dtype == np.uint16
    assert np.array_equal(a.thermal, b.thermal) and b.thermal.dtype == np.uint16
    assert a.depth_time_s == b.depth_time_s
    assert a.thermal_time_s == b.thermal_time_s
    assert a.index == b.index
    assert same_telemetry(a.telemetry, b.telemetry), (a.telemetry, b.telemetry)
    if a.ir is None:
        assert b.ir is None
    else:
        assert b.ir is not None and np.array_equal(a.ir, b.ir) and b.ir.dtype == np.uint8


def test_record_sim_and_replay_every_field(tmp_path: Path) -> None:
    out = tmp_path / "s.zarr"
    rig = sim_rig(with_ir=True)
    result = record_session(SimSource(rig), out, frames=6)
    assert result.stopped == "frames" and result.recorder.total_dropped == 0
    want = list(sim_rig(with_ir=True).frames(6))
    assert any(p.telemetry.in_ffc for p in want)  # the power-on FFC is in there, flagged
    src = open_source(f"recording:{out}")
    got = list(src)
    assert len(got) == 6
    for a, b in zip(want, got, strict=True):
        assert_same_pair(a, b)
    assert [p.telemetry.in_ffc for p in got] == [p.telemetry.in_ffc for p in want]
    rec = Recording(out)
    assert rec.complete and rec.n_pairs == rec.n_depth == rec.n_thermal == 6
    assert rec.calibration is not None
    assert rec.calibration.to_dict() == rig.calibration.to_dict()
    assert rec.settings["source"] == "sim"
    assert rec.attrs["counts"] == {"depth": 6, "thermal": 6, "pairs": 6}


def test_telemetry_none_nan_and_big_counters_round_trip(tmp_path: Path) -> None:
    t = Telemetry(
        frame_counter=2**32 - 1,
        fpa_temp_k=301.27,
        housing_temp_k=float("nan"),
        ffc_state=FfcState.NEVER_COMMANDED,
        time_since_ffc_s=None,
        ffc_desired=True,
        tlinear=True,
        tlinear_resolution_k=0.01,
    )
    pair = FramePair(np.ones((4, 6), np.uint16), np.full((2, 3), 8000, np.uint16), 1.5, 1.49, t, 7)
    with RecordingWriter(tmp_path / "t.zarr") as w:
        w.add_pair(pair)
    (got,) = list(Recording(tmp_path / "t.zarr").pairs())
    assert_same_pair(pair, got)


def test_raw_streams_and_pairs_as_references(tmp_path: Path) -> None:
    """A live source records every depth frame (30 fps), not just the paired ones."""
    tel = Telemetry(frame_counter=0, fpa_temp_k=300.0, housing_temp_k=299.0)
    depth = [DepthFrame(np.full((3, 4), i, np.uint16), i / 30, i) for i in range(10)]
    thermal = ThermalFrame(np.full((2, 2), 9, np.uint16), 4.1 / 30, 0, tel)
    from thermodepth.frames import Match, pair_of

    with RecordingWriter(tmp_path / "r.zarr") as w:
        for d in depth[:5]:
            w.add(d)
        w.add(thermal)
        w.add(Match(depth[4], thermal, pair_of(depth[4], thermal, 0)))
        for d in depth[5:]:
            w.add(d)
    rec = Recording(tmp_path / "r.zarr")
    assert (rec.n_depth, rec.n_thermal, rec.n_pairs) == (10, 1, 1)
    (p,) = list(rec.pairs())
    assert p.depth[0, 0] == 4 and p.depth_time_s == 4 / 30
    assert rec.depth_frame(9).time_s == 9 / 30


def test_corrupt_chunk_skips_that_frame_with_one_warning(tmp_path: Path) -> None:
    out = tmp_path / "c.zarr"
    record_session(SimSource(sim_rig()), out, frames=5)
    chunk = out / "depth" / "image" / "c" / "2" / "0" / "0"
    assert chunk.is_file()
    raw = bytearray(chunk.read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    chunk.write_bytes(bytes(raw))
    lines: list[str] = []
    src = open_source(f"recording:{out}", warn=lines.append)
    got = list(src)
    assert [p.index for p in got] == [0, 1, 3, 4]
    assert src.skipped == 1  # type: ignore[attr-defined]
    assert len(lines) == 1
    assert lines[0].startswith(f"{out}: pair 2 skipped: depth frame 2: unreadable chunk")
    assert "\n" not in lines[0]


def test_corrupt_chunk_default_warning_category(tmp_path: Path) -> None:
    out = tmp_path / "c.zarr"
    record_session(SimSource(sim_rig()), out, frames=2)
    (out / "thermal" / "image" / "c" / "1" / "0" / "0").write_bytes(b"not a chunk")
    with pytest.warns(RecordingWarning, match="pair 1 skipped: thermal frame 1"):
        assert [p.index for p in Recording(out).pairs()] == [0]


def test_missing_chunk_is_caught_by_the_checksum(tmp_path: Path) -> None:
    out = tmp_path / "m.zarr"
    record_session(SimSource(sim_rig()), out, frames=3)
    (out / "depth" / "image" / "c" / "1" / "0" / "0").unlink()  # reads back as zeros
    lines: list[str] = []
    rec = Recording(out, warn=lines.append)
    assert [p.index for p in rec.pairs()] == [0, 2]
    assert rec.skipped == 1
    assert lines == [f"{out}: pair 1 skipped: depth frame 1: pixels do not match their CRC-32"]


KILL_SCRIPT = """
import sys
from thermodepth.cli import main
sys.argv = ["thermodepth", "record", "--source", "sim", "-o", sys.argv[1], "--frames", "100000"]
main()
"""


def test_sigkill_mid_write_keeps_every_completed_frame(tmp_path: Path) -> None:
    out = tmp_path / "killed.zarr"
    proc = subprocess.Popen(
        [sys.executable, "-c", KILL_SCRIPT, str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 60
        n = 0
        while time.monotonic() < deadline:
            time.sleep(0.2)
            meta = out / "pairs" / "c"
            n = len(list(meta.iterdir())) if meta.is_dir() else 0
            if n >= 6:
                break
        assert n >= 6, "the recorder did not start writing"
        time.sleep(0.13)  # land somewhere inside a frame's writes
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(10)
    assert proc.returncode == -signal.SIGKILL
    rec = Recording(out)
    assert not rec.complete
    assert rec.n_pairs >= 5  # the 6th pair's folder may be there before its file
    assert rec.n_depth >= rec.n_pairs and rec.n_thermal >= rec.n_pairs
    got = list(rec.pairs())
    assert len(got) == rec.n_pairs and rec.skipped == 0
    want = list(sim_rig().frames(len(got)))
    assert_same_pair(want[-1], got[-1])  # the last completed frame, bit for bit
    assert_same_pair(want[0], got[0])


def test_recorder_drops_when_the_writer_cannot_keep_up(tmp_path: Path) -> None:
    class SlowWriter(RecordingWriter):
        def add(self, event: object) -> None:  # type: ignore[override]
            time.sleep(0.05)
            super().add(event)  # type: ignore[arg-type]

    rec = Recorder(SlowWriter(tmp_path / "d.zarr"), block=False, max_queue=2)
    tel = Telemetry(frame_counter=0, fpa_temp_k=300.0, housing_temp_k=299.0)
    from thermodepth.frames import Match, pair_of

    for i in range(20):
        d = DepthFrame(np.zeros((2, 2), np.uint16), i / 30, i)
        rec.add(d)
        if i % 3 == 0:
            t = ThermalFrame(np.zeros((2, 2), np.uint16), i / 30, i // 3, tel)
            rec.add(t)
            rec.add(Match(d, t, pair_of(d, t, i // 3)))
    stats = rec.close()
    assert stats.total_dropped > 0
    recording = Recording(tmp_path / "d.zarr")
    written = recording.n_depth + recording.n_thermal
    assert stats.depth_frames + stats.thermal_frames == written
    assert stats.dropped["depth"] + recording.n_depth == 20
    # every pair recorded refers to frames that were recorded
    assert len(list(recording.pairs())) == recording.n_pairs
    assert recording.attrs["recorder"]["dropped"] == stats.dropped


def test_keyboard_interrupt_closes_the_recording(tmp_path: Path) -> None:
    class Interrupted(SimSource):
        def events(self):  # type: ignore[no-untyped-def]
            for i, e in enumerate(super().events()):
                if i == 3:
                    raise KeyboardInterrupt
                yield e

    result = record_session(Interrupted(sim_rig()), tmp_path / "i.zarr")
    assert result.stopped == "interrupted"
    rec = Recording(tmp_path / "i.zarr")
    assert rec.complete and rec.n_pairs == 3


def test_duration_uses_source_time(tmp_path: Path) -> None:
    result = record_session(SimSource(sim_rig()), tmp_path / "d.zarr", duration_s=1.0)
    assert result.stopped == "duration"
    assert Recording(tmp_path / "d.zarr").n_pairs == 9  # thermal frames at 0 .. 8/8.7 s


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda p: None, "{p}: no such recording"),
        (lambda p: p.mkdir(), "{p}: not a readable Zarr v3 store"),
        (lambda p: zarr.open_group(str(p), mode="w"), "{p}: not a thermodepth recording"),
    ],
)
def test_not_a_recording(tmp_path: Path, make, message: str) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "x.zarr"
    make(p)
    with pytest.raises(InputError, match=message.format(p=p).replace(".", r"\.")):
        open_source(f"recording:{p}")


def test_writer_refuses_existing_path_and_mismatched_frames(tmp_path: Path) -> None:
    p = tmp_path / "w.zarr"
    p.mkdir()
    with pytest.raises(InputError, match="already exists"):
        RecordingWriter(p)
    w = RecordingWriter(p, overwrite=True)
    w.add_depth(DepthFrame(np.zeros((720, 1280), np.uint16), 0.0, 0))
    with pytest.raises(
        InputError, match="depth frame 1: 640x480 differs from the recording's 1280x720"
    ):
        w.add_depth(DepthFrame(np.zeros((480, 640), np.uint16), 0.1, 1))
    with pytest.raises(InputError, match=r"expected \(H, W\) uint16, got \(720, 1280\) float64"):
        w.add_depth(DepthFrame(np.zeros((720, 1280)), 0.1, 1))  # type: ignore[arg-type]
