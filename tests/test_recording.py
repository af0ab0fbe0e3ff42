"""Recordings: bit-for-bit replay, crash safety (SIGKILL), corrupt chunks, bad input."""

from __future__ import annotations

import json
import math
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import google_crc32c
import numpy as np
import pytest
import zarr
from numcodecs import Blosc
from zarr.codecs import ZstdCodec

from thermodepth.errors import FieldError, InputError
from thermodepth.frames import (
    DepthFrame,
    FfcState,
    FramePair,
    Match,
    StreamEvent,
    Telemetry,
    ThermalFrame,
    pair_of,
)
from thermodepth.io.recording import (
    CODECS,
    TABLE_CHUNK_ROWS,
    CorruptFrameError,
    Recorder,
    Recording,
    RecordingWarning,
    RecordingWriter,
    checksum,
)
from thermodepth.io.recording.chunks import ChunkError, FrameChunks
from thermodepth.io.recording.reader import READ_AHEAD
from thermodepth.radiometry import ThermalOutput
from thermodepth.session import record_session
from thermodepth.sim import Rig, camera_pose, plate_scene
from thermodepth.sources import open_source
from thermodepth.sources.pairing import StreamPairer
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


def test_replay_says_that_its_own_calibration_beats_the_one_given(tmp_path: Path) -> None:
    out = tmp_path / "s.zarr"
    rig = sim_rig()
    record_session(SimSource(rig), out, frames=1)
    lines: list[str] = []
    mine = replace(rig.calibration, depth_scale_m=0.0005)
    src = open_source(f"recording:{out}", mine, warn=lines.append)
    assert lines == [
        f"recording:{out}: the recording keeps its own calibration; the one given is not used"
    ]
    assert src.calibration is not None and src.calibration.depth_scale_m == 0.001
    src.close()


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


def live_events(n_depth: int) -> list[StreamEvent]:
    """What a live rig emits: depth at 30 fps, thermal at 8.7 fps, pairs as they form."""
    pairer = StreamPairer()
    events: list[StreamEvent] = []
    frames: list[DepthFrame | ThermalFrame] = [
        DepthFrame(np.full((3, 4), i, np.uint16), i / 30, i) for i in range(n_depth)
    ]
    frames += [
        ThermalFrame(np.full((2, 2), k, np.uint16), k / 8.7, k, Telemetry(k, 300.0, 299.0))
        for k in range(int(n_depth / 30 * 8.7))
    ]
    for f in sorted(frames, key=lambda f: f.time_s):
        events.append(f)
        events += pairer.add_depth(f) if isinstance(f, DepthFrame) else pairer.add_thermal(f)
    return events + pairer.flush()


@pytest.mark.parametrize("via", ["writer", "recorder"])
def test_paired_depth_keeps_only_the_depth_frames_that_pair(tmp_path: Path, via: str) -> None:
    events = live_events(60)
    recs = {}
    for mode in ("all", "paired"):
        w = RecordingWriter(tmp_path / f"{mode}.zarr", depth_frames=mode)
        if via == "writer":
            with w:
                for e in events:
                    w.add(e)
        else:
            with Recorder(w, block=True) as r:
                for e in events:
                    r.add(e)
        recs[mode] = Recording(tmp_path / f"{mode}.zarr")
    every, paired = recs["all"], recs["paired"]
    assert (every.depth_frames, paired.depth_frames) == ("all", "paired")
    assert every.n_depth == 60 and every.n_pairs == paired.n_pairs == 17
    assert paired.n_depth == paired.n_pairs  # one depth frame per pair, no more
    for a, b in zip(every.pairs(), paired.pairs(), strict=True):
        assert_same_pair(a, b)


