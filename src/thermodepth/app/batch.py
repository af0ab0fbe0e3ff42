"""``thermodepth batch``: many recordings measured again on a dask.distributed cluster.

Each recording is split into ranges of pairs, one task each, so that one long recording also
spreads over the workers. A task replays its range through the pipeline on a worker and
returns the lines each frame adds to the measurement files (:class:`~thermodepth.io.
measurements.FrameLines`); the client writes each recording's files when all its ranges are
in, so they are byte for byte those of ``run --source recording:`` with the same settings.
The alarm rules count frames across a range's start: a task first measures, without keeping
them, the pairs before its range that rebuild that count (the largest ``for_frames`` measured
frames, FFC frames skipped as the run skips them, and the seconds of the rules' delays and
windows). A rule whose state may depend on the whole past (a latch, hysteresis) makes its
recordings one task each. Files are written into
``<name>.partial/`` and renamed whole, so a folder ``<name>/`` is complete;
``batch.json`` says which settings made the folder's results (``--resume`` completes only
those). See docs/batch.md.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from functools import lru_cache
from pathlib import Path
from typing import Any

import numba
import numpy as np

from ..alarms import AlarmTracker
from ..calibration import Calibration
from ..compensation import CompensationModel, load_model
from ..errors import FieldError, InputError, ThermodepthError, check_count, repeated
from ..io.measurements import ALL_FILES, FrameLines, MeasurementWriter
from ..io.recording import Recording
from ..pipeline import Pipeline, Settings
from ..progress import SILENT, Reporter
from ..registration import Registration
from .batch_summary import write_tables
from .run import Warn

RANGE_PAIRS = 256
"""Pairs per task: about a second of work on one core, so that a recording of an hour
(31,320 pairs) becomes 123 tasks and the cluster stays busy to the end."""

MANIFEST = "batch.json"
SUMMARY_FILES = ("summary.parquet", "summary.csv", "summary.md", "summary.png")
PROGRESS_TOPIC = "thermodepth-batch-progress"
WORKER_ENV = {"MALLOC_TRIM_THRESHOLD_": "33554432", "MALLOC_MMAP_THRESHOLD_": "33554432"}
"""What a local cluster's worker processes start with: dask's nannies set glibc's
MALLOC_TRIM_THRESHOLD_ to 64 KiB, which also pins the mmap threshold at 128 KiB, so every
frame-sized array would be a fresh mmap paying its page faults (a 174-pair range: 1.45 s
against 1.05 s with 32 MiB for both). Workers of an existing cluster should start with the
same (docs/batch.md)."""
INSTALL = "batch needs dask.distributed: pip install 'thermodepth[distributed]'"


@dataclass(frozen=True)
class BatchOptions:
    """What to measure again, with what, where, on which cluster.

    recordings: local paths or fsspec URLs (``file://``, ``s3://``); out_dir: the results
    (one folder per recording, the summary); settings: the settings YAML (None: defaults);
    workers: processes of a local cluster (default: one per core); scheduler: the address of
    an existing cluster's scheduler instead (``tcp://host:8786``); resume: complete a batch
    whose folder holds some results already; overwrite: replace an earlier batch's results;
    range_pairs: pairs per task.
    """

    recordings: tuple[str, ...]
    out_dir: Path
    settings: Path | None = None
    workers: int | None = None
    scheduler: str | None = None
    resume: bool = False
    overwrite: bool = False
    range_pairs: int = RANGE_PAIRS

    def check(self) -> None:
        """One FieldError for options that cannot go together or cannot be."""
        if not self.recordings:
            raise FieldError("recordings", "give at least one recording")
        check_count("workers", self.workers)
        check_count("range_pairs", self.range_pairs)
        if self.workers is not None and self.scheduler is not None:
            raise FieldError(
                "workers", "a local cluster's workers, or an existing cluster's scheduler: not both"
            )
        if self.resume and self.overwrite:
            raise FieldError("resume", "resume completes earlier results, overwrite replaces them")


@dataclass(frozen=True)
class PipelineSpec:
    """What every task builds its pipeline from, shipped once to each worker: the settings,
    their calibration (for recordings that hold none) and the compensation model, loaded on
    the client so that workers need no access to the files."""

    settings: Settings
    calibration: Calibration | None
    model: CompensationModel | None
    threads: int | None = None  # numba's threads in a task (None: the worker's default)

    def pipeline(self, calibration: Calibration | None) -> Pipeline:
        """A pipeline for a recording holding ``calibration`` (None: the settings'), with
        the registration of that calibration this process already built, if any."""
        cal = calibration or self.calibration
        if cal is None:  # the settings name none either: Pipeline says so
            return Pipeline(self.settings, model=self.model)
        # keyed on the calibration's content: each task opens its recording, whose
        # Calibration is a new object (they compare by identity)
        key = json.dumps(cal.to_dict(), sort_keys=True)
        shared = _registration(key, self.settings.registration.method)
        return Pipeline(self.settings, shared.calibration, registration=shared, model=self.model)

    @property
    def alarm_memory(self) -> tuple[int, float]:
        """Measured frames and seconds the alarm rules look back over (the largest
        ``for_frames``; the largest of their delays and windows)."""
        rules = [a.rule() for a in self.settings.alarms]
        return (
            max((r.for_frames for r in rules), default=0),
            max((r.memory_s for r in rules), default=0.0),
        )

    @property
    def whole_recordings(self) -> bool:
        """Whether a rule's state may depend on the whole past (a latch, hysteresis): then
        each recording is one task."""
        return any(not a.rule().history_bound for a in self.settings.alarms)


@lru_cache(maxsize=8)
def _registration(calibration_json: str, method: str) -> Registration:
    """One registration per calibration (its file form, as JSON) and process: the tasks of
    one rig's recordings share it (building one takes about 60 ms, 5 % of a 256-pair range's
    work)."""
    return Registration(Calibration.from_dict(json.loads(calibration_json)), method)


@dataclass(frozen=True)
class RangeTask:
    """Pairs ``start`` to ``stop`` of the recording at ``url``, written to ``name``."""

    name: str
    url: str
    start: int
    stop: int


@dataclass
class RangeResult:
    """A task's output: each frame's lines, the warnings of its range, or the one-line error
    that stopped it."""

    task: RangeTask
    frames: list[FrameLines] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    error: str | None = None


# -- on a worker ----------------------------------------------------------------------------


def measure_range(spec: PipelineSpec, task: RangeTask) -> RangeResult:
    """Replay ``task``'s pairs through a pipeline built from ``spec`` (after the pairs before
    them that rebuild the alarm rules' counts) and return each frame's lines. A recording
    that cannot be read or a frame that does not fit ends it with ``error``."""
    result = RangeResult(task)
    listening = False  # warnings about the range's own pairs only: the warm-up's are another's

    def warn(message: str) -> None:
        if listening:
            result.warnings.append(message)

    tell = _progress_sender(task)
    if spec.threads is not None:  # per thread: the task's own
        numba.set_num_threads(min(spec.threads, numba.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]
    try:
        rec = Recording(task.url, warn)
        pipe = spec.pipeline(rec.calibration)
        _warm_up(pipe, rec, task.start, spec.alarm_memory)
        listening = True
        for pair in rec.pairs(task.start, task.stop):
            result.frames.append(FrameLines.of(pipe.process(pair)))
            tell(len(result.frames))
    except ThermodepthError as exc:  # one line, sent as text (it pickles whatever its class)
        result.error = str(exc)
    tell(len(result.frames), final=True)
    return result


def _warm_up(pipe: Pipeline, rec: Recording, start: int, memory: tuple[int, float]) -> None:
    """Measure (and drop) the pairs before ``start`` that the alarm states at ``start``
    depend on: the last ``memory[0]`` measured ones (FFC pairs are not measured), reaching
    ``memory[1]`` seconds back. A pair that turns out unreadable there is skipped as the run
    skips it, so go back further until enough were measured or the recording's start is
    reached."""
    frames, seconds = memory
    if start == 0 or (frames == 0 and seconds == 0):
        return
    measured_rows = np.flatnonzero(~rec.pair_in_ffc()[:start])
    times = rec.pair_times_s()
    back = max(frames, 1)
    while True:
        first = int(measured_rows[-back]) if back <= measured_rows.size else 0
        spans = times[start] - times[first] > seconds if seconds else True
        if not spans and first > 0:
            back *= 2
            continue
        pipe.alarms = AlarmTracker(pipe.alarms.rules)
        measured = sum(not pipe.process(p).in_ffc for p in rec.pairs(first, start))
        if measured >= frames or first == 0:
            return
        back *= 2


def task_key(task: RangeTask) -> str:
    """A task's name in the progress events."""
    return f"{task.name}:{task.start}"


def _progress_sender(task: RangeTask) -> Callable[..., None]:
    """``tell(done, final=False)``: the pairs the task has measured, sent to the client at
    most every 0.2 s (absolute counts: a task run again after its worker died counts from
    0 again without counting twice). Nothing outside a dask worker."""
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):
        return lambda done, final=False: None
    key = task_key(task)
    last = [0.0]

    def tell(done: int, final: bool = False) -> None:
        now = time.monotonic()
        if final or now - last[0] >= 0.2:
            last[0] = now
            worker.log_event(PROGRESS_TOPIC, {"task": key, "done": done})

    return tell


