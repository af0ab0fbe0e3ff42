"""The monitor: every rig of a config supervised (:mod:`.supervisor`), their events written,
evidenced and published, the storage kept bounded, health told over HTTP and to systemd.

Every event goes the same way (:meth:`Monitor.emit`): a raising event gets its clip first
(:mod:`.evidence`), then its row in the event store (written before it is published), then the
outbox (a row for each outbox output that wants it: the broker, each notification target),
then a log line. An event the store cannot take (a full disk) is published
from memory, kept in memory until the store takes it again, and raises a ``storage_fault``:
measuring and alarming go on.

The monitor's clock (:data:`TICK_S`) watches each rig: no new frame for its ``stall_s``
(longer while its shutter closes), or the same frame again and again, is a stall (the rig's
source is closed, recovered and reopened) and a ``sensor_fault``; it also sends systemd its
watchdog while every rig and every worker is well, and ticks the outputs. The storage is
swept every :data:`SWEEP_S`. The clock, the sweep, the evidence painter, the HTTP server and
the outputs' loops are supervised workers (:mod:`.workers`); the outputs (MQTT, OPC UA, ...)
are driven through one interface (:mod:`.outputs`).
"""

from __future__ import annotations

import json
import logging
import sqlite3
import threading
import time
from collections import Counter, deque
from collections.abc import Iterable
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from .. import __version__
from ..alarms import RAISED, event_line
from ..io.measurements import jsonable
from ..pipeline import FusedFrame
from .bounded import GIVE_BACK_S, give_back_memory
from .config import MONITOR, MonitorConfig, RigConfig, report_target
from .evidence import Evidence
from .failsafe import STORAGE_FAULT, Fault
from .live import Picture, VideoFrame
from .logs import apply_levels, logger
from .outputs import OUTPUT_BUILDERS, Output, OutputContext, RigEntities, build_outputs
from .readings import MinuteReadings, minute_of
from .reports import REPORT_NAME, Reports
from .rig import RigSink, quantiles
from .storage import CLIPS, REPORTS, Retention, free_bytes
from .store import EventStore, counts_by_rig
from .supervisor import AckRefusedError, ClipNotReadyError, RigRunner
from .systemd import notify, watchdog_interval_s
from .workers import Worker, Workers

TICK_S = 0.25
SWEEP_S = 30.0
STORE_NAME = "events.sqlite"
CLOCK_LIMIT_S = 5.0
SWEEP_LIMIT_S = 120.0
OUTPUT_ERROR_EVERY_S = 60.0
"""An output whose tick keeps failing is logged (with its traceback) at most this often."""
BACKLOG_MAX = 10_000
"""Events the store could not take (a full disk) kept in memory for it, at most; past it the
oldest is dropped and counted (``storage.events_lost``; its line is in the log). The same
bound holds the capture times kept for outputs' delivery latencies."""


def utc_of(time_s: float) -> str:
    """A Unix time as ISO 8601 UTC with milliseconds."""
    return datetime.fromtimestamp(time_s, timezone.utc).isoformat(timespec="milliseconds")


EVIDENCE_FILES = {"snapshot.png": "overlay.png", "clip.zip": "clip.zarr", "cloud.ply": "frame.ply"}
"""An event's evidence by the name the API gives it: its file in the event's clip folder."""