def test_either_codec_replays_bit_for_bit_and_reads_from_the_chunk_files(tmp_path: Path) -> None:
    recs = {}
    for codec in CODECS:
        record_session(SimSource(sim_rig(with_ir=True)), tmp_path / codec, frames=3, codec=codec)
        recs[codec] = Recording(tmp_path / codec)
        array = recs[codec]._arrays["depth/image"]
        blosc = array.metadata.codecs[1]
        assert (blosc.cname, blosc.clevel, blosc.shuffle) == (
            CODECS[codec].cname,
            CODECS[codec].clevel,
            CODECS[codec].shuffle,
        )
        assert FrameChunks(array).direct
    for a, b in zip(recs["lz4"].pairs(), recs["zstd"].pairs(), strict=True):
        assert_same_pair(a, b)
        assert a.ir is not None
    with pytest.raises(FieldError, match=r"^codec: expected one of lz4, zstd$"):
        RecordingWriter(tmp_path / "x.zarr", codec="gzip")


def test_paired_depth_needs_both_cameras(tmp_path: Path) -> None:
    depth_only(tmp_path / "d.zarr", 3)
    src = open_source(f"recording:{tmp_path / 'd.zarr'}")
    with pytest.raises(InputError, match="gives depth only; FramePairs need"):
        record_session(src, tmp_path / "p.zarr", depth_frames="paired")
    with pytest.raises(FieldError, match=r"^depth_frames: expected one of all, paired$"):
        RecordingWriter(tmp_path / "x.zarr", depth_frames="some")


def test_replay_reads_ahead_in_batches_bit_for_bit(tmp_path: Path) -> None:
    # more pairs than a batch, one corrupt chunk inside the second: only its pair is lost
    out = tmp_path / "b.zarr"
    n = 2 * READ_AHEAD + 3
    record_session(SimSource(sim_rig()), out, frames=n)
    one_by_one = [Recording(out).depth_frame(i).depth for i in range(n)]
    chunk = out / "depth" / "image" / "c" / str(READ_AHEAD + 2) / "0" / "0"
    chunk.write_bytes(b"torn")
    lines: list[str] = []
    got = list(Recording(out, warn=lines.append).pairs())
    assert [p.index for p in got] == [i for i in range(n) if i != READ_AHEAD + 2]
    for p in got:
        assert np.array_equal(p.depth, one_by_one[p.index])
    assert len(lines) == 1 and f"pair {READ_AHEAD + 2} skipped" in lines[0]
    first = next(iter(Recording(out).pairs()))  # stopping early leaves no thread behind
    assert first.index == 0
    assert not [t for t in threading.enumerate() if t.name.startswith("replay-read")]


def depth_only(path: Path, n: int) -> list[DepthFrame]:
    """A recording of ``n`` small depth frames at 30 fps and no thermal camera."""
    depth = [DepthFrame(np.full((3, 4), i, np.uint16), i / 30, i) for i in range(n)]
    with RecordingWriter(path) as w:
        for d in depth:
            w.add(d)
    return depth


def test_a_recording_of_one_camera_replays_its_frames(tmp_path: Path) -> None:
    depth = depth_only(tmp_path / "d.zarr", 5)
    src = open_source(f"recording:{tmp_path / 'd.zarr'}")
    assert src.streams == {"depth"}
    result = record_session(src, tmp_path / "again.zarr")
    again = Recording(tmp_path / "again.zarr")
    assert result.stopped == "end" and (again.n_depth, again.n_thermal, again.n_pairs) == (5, 0, 0)
    for i, d in enumerate(depth):
        got = again.depth_frame(i)
        assert np.array_equal(got.depth, d.depth) and (got.time_s, got.index) == (d.time_s, i)


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
    assert lines == [f"{out}: pair 1 skipped: depth frame 1: pixels do not match their CRC-32C"]


