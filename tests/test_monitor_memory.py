"""What waits between a rig and its evidence is bounded in bytes, and what a replay hands out
keeps only its own bytes: a clip whose disk stalls, pictures that wait for the painter, the
frames a recording is read into."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from thermodepth.frames import match_of
from thermodepth.io.recording import Recording, RecordingWriter
from thermodepth.io.recording import writer as writer_mod
from thermodepth.monitor.bounded import ByteQueue, nbytes_of
from thermodepth.monitor.evidence import Clip, Evidence, PreTrigger
from thermodepth.sinks.base import RunContext
from thermodepth.sources import open_source


@given(st.lists(st.integers(0, 100), max_size=40), st.integers(1, 250))
def test_a_byte_queue_holds_at_most_its_bytes_in_order(sizes: list[int], bound: int) -> None:
    q = ByteQueue(bound)
    taken = [i for i, n in enumerate(sizes) if q.offer(i, n)]
    assert q.nbytes == sum(sizes[i] for i in taken)
    assert q.nbytes <= bound or len(taken) == 1  # one item alone may be larger than the bound
    assert q.refused == len(sizes) - len(taken)
    assert [q.get(0) for _ in taken] == taken and q.nbytes == 0
    with pytest.raises(TimeoutError):
        q.get(0)


def test_an_item_counts_each_array_it_holds_once() -> None:
    pair = next(iter(open_source("sim", frames=1)))
    m = match_of(pair)  # its frames and its pair share the same arrays
    assert nbytes_of(m) == pair.depth.nbytes + pair.thermal.nbytes


def test_a_clip_whose_disk_stalls_keeps_its_bytes_and_counts_what_it_left_out(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pairs = [match_of(p) for p in open_source("sim", frames=12)]
    one = nbytes_of(pairs[0])
    disk = threading.Event()  # the disk answers when set
    writing = threading.Event()  # the writer holds a pair
    real_add = RecordingWriter.add_match

    def slow_add(self: RecordingWriter, match: object) -> None:
        writing.set()
        disk.wait()
        real_add(self, match)  # type: ignore[arg-type]

    monkeypatch.setattr(writer_mod.RecordingWriter, "add_match", slow_add)
    faults: list[str] = []
    with open_source("sim") as source:
        context = RunContext(source, source.calibration, None)
        clip = Clip("a/x", tmp_path / "x", context, [], 1e9, faults.append, int(4.5 * one))
        assert clip.add(pairs[0])
        assert writing.wait(60)
        for m in pairs[1:]:
            assert clip.add(m)
        # the writer holds the first while the disk stalls; four wait: the rest are left out
        assert clip._queue.nbytes <= 4.5 * one and clip.lost == len(pairs) - 5
        disk.set()
        clip.finish()
        clip.join(60)
    assert not faults and clip.written == 5
    rec = Recording(tmp_path / "x" / "clip.zarr")
    assert rec.n_pairs == 5 and rec.attrs["frames_not_kept"] == len(pairs) - 5


def test_pictures_past_their_bytes_are_skipped_not_queued(tmp_path: Path) -> None:
    from thermodepth.pipeline import Pipeline, Settings

    lines: list[str] = []
    evidence = Evidence(tmp_path, 0.0, 1.0, 10.0, lines.append)  # its painter not started
    with open_source("sim", frames=3) as source:
        pipe = Pipeline(Settings(), source.calibration)
        frames = [pipe.process(p) for p in source]
        context = RunContext(source, pipe.calibration, pipe)
        _ = frames[0].on_depth  # as draw() samples it, before it is queued
        evidence._pictures.max_bytes = int(2.5 * nbytes_of(frames[0]))
        for k, frame in enumerate(frames):
            event = {"event": "alarm", "rule": f"r{k}"}
            clip, _ = evidence.trigger(f"rig{k}", event, frame.thermal_time_s, context,
                                       PreTrigger(0, 0))  # fmt: skip
            evidence.draw(frame, clip, event, (15.0, 80.0))
    assert len(evidence._pictures) == 2 and evidence.pictures_skipped == 1
    assert evidence._pictures.nbytes <= evidence._pictures.max_bytes


def test_replayed_frames_are_their_own_arrays(tmp_path: Path) -> None:
    source = open_source("sim", frames=20)
    with source, RecordingWriter(tmp_path / "r.zarr", source.calibration) as w:
        for p in source:
            w.add_pair(p)
    matches = list(Recording(tmp_path / "r.zarr").matches())
    assert len(matches) == 20
    for m in matches:  # a frame kept keeps its own bytes, not its batch's
        assert m.pair.depth.base is None or m.pair.depth.base.nbytes == m.pair.depth.nbytes
        assert np.shares_memory(m.pair.depth, m.depth.depth)


FRAGMENTED = """
import numpy as np
from thermodepth.monitor.bounded import give_back_memory

def resident_mb():
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * 4096 / 1e6

held = [np.ones(12_500) for _ in range(800)]  # 100 kB each: in the heap, not mmapped
keep = held[-1]  # the heap's top still in use: glibc cannot trim what lies under it
del held
freed = resident_mb()
print(give_back_memory(), freed, resident_mb())
"""


def test_memory_freed_between_chunks_in_use_is_given_back() -> None:
    # 80 MB freed under one array still held: resident until given back (glibc)
    import ctypes.util
    import subprocess
    import sys

    if "libc.so" not in (ctypes.util.find_library("c") or ""):
        pytest.skip("malloc_trim is glibc's; this C library has none")
    done = subprocess.run(
        [sys.executable, "-c", FRAGMENTED], capture_output=True, text=True, check=True
    )
    given, freed_mb, after_mb = done.stdout.split()
    assert given == "True"
    assert float(freed_mb) - float(after_mb) > 60  # of the 80 MB freed