# -- on the client --------------------------------------------------------------------------


@dataclass(frozen=True)
class Job:
    """A recording to measure: its output folder's name, where it is, its ranges."""

    name: str
    url: str
    n_pairs: int
    tasks: tuple[RangeTask, ...]


@dataclass
class BatchResult:
    """What a batch did: recordings measured now, skipped as complete (``--resume``),
    failed (name -> one line), pairs measured, the dashboard's address, the summary rows."""

    out_dir: Path
    measured: list[str] = field(default_factory=list)
    complete: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    pairs: int = 0
    dashboard: str | None = None
    summary: list[dict[str, Any]] = field(default_factory=list)
    wall_s: float = 0.0


def batch(
    options: BatchOptions,
    reporter: Reporter = SILENT,
    warn: Warn | None = None,
    say: Callable[[str], None] | None = None,
) -> BatchResult:
    """Measure every recording of ``options`` again (see the module docstring). The settings
    are validated and the output folder checked before any task starts; a recording that
    cannot be read or measured is one line in ``failed`` (and ``warn``), and the others
    complete. ``say`` hears the dashboard's address."""
    options.check()
    t0 = time.perf_counter()
    settings = Settings.load(options.settings) if options.settings else Settings()
    spec = PipelineSpec(
        settings,
        Calibration.load(settings.calibration) if settings.calibration else None,
        load_model(settings.compensation) if settings.compensation else None,
    )
    names = output_names(options.recordings)
    out = prepare_output(options, identity(options.settings, settings))
    result = BatchResult(out)
    warn = warn or (lambda message: None)

    def fail(name: str, message: str) -> None:
        result.failed[name] = message
        warn(message)

    jobs = []
    for name, url in zip(names, options.recordings, strict=True):
        if (out / name).is_dir() and options.resume:
            result.complete.append(name)
            continue
        shutil.rmtree(out / f"{name}.partial", ignore_errors=True)  # a run cut short
        try:
            jobs.append(plan(name, url, spec, options.range_pairs, warn))
        except ThermodepthError as exc:
            fail(name, str(exc))
    if jobs:
        if options.scheduler is None:  # a local cluster's workers share the cores
            cores = os.cpu_count() or 1
            spec = replace(spec, threads=max(1, cores // (options.workers or cores)))
        with _client(options) as client:
            result.dashboard = client.dashboard_link
            if say is not None:
                say(f"dask dashboard: {result.dashboard}")
            _measure(client, spec, jobs, out, result, reporter, warn, fail)
    rules = [a.name for a in settings.alarms]
    result.summary = write_tables(out, names, options.recordings, result.failed, rules)
    result.wall_s = time.perf_counter() - t0
    return result


def output_names(recordings: tuple[str, ...]) -> list[str]:
    """Each recording's output folder name: its last path part without ``.zarr``. Two
    recordings that would write the same folder are one InputError line naming them."""
    names = [Path(r.rstrip("/")).name.removesuffix(".zarr") for r in recordings]
    for twice in repeated(names):
        both = [r for r, n in zip(recordings, names, strict=True) if n == twice]
        raise InputError(f"{' and '.join(both)} would both write {twice}/: rename one")
    return names


def identity(settings_path: Path | None, settings: Settings) -> dict[str, Any]:
    """What decides a batch's results: the SHA-256 of the settings file and of the files it
    names (calibration, compensation model)."""
    digest = hashlib.sha256()
    for path in (settings_path, settings.calibration, settings.compensation):
        digest.update(b"-" if path is None else Path(path).read_bytes())
    return {
        "format": "thermodepth-batch",
        "settings_file": None if settings_path is None else str(settings_path),
        "settings_sha256": digest.hexdigest(),
    }


def prepare_output(options: BatchOptions, ident: dict[str, Any]) -> Path:
    """The output folder, ready: new or empty; or holding this batch's earlier results
    (``resume``); or an earlier batch's, replaced (``overwrite``). Anything else is refused
    with one line, before any task starts."""
    out = options.out_dir
    if out.exists() and not out.is_dir():
        raise FieldError("out_dir", f"{out} is not a directory")
    entries = sorted(p.name for p in out.iterdir()) if out.is_dir() else []
    manifest = out / MANIFEST
    if entries and not manifest.is_file():
        raise FieldError(
            "out_dir", f"{out} holds other files ({entries[0]}, ...): not a batch's results"
        )
    if entries:
        try:
            earlier = json.loads(manifest.read_text(encoding="utf-8"))
            same = earlier.get("settings_sha256") == ident["settings_sha256"]
        except (OSError, ValueError, AttributeError) as exc:
            why = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
            raise FieldError("out_dir", f"{manifest} is unreadable ({why})") from None
        if options.resume and not same:
            raise FieldError(
                "out_dir",
                f"{out} holds results of other settings (or of a changed calibration or "
                "model): --overwrite replaces them",
            )
        if not options.resume and not options.overwrite:
            raise FieldError(
                "out_dir",
                f"{out} holds a batch's results: --resume completes them, --overwrite "
                "replaces them",
            )
        if options.overwrite:
            _clear(out, entries)
    out.mkdir(parents=True, exist_ok=True)
    _write_atomic(manifest, json.dumps({**ident, "created_utc": _now()}, indent=2) + "\n")
    return out


def _clear(out: Path, entries: list[str]) -> None:
    """Remove an earlier batch's results: only what a batch writes (its manifest, summary
    files, and folders holding the measurement files), or refuse naming what is not."""
    ours = set(SUMMARY_FILES) | {MANIFEST}
    for name in entries:
        path = out / name
        own_folder = path.is_dir() and {p.name for p in path.iterdir()} <= set(ALL_FILES)
        if name not in ours and not own_folder:
            raise FieldError("out_dir", f"{path} is not a batch's result: not replacing {out}")
    for name in entries:
        path = out / name
        shutil.rmtree(path) if path.is_dir() else path.unlink()


def plan(name: str, url: str, spec: PipelineSpec, range_pairs: int, warn: Warn) -> Job:
    """Open the recording (its problems told through ``warn`` once, here), check that the
    pipeline can measure it, and cut its pairs into ranges; InputError if it cannot be."""
    rec = Recording(url, warn)
    if not rec.n_pairs:
        raise InputError(f"{url}: no pairs to measure (a recording of one camera, or empty)")
    spec.pipeline(rec.calibration)  # a calibration that does not fit: one line, here
    if spec.whole_recordings:
        range_pairs = rec.n_pairs
    starts = range(0, rec.n_pairs, range_pairs)
    tasks = tuple(RangeTask(name, url, a, min(a + range_pairs, rec.n_pairs)) for a in starts)
    return Job(name, url, rec.n_pairs, tasks)


@contextmanager
def _client(options: BatchOptions) -> Iterator[Any]:
    """A dask client: of a local cluster of ``workers`` processes (numba given the cores
    each), or connected to the scheduler at ``scheduler`` (one line if it cannot be
    reached)."""
    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError:
        raise ThermodepthError(INSTALL) from None
    if options.scheduler is not None:
        _probe(options.scheduler)
        with Client(options.scheduler, timeout=10) as client:
            yield client
        return
    config = {f"distributed.nanny.pre-spawn-environ.{k}": v for k, v in WORKER_ENV.items()}
    with _environ_kept(), dask.config.set(config), LocalCluster(
        n_workers=options.workers or os.cpu_count() or 1,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address="127.0.0.1:0",
        silence_logs=40,  # logging.ERROR: the workers' own lines stay out of the command's
    ) as cluster, Client(cluster) as client:  # fmt: skip
        yield client


@contextmanager
def _environ_kept() -> Iterator[None]:
    """Give this process's environment back as it was: dask's nannies set the workers'
    variables (OMP_NUM_THREADS, MALLOC_*) in it before spawning them, and leave them there
    for every process this one starts later."""
    saved = dict(os.environ)
    try:
        yield
    finally:
        os.environ.clear()
        os.environ.update(saved)


def _probe(address: str, timeout_s: float = 5.0) -> None:
    """Fail in ``timeout_s`` with one line when nothing answers as a dask scheduler at
    ``address`` (dask's own client would wait 30 s, or for ever on a port that accepts and
    never answers)."""
    import asyncio

    from distributed.comm import connect

    async def hello() -> None:
        comm = await asyncio.wait_for(connect(address, timeout=timeout_s), timeout_s)
        await comm.close()

    try:
        asyncio.run(hello())
    except asyncio.TimeoutError:
        raise FieldError(
            "scheduler", f"no dask scheduler answers at {address} (nothing in {timeout_s:g} s)"
        ) from None
    except (OSError, ValueError, TypeError) as exc:
        why = str(exc).split("\n")[0] or type(exc).__name__
        raise FieldError("scheduler", f"no dask scheduler answers at {address} ({why})") from None


def _measure(
    client: Any,
    spec: PipelineSpec,
    jobs: list[Job],
    out: Path,
    result: BatchResult,
    reporter: Reporter,
    warn: Warn,
    fail: Callable[[str, str], None],
) -> None:
    """Submit every range, follow the progress across the cluster, and write each
    recording's files as soon as all its ranges are in (a failed range fails its recording;
    the others go on)."""
    from distributed import as_completed

    total = sum(job.n_pairs for job in jobs)
    by_name = {job.name: job for job in jobs}
    parts: dict[str, dict[int, RangeResult]] = {job.name: {} for job in jobs}
    shipped = client.scatter(spec, broadcast=True)
    futures = {
        client.submit(measure_range, shipped, task, pure=False): task
        for job in jobs
        for task in job.tasks
    }
    with reporter.task(f"measuring {len(jobs)} recordings", total=total) as advance:
        done: dict[str, int] = {}
        lock = threading.Lock()  # events come on dask's IO thread, results on this one

        def progress(event: tuple[float, dict[str, Any]]) -> None:
            key, n = event[1]["task"], int(event[1]["done"])
            with lock:
                gained = n - done.get(key, 0)
                if gained > 0:  # a task run again counts from 0: nothing twice
                    done[key] = n
                    advance(gained)

        client.subscribe_topic(PROGRESS_TOPIC, progress)
        try:
            for future in as_completed(list(futures)):
                task = futures[future]
                if task.name in result.failed:
                    continue
                if future.status == "error":
                    exc = future.exception()
                    fail(task.name, f"{task.url}: pairs {task.start}-{task.stop - 1}: "
                         f"{type(exc).__name__}: {exc}")  # fmt: skip
                    continue
                part: RangeResult = future.result()
                # its last progress event may come after it
                progress((0.0, {"task": task_key(task), "done": len(part.frames)}))
                for line in part.warnings:
                    warn(line)
                if part.error is not None:
                    fail(task.name, part.error)
                    continue
                parts[task.name][task.start] = part
                if len(parts[task.name]) == len(by_name[task.name].tasks):
                    ranges = [parts[task.name][t.start] for t in by_name[task.name].tasks]
                    result.pairs += write_recording(out, task.name, ranges)
                    result.measured.append(task.name)
                    del parts[task.name]
        finally:
            client.unsubscribe_topic(PROGRESS_TOPIC)
            for future in futures:
                future.cancel()


def write_recording(out: Path, name: str, ranges: list[RangeResult]) -> int:
    """Write a recording's three files from its ranges' lines, in order, into
    ``<name>.partial/`` (made afresh by :func:`batch`) and rename it ``<name>/`` (a folder of
    that name is complete); returns the frames written."""
    partial, final = out / f"{name}.partial", out / name
    frames = [lines for r in ranges for lines in r.frames]
    with MeasurementWriter(partial, sync=True) as writer:  # on disk before the rename
        for lines in frames:
            writer.write_lines(lines)
    shutil.rmtree(final, ignore_errors=True)  # --resume: a complete one is never here
    partial.rename(final)
    return len(frames)


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")