KILL_SCRIPT = """
import os, signal, sys
import zarr
from thermodepth.io.recording import format, writer
from thermodepth.cli import main

out, where, at = sys.argv[1], sys.argv[2], int(sys.argv[3])
format.FIRST_CAPACITY = 4  # arrays grow at rows 4, 8, 16, ...


def kill():
    os.kill(os.getpid(), signal.SIGKILL)


write, resize = writer._TableWriter.write, zarr.Array.resize


def write_hook(self, row, values):
    if self.array.path == where and row == at:
        kill()  # depth/meta: frame `at`'s image is on disk, its meta row not; pairs: both frames
    write(self, row, values)


def resize_hook(self, shape):
    if where == "resize" and self.path == "depth/meta" and shape[0] > at:
        kill()  # mid-growth: depth/image already grown past `at`, depth/meta not
    resize(self, shape)


writer._TableWriter.write = write_hook
zarr.Array.resize = resize_hook
sys.argv = ["thermodepth", "record", "--source", "sim", "-o", out, "--frames", "100"]
main()
"""


def killed_recording(tmp_path: Path, where: str, at: int) -> Path:
    """Record the simulator in a subprocess that SIGKILLs itself at a chosen point."""
    out = tmp_path / f"killed-{where.replace('/', '-')}.zarr"
    proc = subprocess.run(
        [sys.executable, "-c", KILL_SCRIPT, str(out), where, str(at)],
        capture_output=True,
        timeout=300,
        check=False,
    )
    assert proc.returncode == -signal.SIGKILL, proc.stderr.decode()
    return out


def array_length(store: Path, name: str) -> int:
    return int(json.loads((store / name / "zarr.json").read_text())["shape"][0])


@pytest.mark.parametrize(
    ("where", "at", "frames", "pairs"),
    [
        ("depth/meta", 5, (5, 5), 5),  # after frame 5's image chunk, before its meta row
        ("pairs", 5, (6, 6), 5),  # after both frames of pair 5, before the pair row
        ("resize", 8, (8, 8), 8),  # growing to 16 rows: image arrays grown, meta not yet
    ],
)
def test_sigkill_at_each_write_step_keeps_every_completed_frame(
    tmp_path: Path, where: str, at: int, frames: tuple[int, int], pairs: int
) -> None:
    out = killed_recording(tmp_path, where, at)
    if where == "depth/meta":  # the orphan image chunk is there: the kill came after it
        assert (out / "depth" / "image" / "c" / str(at) / "0" / "0").is_file()
    if where == "resize":  # killed between the two resizes
        assert array_length(out, "depth/image") == 16 and array_length(out, "depth/meta") == 8
    rec = Recording(out)
    assert not rec.complete
    assert (rec.n_depth, rec.n_thermal) == frames
    assert rec.n_pairs == pairs
    got = list(rec.pairs())
    assert len(got) == pairs and rec.skipped == 0
    want = list(sim_rig().frames(pairs))
    for a, b in zip(want, got, strict=True):
        assert_same_pair(a, b)  # every completed pair, bit for bit


def test_recorder_drops_when_the_writer_cannot_keep_up(tmp_path: Path) -> None:
    class SlowWriter(RecordingWriter):
        def add(self, event: object) -> None:  # type: ignore[override]
            time.sleep(0.05)
            super().add(event)  # type: ignore[arg-type]

    rec = Recorder(SlowWriter(tmp_path / "d.zarr"), block=False, max_queue=2)
    tel = Telemetry(frame_counter=0, fpa_temp_k=300.0, housing_temp_k=299.0)
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


def test_a_source_that_fails_to_close_still_leaves_a_closed_recording(tmp_path: Path) -> None:
    class StuckOnClose(SimSource):  # e.g. a second Ctrl-C while the cameras' threads stop
        def close(self) -> None:
            super().close()
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        record_session(StuckOnClose(sim_rig()), tmp_path / "c.zarr", frames=3)
    rec = Recording(tmp_path / "c.zarr")
    assert rec.complete and rec.n_pairs == 3 and rec.attrs["stopped"] == "frames"


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


def as_version_1(path: Path) -> None:
    """Rewrite a recording as version 1 wrote it: zlib's CRC-32 of the pixels."""
    root = zarr.open_group(str(path), mode="r+")
    for stream in ("depth", "thermal"):
        meta, image = root[f"{stream}/meta"], root[f"{stream}/image"]
        rows = np.asarray(meta[:])
        for row in range(len(rows)):
            if not np.isnan(rows[row, 0]):
                rows[row, 2] = checksum(np.asarray(image[row]), version=1)
        meta[:] = rows
    root.attrs["version"] = 1