class Monitor:
    """The monitor of ``config`` (module docstring), logging to ``thermodepth.monitor`` and
    its parts (:mod:`.logs`). ``start`` and ``stop`` it; ``reload`` a new config while it
    runs."""

    def __init__(self, config: MonitorConfig) -> None:
        self.config = config
        self.log = logger()
        apply_levels(config.log.level, config.log.rigs)
        self.started_mono = time.monotonic()
        self.started_s = time.time()
        self.started_utc = utc_of(self.started_s)
        self.store = EventStore(config.storage.path / STORE_NAME)
        self.backlog: list[dict[str, Any]] = []  # events the store could not take yet
        self.events_lost = 0  # ... and dropped, oldest first, past BACKLOG_MAX
        self.event_counts: Counter[tuple[str, str]] = Counter()
        self.latency_s: dict[str, deque[float]] = {
            "event_row": deque(maxlen=1000),
            "broker": deque(maxlen=1000),
        }
        self._captured: dict[int, float] = {}  # event id -> its frame's capture time (Unix s)
        self._lock = threading.RLock()
        self._storage_fault = Fault(STORAGE_FAULT, "disk")
        self._storage_lines: list[str] = []
        self._output_errors: dict[str, float] = {}
        self._readings: dict[str, MinuteReadings] = {}  # each rig's minute so far
        self._build(config)

    # -- parts ---------------------------------------------------------------------------------

    def _build(self, config: MonitorConfig) -> None:
        """The parts a config makes (not started)."""
        self.config = config
        self.http: Any = None
        s = config.storage
        self.evidence = Evidence(
            s.path / CLIPS, s.pre_s, s.post_s, s.clip_max_s, self.storage_problem
        )
        self.runners = {rig.name: self._runner(rig) for rig in config.rigs}
        self.retention = Retention(s, self._busy, self.store.clip_deleted)
        self.outputs: list[Output] = build_outputs(config, self._context())
        self.workers = Workers()
        self.workers.add(Worker("clock", self._clock, TICK_S, CLOCK_LIMIT_S, self.log))
        self.workers.add(Worker("storage", self._sweeper, SWEEP_S, SWEEP_LIMIT_S, self.log))
        self.workers.add(self.evidence.painter)
        self.reports = Reports(config, self._report_target, self.started_s)
        if config.reports:
            self.workers.add(self.reports.worker)
        for output in self.outputs:
            for worker in output.workers():
                self.workers.add(worker)

    def _context(self) -> OutputContext:
        return OutputContext(
            self.config,
            self.entities(),
            self.store,
            self.acknowledge,
            self.picture,
            self._delivered,
            lambda: self.status()["rigs"],
            self.evidence_of,
            self._snapshot_file,
            self.video,
        )

    def entities(self) -> list[RigEntities]:
        """What each rig shows a plant's systems: its ROIs and alarm rules."""
        return [
            RigEntities.of(r.name, r.config.location, r.settings) for r in self.runners.values()
        ]

    def _report_target(self, name: str) -> Any:
        """The notify output a scheduled report goes to (None: none of that name)."""
        target = report_target(self.config, name)
        return None if target is None else self.output(target.target_name())

    def report_file(self, name: str) -> Path | None:
        """A kept scheduled report by its file's name (None: no such name or file)."""
        if not REPORT_NAME.fullmatch(name):
            return None
        path = self.config.storage.path / REPORTS / name
        return path if path.is_file() else None

    def output(self, name: str) -> Output | None:
        """The output of that name (``mqtt``, ``opcua``, ...), None when not configured."""
        return next((o for o in self.outputs if o.name == name), None)

    def _runner(self, rig: RigConfig, config: MonitorConfig | None = None) -> RigRunner:
        c = config or self.config
        return RigRunner(
            rig,
            c.storage,
            c.failsafe,
            self.evidence,
            self.emit,
            self.measured,
            self.storage_problem,
        )

    def measured(self, sink: RigSink, fused: FusedFrame) -> None:
        """A rig's fused frame: into its readings of the minute (:mod:`.readings`), to every
        output (each keeps its own rate)."""
        runner = self.runners.get(sink.name)
        if runner is not None:
            readings = self._readings.get(sink.name)
            if readings is None or readings.rois is not runner.live.rois:  # a new runner
                self._flush_readings(sink.name)
                readings = MinuteReadings(sink.name, runner.live.rois, self._write_readings)
                self._readings[sink.name] = readings
            readings.add(fused, fused.thermal_time_s if runner.wall_clock else time.time())
        for output in self.outputs:
            output.measured(sink.name, fused)

    def _write_readings(self, rows: list[dict[str, Any]]) -> None:
        try:
            self.store.add_readings(rows)
        except sqlite3.Error as exc:  # a full disk: a minute's readings are not kept
            self.storage_problem(
                f"{rows[0]['rig']}: readings of {rows[0]['minute_utc']} not written to "
                f"{self.store.path} ({exc})"
            )

    def _flush_readings(self, rig: str | None = None) -> None:
        """Write a rig's (None: every rig's) readings of the minute so far."""
        for name in list(self._readings) if rig is None else [rig]:
            readings = self._readings.pop(name, None)
            if readings is not None:
                readings.flush()

    def _busy(self) -> set[Any]:
        busy = self.evidence.active_folders()
        for r in self.runners.values():
            if r.sink.continuous is not None:
                busy |= r.sink.continuous.active
        return busy

    def _raised(self) -> dict[str, set[str]]:
        return {name: {a["rule"] for a in r.raised()} for name, r in self.runners.items()}

    def start(self) -> None:
        """Start every part: the outputs and the HTTP server first, each binding or connecting
        without a word to anyone (each may refuse with one InputError line: what had started
        is stopped, nothing else starts, nothing was published); then the outputs announce
        the monitor, and the rigs and the workers start."""
        started: list[Any] = []
        try:
            for output in self.outputs:
                output.start()
                started.append(output)
                self.log.info("monitor: %s", output.describe())
            if self.config.http.listen is not None:
                from .http import HttpServer

                self.http = HttpServer(self, self.config.http, self.config.mjpeg)
                self.http.start()
                started.append(self.http)
                self.workers.add(self.http.worker)
                self.log.info("monitor: HTTP on %s", self.http.url)
        except BaseException:
            for part in reversed(started):
                for worker in getattr(part, "workers", lambda: [])():
                    worker.stop()
                part.stop("not started")
            self.outputs, self.http = [], None
            raise
        raised = self._raised()
        for output in self.outputs:
            output.announce(raised)
        self._warm_up(self.runners.values())
        for runner in self.runners.values():
            runner.start()
        self.workers.start()
        self.log.info(
            "monitor: watching %d rigs (%s), storage %s",
            len(self.runners),
            ", ".join(self.runners),
            self.config.storage.path,
        )

    def _warm_up(self, runners: Iterable[RigRunner]) -> None:
        """Every kernel the rigs' frames run compiled before any rig runs (once per process;
        numba keeps them on disk too): a compile in one rig's thread would hold the others'."""
        t0 = time.monotonic()
        seen: set[tuple[str | None, Path | None]] = set()
        for runner in runners:  # the same settings file: the same kernels
            key = (runner.settings_text, runner.config.settings)
            if key not in seen:
                seen.add(key)
                runner.warm_up()
        if (took_s := time.monotonic() - t0) > 1.0:
            self.log.info("monitor: kernels compiled in %.0f s (numba keeps them on disk)", took_s)

    def stop(self, reason: str = "stopped") -> None:
        """Stop the rigs, finish the clips and recordings, say so to the outputs, close."""
        self._stop_parts(reason)
        self._flush_backlog()
        if self.backlog:  # a disk still full: the log keeps them
            self.log.error(
                "storage: %d events could not be written to %s; here they are, one JSON line each:",
                len(self.backlog),
                self.store.path,
            )
            for event in self.backlog:
                self.log.error("%s", json.dumps(jsonable(event)))
        self.store.close()

    def _stop_parts(self, reason: str) -> None:
        """Everything but the event store stopped (see :meth:`stop`)."""
        for runner in self.runners.values():
            runner.stop()
        self._flush_readings()
        self.evidence.close()
        for runner in self.runners.values():
            if runner.sink.continuous is not None:
                runner.sink.continuous.join()
        self.workers.stop()
        for output in self.outputs:
            output.stop(reason)
        if self.http is not None:
            self.http.stop()

    def reload(self, config: MonitorConfig) -> None:
        """Apply a new config while running: a rig changed (its entry or its settings
        file's content), added or removed is restarted, added or stopped on its own, and an
        output whose rigs changed is started again; any other change (storage, http, an
        output's section, failsafe) restarts every part. A rule that did not change keeps
        its state (raised, acknowledged) across either. The log's levels change at once. The
        event store stays open."""
        apply_levels(config.log.level, config.log.rigs)
        old = self.config

        def rest(c: MonitorConfig) -> MonitorConfig:
            return c.model_copy(update={"rigs": [], "log": None})

        if rest(old) != rest(config):
            self.log.info(
                "monitor: reloading every part (storage, http, outputs or failsafe changed)"
            )
            self._restart(config)
            return
        keep = {r.name for r in config.rigs if self._unchanged(r)}
        gone: dict[str, RigRunner] = {}
        for name, runner in list(self.runners.items()):
            if name not in keep:
                runner.stop()
                self._flush_readings(name)
                gone[name] = self.runners.pop(name)
                self.log.info("%s: stopped (reload)", name)
        self.config = config
        for rig in config.rigs:
            if rig.name not in self.runners:
                runner = self._runner(rig, config)
                kept = runner.carry_over(gone[rig.name]) if rig.name in gone else []
                self.runners[rig.name] = runner
                self._warm_up([runner])
                runner.start()
                self.log.info(
                    "%s: started (reload)%s", rig.name,
                    f"; rules kept as they were: {', '.join(kept)}" if kept else "",
                )  # fmt: skip
        self.runners = {r.name: self.runners[r.name] for r in config.rigs}  # config order
        for i, output in enumerate(self.outputs):
            if not output.fits(self.entities()):
                self.outputs[i] = self._rebuilt(output)

    def _rebuilt(self, output: Output) -> Output:
        """An output built again for the rigs now, started and announced."""
        for worker in output.workers():
            self.workers.all.pop(worker.name, None)
            worker.stop()
        output.stop("reloading")
        built = OUTPUT_BUILDERS[output.section].build(self.config, self._context())
        new = next(o for o in built if o.name == output.name)
        new.start()
        new.announce(self._raised())
        for worker in new.workers():
            self.workers.add(worker)
            worker.start()
        return new

    def _unchanged(self, rig: Any) -> bool:
        runner = self.runners.get(rig.name)
        if runner is None or runner.config != rig:
            return False
        if rig.settings is None:
            return True
        try:
            text = rig.settings.read_text(encoding="utf-8")
        except OSError:
            return False
        return text == runner.settings_text

    def _restart(self, config: MonitorConfig) -> None:
        """Every part stopped and started again from ``config`` (unchanged rules keeping
        their states); if it cannot start (a port taken, a broker away), the old config is
        started again and the error raised."""
        old, before = self.config, self.runners
        self._stop_parts("reloading")
        if config.storage.path != old.storage.path:
            self.store.close()
            self.store = EventStore(config.storage.path / STORE_NAME)
        try:
            self._build(config)
            self._carry_over(before)
            self.start()
        except BaseException:
            self._stop_parts("reloading")
            if config.storage.path != old.storage.path:
                self.store.close()
                self.store = EventStore(old.storage.path / STORE_NAME)
            self._build(old)
            self._carry_over(before)
            self.start()
            raise

    def _carry_over(self, before: dict[str, RigRunner]) -> None:
        for name, runner in self.runners.items():
            if name in before:
                runner.carry_over(before[name])

    # -- events --------------------------------------------------------------------------------

    def emit(self, sink: RigSink, events: list[dict[str, Any]], fused: FusedFrame | None) -> None:
        """A rig's events (module docstring): clip, row, outbox, line; then to every output,
        and the picture of a new clip (the slow part, after the alarm is out)."""
        runner = self.runners.get(sink.name)
        told = []
        for event in events:
            event = {**event, "rig": sink.name}
            if runner is not None and runner.config.location:
                event["location"] = runner.config.location
            captured, drawn = None, None
            if fused is not None:
                vox = fused.vox_temp_c
                event["vox_temp_c"] = None if vox != vox else round(vox, 3)
                if runner is not None and runner.wall_clock:
                    captured = fused.thermal_time_s
                if event["event"] in RAISED and sink.context is not None:
                    clip, new = self.evidence.trigger(
                        sink.name, event, fused.thermal_time_s, sink.context, sink.pre
                    )
                    event["clip"] = clip.id
                    drawn = clip if new else None
            self.record(event, captured, runner is None or runner.wall_clock)
            told.append(event)
            if drawn is not None and fused is not None:
                fixed = runner.settings.viewer.fixed_range_c if runner else None
                self.evidence.draw(fused, drawn, event, fixed)
        if runner is not None:
            raised = {a["rule"] for a in runner.raised()}
            for output in self.outputs:
                output.events(sink.name, told, raised)

    def record(
        self, event: dict[str, Any], captured_s: float | None = None, unix_time: bool = True
    ) -> None:
        """Write, send and log one event (with ``rig``); ``captured_s``: its frame's capture
        time (Unix s), for the latency figures; ``unix_time``: its ``time_s`` is a Unix time
        (a rig on a live clock; else it is stamped with now)."""
        time_s = event.get("time_s")
        event["time_utc"] = utc_of(time_s if unix_time and time_s else time.time())
        event["state"] = event["event"]  # the lifecycle's word for it, as the store's column
        why = None
        outbox = [o for o in self.outputs if o.outbox and o.wants(event)]
        with self._lock:
            self.event_counts[(event["rig"], event["event"])] += 1
            self._flush_backlog()
            try:
                event["id"] = self.store.add(event, outbox=[o.name for o in outbox])
            except sqlite3.Error as exc:
                if len(self.backlog) >= BACKLOG_MAX:  # its line is in the log already
                    self.backlog.pop(0)
                    self.events_lost += 1
                self.backlog.append(event)
                why = (
                    f"event {event['rig']} {event['rule']} not written to {self.store.path} "
                    f"({exc}): kept in memory until it can be"
                )
            else:
                if captured_s is not None:
                    self.latency_s["event_row"].append(time.time() - captured_s)
                    if outbox:  # an output tells when it has it: the delivery's latency
                        if len(self._captured) >= BACKLOG_MAX:
                            del self._captured[next(iter(self._captured))]
                        self._captured[event["id"]] = captured_s
        if why is not None:
            self.storage_problem(why)
        for output in outbox:
            if why is None:
                output.wake()
            else:
                output.send_now(event)
        rig_log = self.log if event["rig"] == MONITOR else logger(f"rig.{event['rig']}")
        level = logging.WARNING if event["event"] in RAISED else logging.INFO
        rig_log.log(level, "%s: %s", event["rig"], event_line(event))

    def _flush_backlog(self) -> None:
        """Write the events the store could not take, in order, while it takes them."""
        with self._lock:
            while self.backlog:
                try:
                    self.backlog[0]["id"] = self.store.add(self.backlog[0])
                except sqlite3.Error:
                    return
                self.backlog.pop(0)

    def _delivered(self, event: dict[str, Any]) -> None:
        captured = self._captured.pop(event.get("id", -1), None)
        if captured is not None:
            self.latency_s["broker"].append(time.time() - captured)

    def acknowledge(self, rig: str, rule: str, by: str) -> list[dict[str, Any]]:
        """Acknowledge a rig's raised rule (who: ``by``); its events, recorded and published.
        AckRefusedError (404 or 409) when it cannot be."""
        runner = self.runners.get(rig)
        if runner is None:
            raise AckRefusedError(404, f"no rig {rig!r}")
        events = runner.acknowledge(rule, by)
        self.emit(runner.sink, events, None)
        return events

    def retire(self, name: str) -> list[str]:
        """Rigs leave a monitor by leaving its config (a reload); only a central dashboard
        retires them (AckRefusedError 409)."""
        raise AckRefusedError(
            409, "a monitor's rigs leave by its config (then reload it); the central "
            "dashboard retires a monitor that is gone"
        )  # fmt: skip

    def storage_problem(self, line: str) -> None:
        """Something could not be kept: a ``storage_fault`` (raised once; cleared by a sweep
        with nothing new to tell and space enough)."""
        self.log.error("storage: %s", line)
        with self._lock:
            self._storage_lines.append(line)
            event = self._storage_fault.update(time.time(), True, line)
        if event is not None:
            self.record({**event, "rig": MONITOR})

    # -- the workers ---------------------------------------------------------------------------

    def _clock(self, worker: Worker) -> None:
        watchdog_s = watchdog_interval_s()
        last = time.monotonic()
        last_dog = last_give = float("-inf")
        while not worker.stopping.wait(TICK_S):
            worker.beat()
            now = time.monotonic()
            dt, last = now - last, now
            if now - last_give >= GIVE_BACK_S:  # the frames' freed memory (bounded.py)
                give_back_memory()
                last_give = now
            for runner in list(self.runners.values()):
                self._watch(runner, now, dt)
            well = all(r.alive for r in self.runners.values()) and not self.workers.unhealthy()
            if watchdog_s is not None and now - last_dog >= watchdog_s and well:
                notify("WATCHDOG=1")
                last_dog = now
            for output in list(self.outputs):
                try:
                    output.tick(now)
                except Exception:  # one output's trouble must not stop the clock's watch
                    if now - self._output_errors.get(output.name, -OUTPUT_ERROR_EVERY_S) >= (
                        OUTPUT_ERROR_EVERY_S
                    ):
                        self._output_errors[output.name] = now
                        self.log.error("%s: its tick failed", output.name, exc_info=True)

    def _watch(self, runner: RigRunner, now_mono: float, dt: float) -> None:
        s = runner.status
        if s.state in ("ended", "stopped"):
            return
        age = s.age_s(now_mono)
        events = runner.watch.tick(time.time(), age, s.in_ffc, s.last_frame_mono is None)
        if runner.watch.faults["no_data"].raised:
            s.seconds_without_data += dt
        if events:
            self.emit(runner.sink, events, None)
        if s.state != "running":
            return
        limit = runner.config.stall_s + (self.config.failsafe.ffc_grace_s if s.in_ffc else 0.0)
        quiet = s.quiet_s(now_mono)
        if quiet >= limit:
            runner.abort_stalled(f"no new frame for {quiet:.1f} s")
        elif s.frozen_since_mono is not None and now_mono - s.frozen_since_mono >= limit:
            runner.abort_stalled(f"the same frame for {now_mono - s.frozen_since_mono:.1f} s")

    def _sweeper(self, worker: Worker) -> None:
        while True:
            worker.beat()
            self.sweep()
            if worker.stopping.wait(SWEEP_S):
                return

    def sweep(self) -> None:
        """Apply the storage rule, write what the store could not take; clear the storage
        fault when nothing new went wrong and space is enough. An error of the event store
        ends the sweep (its worker is restarted; what it had not done is done next time)."""
        try:
            low = self.retention.sweep()
        except OSError as exc:
            low = f"{self.config.storage.path}: cannot sweep ({exc.strerror or exc})"
        self._flush_backlog()
        oldest_s = time.time() - self.config.storage.retention_days * 86400.0
        self.store.forget_readings(minute_of(oldest_s))
        with self._lock:
            lines, self._storage_lines = self._storage_lines, []
            quiet = not lines and low is None and not self.backlog
        if low is not None:
            self.storage_problem(low)
        elif quiet:
            event = self._storage_fault.update(time.time(), False)
            if event is not None:
                self.record({**event, "rig": MONITOR})

    # -- what it tells -------------------------------------------------------------------------

    def stale_rigs(self) -> list[str]:
        """The rigs without fresh data (none: healthy); a replay that ended is not one."""
        now = time.monotonic()
        return [
            r.name
            for r in self.runners.values()
            if r.status.state != "ended"
            and (r.status.state != "running" or r.status.age_s(now) >= r.config.stall_s)
        ]

    def unhealthy_workers(self) -> list[str]:
        """The monitor's workers down for longer than their limit (none: healthy)."""
        return self.workers.unhealthy()

    @staticmethod
    def _health(runner: RigRunner, stale: set[str]) -> str:
        """``stale`` (no fresh data), ``fault`` (a sensor fault raised) or ``ok``."""
        return "stale" if runner.name in stale else "fault" if runner.watch.raised else "ok"

    def status(self) -> dict[str, Any]:
        """Everything ``/api/status`` tells (module docstring of :mod:`.http`)."""
        now = time.monotonic()
        stale = set(self.stale_rigs())
        rigs = []
        for r in list(self.runners.values()):
            d = r.status.as_dict(now)
            d["up"] = int(r.name not in stale)
            d["active_alarms"] = r.raised()
            d["health"] = self._health(r, stale)
            d["temp_range_c"] = r.live.range_c
            rigs.append(d)
        path = self.config.storage.path
        mqtt = self.output("mqtt")
        return {
            "version": __version__,
            "started_utc": self.started_utc,
            "uptime_s": round(now - self.started_mono, 1),
            "rigs": rigs,
            "workers": self.workers.status(now),
            "outputs": {o.name: o.status() for o in self.outputs},
            "storage": {
                "path": str(path),
                "free_bytes": free_bytes(path),
                "event_store_bytes": self.store.size_bytes(),
                "events_not_stored": len(self.backlog),
                "events_lost": self.events_lost,
                "pictures_skipped": self.evidence.pictures_skipped,
                "deleted": dict(self.retention.deleted),
                "fault": self._storage_fault.raised,
            },
            "reports": self.reports.status() if self.config.reports else None,
            "mqtt": None if mqtt is None else mqtt.status(),
            "mjpeg": None if self.http is None else self.http.streams.status(),
            "event_counts": counts_by_rig(self.event_counts),
            "latency_s": {k: quantiles(v) for k, v in self.latency_s.items()},
        }

    def events(
        self,
        limit: int = 100,
        rig: str | None = None,
        before_id: int | None = None,
        level: str | None = None,
        state: str | None = None,
    ) -> list[dict[str, Any]]:
        """The newest events (``/api/events``): those not yet in the store first."""
        wanted = {"rig": rig, "level": level, "state": state}
        with self._lock:
            waiting = [
                e
                for e in reversed(self.backlog)
                if all(v is None or e.get(k) == v for k, v in wanted.items())
            ]
        stored = self.store.events(limit, rig, before_id, level, state)
        return (waiting if before_id is None else []) + stored[: max(0, limit - len(waiting))]

    def event(self, event_id: int) -> dict[str, Any] | None:
        """One stored event by its id."""
        return self.store.event(event_id)

    def evidence_file(self, event_id: int, what: str) -> Path | None:
        """An event's kept evidence: ``snapshot.png`` (its clip's overlay), ``cloud.ply``
        (its point cloud), ``clip.zip`` (the folder of its recording, zipped by the
        caller; ClipNotReadyError while it is still being recorded); None when it has none or
        it is not kept. Found by the event's id, never a path from outside: a clip id that
        leads out of the clips' folder is none."""
        event = self.store.event(event_id)
        if event is None or what not in self.evidence_of(event):
            return None
        root = (self.config.storage.path / CLIPS).resolve()
        folder = (root / str(event["clip"])).resolve()
        if not folder.is_relative_to(root) or folder == root:
            return None
        path = folder / EVIDENCE_FILES[what]
        if what == "clip.zip" and folder in self.evidence.active_folders():
            raise ClipNotReadyError(f"event {event_id}: its clip is still being recorded")
        return path if path.exists() else None

    def _snapshot_file(self, event_id: int, what: str) -> Path | None:
        """An event's evidence file for an output (a clip still recorded: none yet)."""
        try:
            return self.evidence_file(event_id, what)
        except ClipNotReadyError:
            return None

    def evidence_of(self, event: dict[str, Any]) -> list[str]:
        """What :meth:`evidence_file` may give for an event: all of it while its clip is
        kept, nothing otherwise."""
        return list(EVIDENCE_FILES) if event.get("clip") and event.get("clip_kept", True) else []

    def picture(self, rig: str, what: str, width: int | None = None) -> Picture | None:
        """A rig's latest ``overlay`` (JPEG) or ``thermal`` (PNG) picture (:mod:`.live`)."""
        runner = self.runners.get(rig)
        return None if runner is None else runner.live.picture(what, width)

    def video(self, rig: str, view: str, hz: float) -> VideoFrame | None:
        """A rig's latest picture framed for a video stream playing at ``hz`` (:mod:`.live`):
        titled with its name, location and the frame's time."""
        runner = self.runners.get(rig)
        if runner is None:
            return None
        title = " ".join(filter(None, (rig, runner.config.location)))
        return runner.live.video(view, title, hz)

    def trend(self, rig: str) -> list[dict[str, Any]] | None:
        """A rig's readings over the last hour (:mod:`.live`)."""
        runner = self.runners.get(rig)
        return None if runner is None else list(runner.live.trend.points)

    def lines(self, rig: str) -> dict[str, Any] | None:
        """A rig's latest line profiles and isotherm areas (:meth:`.live.LiveView.lines`)."""
        runner = self.runners.get(rig)
        return None if runner is None else runner.live.lines()