def test_version_1_recordings_replay_and_other_versions_are_refused(tmp_path: Path) -> None:
    out = tmp_path / "v.zarr"
    record_session(SimSource(sim_rig()), out, frames=3)
    now = [(p.depth, p.thermal) for p in Recording(out).pairs()]
    as_version_1(out)
    lines: list[str] = []
    old = [(p.depth, p.thermal) for p in Recording(out, warn=lines.append).pairs()]
    assert not lines and len(old) == len(now) == 3
    for (d0, t0), (d1, t1) in zip(now, old, strict=True):
        assert np.array_equal(d0, d1) and np.array_equal(t0, t1)
    # version 1 checks zlib's CRC-32: a CRC-32C there fails it
    root = zarr.open_group(str(out), mode="r+")
    meta = np.asarray(root["thermal/meta"][:])
    meta[1, 2] = checksum(np.asarray(root["thermal/image"][1]), version=2)
    root["thermal/meta"][:] = meta
    list(Recording(out, warn=lines.append).pairs())
    assert lines == [f"{out}: pair 1 skipped: thermal frame 1: pixels do not match their CRC-32"]
    root.attrs["version"] = 3
    refused = r"recording version 3 is not supported \(.* reads versions 1, 2\)"
    with pytest.raises(InputError, match=refused):
        Recording(out)


def test_the_thermal_output_is_recorded_and_old_recordings_read_as_counts(tmp_path: Path) -> None:
    out = tmp_path / "boson.zarr"
    src = SimSource(thermal="boson640", depth="848x480")  # TLinear that only the file says
    record_session(src, out, frames=2)
    assert Recording(out).calibration.thermal_output == ThermalOutput.kelvin_per(0.01)
    root = zarr.open_group(str(out), mode="r+")
    calibration = dict(root.attrs["calibration"])
    calibration["thermal"] = {k: v for k, v in calibration["thermal"].items() if k != "output"}
    root.attrs["calibration"] = calibration  # as recordings made before thermal.output
    assert Recording(out).calibration.thermal_output == ThermalOutput()


def test_frames_are_read_from_their_chunk_files_as_zarr_reads_them(tmp_path: Path) -> None:
    out = tmp_path / "c.zarr"
    record_session(SimSource(sim_rig(with_ir=True)), out, frames=3)
    root = zarr.open_group(str(out), mode="r")
    for name in ("depth/image", "depth/ir", "thermal/image"):
        chunks = FrameChunks(root[name])
        assert chunks.direct, name
        assert np.array_equal(chunks.rows(0, 2), root[name][0:3])
    chunks = FrameChunks(root["depth/image"])
    path = out / "depth" / "image" / "c" / "1" / "0" / "0"
    data = bytearray(path.read_bytes())
    # a chunk of a smaller frame, whole and with its own CRC-32C: the wrong size
    small = Blosc(cname="zstd", clevel=1, shuffle=Blosc.SHUFFLE).encode(np.ones((4, 4), np.uint16))
    crc = google_crc32c.value(small).to_bytes(4, "little")
    for damage, message in (
        (data[:100] + bytes([data[100] ^ 1]) + data[101:], "does not match its CRC-32C"),
        (data[:10], "10 bytes, too short for a chunk"),
        (small + crc, f"the chunk holds 32 bytes, a frame {1280 * 720 * 2}"),
    ):
        path.write_bytes(bytes(damage))
        with pytest.raises(ChunkError, match=message):
            chunks.rows(1, 1)
    path.unlink()  # absent: the fill value, as zarr reads it (the frame's checksum fails)
    assert not chunks.rows(0, 2)[1].any() and chunks.rows(0, 2)[0].any()
    # an array with other codecs is read through zarr
    other = zarr.create_array(str(tmp_path / "z.zarr"), shape=(2, 3, 4), chunks=(1, 3, 4),
                              dtype=np.uint16, compressors=[ZstdCodec()])  # fmt: skip
    other[:] = np.arange(24, dtype=np.uint16).reshape(2, 3, 4)
    assert not FrameChunks(other).direct
    assert np.array_equal(FrameChunks(other).rows(0, 1), other[:])


def test_writer_refuses_mismatched_frames(tmp_path: Path) -> None:
    w = RecordingWriter(tmp_path / "w.zarr")
    w.add_depth(DepthFrame(np.zeros((720, 1280), np.uint16), 0.0, 0))
    with pytest.raises(
        InputError, match="depth frame 1: 640x480 differs from the recording's 1280x720"
    ):
        w.add_depth(DepthFrame(np.zeros((480, 640), np.uint16), 0.1, 1))
    with pytest.raises(InputError, match=r"expected \(H, W\) uint16, got \(720, 1280\) float64"):
        w.add_depth(DepthFrame(np.zeros((720, 1280)), 0.1, 1))  # type: ignore[arg-type]


# -- overwriting ------------------------------------------------------------------------------


def test_existing_output_is_refused_without_overwrite(tmp_path: Path) -> None:
    p = tmp_path / "w.zarr"
    p.mkdir()
    with pytest.raises(InputError, match=re.escape(f"{p}: already exists (choose another")):
        RecordingWriter(p)


@pytest.mark.parametrize("kind", ["directory", "file", "zarr group"])
def test_overwrite_never_deletes_what_is_not_a_recording(tmp_path: Path, kind: str) -> None:
    p = tmp_path / "data"
    if kind == "directory":  # `record -o ~/data --overwrite`
        p.mkdir()
        (p / "thesis.tex").write_text("years of work")
    elif kind == "file":
        p.write_text("years of work")
    else:  # a Zarr store of someone else's
        zarr.open_group(str(p), mode="w").attrs["format"] = "not-ours"
    before = sorted(str(f.relative_to(tmp_path)) for f in tmp_path.rglob("*"))
    with pytest.raises(InputError) as info:
        RecordingWriter(p, overwrite=True)
    assert str(info.value) == (
        f"{p}: not a thermodepth recording; --overwrite replaces recordings only "
        "(nothing was deleted)"
    )
    assert sorted(str(f.relative_to(tmp_path)) for f in tmp_path.rglob("*")) == before


def test_overwrite_replaces_a_recording(tmp_path: Path) -> None:
    p = tmp_path / "r.zarr"
    record_session(SimSource(sim_rig()), p, frames=2)
    record_session(SimSource(sim_rig()), p, frames=1, overwrite=True)
    assert Recording(p).n_pairs == 1


@pytest.mark.parametrize("out", ["{src}", "{src}/inside.zarr", "{tmp}"])
def test_recording_over_its_own_source_is_refused(tmp_path: Path, out: str) -> None:
    src = tmp_path / "a.zarr"
    record_session(SimSource(sim_rig()), src, frames=2)
    target = Path(out.format(src=src, tmp=tmp_path))
    with pytest.raises(InputError, match=re.escape(f"{target}: the source reads {src}")):
        record_session(open_source(f"recording:{src}"), target, overwrite=True)
    rec = Recording(src)
    assert rec.complete and rec.n_pairs == 2 and len(list(rec.pairs())) == 2  # untouched


# -- damaged stores ---------------------------------------------------------------------------


def test_corrupt_array_metadata_is_one_line(tmp_path: Path) -> None:
    out = tmp_path / "j.zarr"
    record_session(SimSource(sim_rig()), out, frames=1)
    (out / "depth" / "meta" / "zarr.json").write_text("garbage{")
    with pytest.raises(InputError) as info:
        open_source(f"recording:{out}")
    message = str(info.value)
    assert message.startswith(f"{out}: depth/meta/zarr.json is unreadable (JSONDecodeError: ")
    assert "\n" not in message


def small_recording(path: Path, n: int) -> None:
    """n pairs of tiny frames, numbered by their pixels (fast: no simulator)."""
    tel = Telemetry(frame_counter=0, fpa_temp_k=300.0, housing_temp_k=float("nan"))
    with RecordingWriter(path) as w:
        for i in range(n):
            d = DepthFrame(np.full((2, 3), i, np.uint16), i / 30, i)
            t = ThermalFrame(np.full((2, 2), i, np.uint16), i / 30, i, tel)
            w.add(Match(d, t, pair_of(d, t, i)))


@pytest.fixture(scope="module")
def two_chunks(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A recording whose tables span two chunks (300 pairs); copy it before changing it."""
    out = tmp_path_factory.mktemp("chunks") / "t.zarr"
    small_recording(out, TABLE_CHUNK_ROWS + 44)
    return out


def test_tables_are_chunked_so_a_recording_opens_from_few_files(two_chunks: Path) -> None:
    out = two_chunks
    for table in ("depth/meta", "thermal/meta", "pairs"):
        chunks = sorted(p.parent.name for p in (out / table / "c").rglob("0") if p.is_file())
        assert chunks == ["0", "1"], table  # 300 rows in two files, not 300
    rec = Recording(out)
    assert (rec.n_depth, rec.n_thermal, rec.n_pairs) == (300, 300, 300)
    assert [int(p.depth[0, 0]) for p in rec.pairs()] == list(range(300))


def test_corrupt_meta_chunk_is_unreadable_not_missing_one_warning(
    tmp_path: Path, two_chunks: Path
) -> None:
    out = tmp_path / "m.zarr"
    shutil.copytree(two_chunks, out)
    chunk = out / "thermal" / "meta" / "c" / "0" / "0"  # rows 0-255
    raw = bytearray(chunk.read_bytes())
    raw[100] ^= 0xFF
    chunk.write_bytes(bytes(raw))
    lines: list[str] = []
    src = open_source(f"recording:{out}", warn=lines.append)
    got = list(src)
    assert [p.index for p in got] == list(range(256, 300))
    assert src.counters() == {"replay_skipped": 256}
    assert lines == [
        f"{out}: thermal/meta rows 0-255 unreadable (corrupt chunk): the frames and pairs "
        "there are skipped"
    ]
    with pytest.raises(CorruptFrameError, match=r"^thermal frame 3: meta row unreadable"):
        Recording(out, warn=lines.append).thermal_frame(3)


def test_the_last_meta_chunk_gone_is_one_line_for_all_its_pairs(
    tmp_path: Path, two_chunks: Path
) -> None:
    out = tmp_path / "m.zarr"
    shutil.copytree(two_chunks, out)
    (out / "depth" / "meta" / "c" / "1" / "0").unlink()  # rows 256-299: the table now ends at 255
    lines: list[str] = []
    src = open_source(f"recording:{out}", warn=lines.append)
    assert [p.index for p in src] == list(range(256))
    assert src.counters() == {"replay_skipped": 44}
    assert lines == [
        f"{out}: pairs 256-299 skipped: depth frame 256: meta row missing (and alike for the "
        "43 after)"
    ]


def test_skips_of_different_causes_or_apart_are_told_apart(tmp_path: Path) -> None:
    out = tmp_path / "s.zarr"
    small_recording(out, 6)
    for stream, row in (("depth", 1), ("depth", 2), ("thermal", 3), ("depth", 5)):
        (out / stream / "image" / "c" / str(row) / "0" / "0").unlink()  # zeros: bad CRC
    lines: list[str] = []
    assert [p.index for p in Recording(out, warn=lines.append).pairs()] == [0, 4]
    assert lines == [
        f"{out}: pairs 1-2 skipped: depth frame 1: pixels do not match their CRC-32C (and alike "
        "for the 1 after)",
        f"{out}: pair 3 skipped: thermal frame 3: pixels do not match their CRC-32C",
        f"{out}: pair 5 skipped: depth frame 5: pixels do not match their CRC-32C",
    ]


def test_an_image_array_without_metadata_is_one_line(tmp_path: Path) -> None:
    out = tmp_path / "j.zarr"
    small_recording(out, 3)
    (out / "thermal" / "image" / "zarr.json").unlink()
    with pytest.raises(InputError) as info:
        Recording(out)
    assert str(info.value) == (
        f"{out}: thermal/image/zarr.json is missing: the 3 thermal frames the recording lists "
        "cannot be read"
    )


def test_a_recording_whose_pairs_are_gone_is_paired_again_by_time(tmp_path: Path) -> None:
    out = tmp_path / "p.zarr"
    small_recording(out, 5)  # frames 1/30 s apart, depth and thermal at the same times
    want = [(p.index, int(p.depth[0, 0]), int(p.thermal[0, 0])) for p in Recording(out).pairs()]
    shutil.rmtree(out / "pairs")
    lines: list[str] = []
    src = open_source(f"recording:{out}", warn=lines.append)
    got = [(p.index, int(p.depth[0, 0]), int(p.thermal[0, 0])) for p in src]
    assert got == want == [(i, i, i) for i in range(5)]
    assert lines == [
        f"{out}: no pairs table, though it holds 5 depth and 5 thermal frames: paired again by "
        "time (max skew 20 ms); the pairs may differ from the live run's"
    ]
    assert src.pairer is not None and src.pairer.stats.pairs == 5  # type: ignore[attr-defined]


def test_a_frame_that_does_not_fit_the_calibration_names_the_recording(tmp_path: Path) -> None:
    from thermodepth.app.run import RunOptions, run

    out = tmp_path / "tiny.zarr"
    small_recording(out, 2)  # 3x2 depth frames
    sim_rig().calibration.save(tmp_path / "cal.yaml")
    (tmp_path / "s.yaml").write_text("calibration: cal.yaml\n")
    with pytest.raises(InputError) as info:
        run(RunOptions(f"recording:{out}", tmp_path / "s.yaml"))
    assert str(info.value) == (
        f"recording:{out}: frame 0: the depth image is 3x2 but the calibration's depth camera "
        "is 1280x720"
    )


def test_rerecording_a_replay_keeps_frames_whose_numbering_restarted(tmp_path: Path) -> None:
    # a depth camera that reconnected numbers its frames from 0 again (pixels = the time)
    tel = Telemetry(frame_counter=0, fpa_temp_k=300.0, housing_temp_k=float("nan"))
    live = tmp_path / "live.zarr"
    with RecordingWriter(live) as w:
        for i in range(6):
            d = DepthFrame(np.full((2, 3), i, np.uint16), i / 30, i % 3)
            t = ThermalFrame(np.full((2, 2), i, np.uint16), i / 30, i, tel)
            w.add(d)
            w.add(t)
            w.add(Match(d, t, pair_of(d, t, i)))
    again = tmp_path / "again.zarr"
    record_session(open_source(f"recording:{live}"), again)
    got = list(Recording(again).pairs())
    assert [int(p.depth[0, 0]) for p in got] == list(range(6))  # not 0, 1, 2, 0, 1, 2
    assert Recording(again).n_depth == 6


def test_replaying_a_recording_with_recorder_drops_warns(tmp_path: Path) -> None:
    out = tmp_path / "d.zarr"
    record_session(SimSource(sim_rig()), out, frames=2)
    attrs = zarr.open_group(str(out), mode="r+").attrs
    attrs["recorder"] = {"dropped": {"depth": 3, "thermal": 1, "pairs": 1}}
    lines: list[str] = []
    assert len(list(open_source(f"recording:{out}", warn=lines.append))) == 2
    assert lines == [
        f"{out}: the recorder dropped 5 events while recording (depth 3, thermal 1, pairs 1): "
        "the replay gives the pairs recorded, not every pair the live run saw"
    ]
