"""The monitor: every rig of a config supervised (:mod:`.supervisor`), their events written,
evidenced and published, the storage kept bounded, health told over HTTP and to systemd.

Every event goes the same way (:meth:`Monitor.emit`): a raising event gets its clip first
(:mod:`.evidence`), then its row in the event store (written before it is published), then the
broker's outbox, then a log line. An event the store cannot take (a full disk) is published
from memory, kept in memory until the store takes it again, and raises a ``storage_fault``:
measuring and alarming go on.

The monitor's clock (:data:`TICK_S`) watches each rig: no new frame for its ``stall_s``
(longer while its shutter closes), or the same frame again and again, is a stall (the rig's
source is closed, recovered and reopened) and a ``sensor_fault``; it also sends systemd its
watchdog, publishes the rigs' status, and sweeps the storage every :data:`SWEEP_S`.
"""

from __future__ import annotations

import json
import sqlite3
import threading
import time
from collections import Counter, deque
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from .. import __version__
from ..alarms import RAISED, event_line
from ..io.measurements import jsonable
from ..pipeline import FusedFrame
from .config import MONITOR, MonitorConfig, RigConfig
from .evidence import Evidence
from .failsafe import SENSOR_FAULT, STORAGE_FAULT, Fault
from .homeassistant import RigEntities
from .live import Picture
from .opcua import OpcUaServer
from .publish import MonitorPublisher
from .rig import RigSink, quantiles
from .storage import CLIPS, Retention, free_bytes
from .store import EventStore, counts_by_rig
from .supervisor import AckRefusedError, ClipNotReadyError, RigRunner
from .systemd import notify, watchdog_interval_s

TICK_S = 0.25
SWEEP_S = 30.0
STATUS_EVERY_S = 10.0
STORE_NAME = "events.sqlite"


def utc_of(time_s: float) -> str:
    """A Unix time as ISO 8601 UTC with milliseconds."""
    return datetime.fromtimestamp(time_s, timezone.utc).isoformat(timespec="milliseconds")


EVIDENCE_FILES = {"snapshot.png": "overlay.png", "clip.zip": "clip.zarr", "cloud.ply": "frame.ply"}
"""An event's evidence by the name the API gives it: its file in the event's clip folder."""


class Monitor:
    """The monitor of ``config`` (module docstring); ``log``: one line each of what happens.
    ``start`` and ``stop`` it; ``reload`` a new config while it runs."""

    def __init__(self, config: MonitorConfig, log: Callable[[str], None] = print) -> None:
        self.config, self.log = config, log
        self.started_mono = time.monotonic()
        self.started_utc = utc_of(time.time())
        self.store = EventStore(config.storage.path / STORE_NAME)
        self.backlog: list[dict[str, Any]] = []  # events the store could not take yet
        self.event_counts: Counter[tuple[str, str]] = Counter()
        self.latency_s: dict[str, deque[float]] = {
            "event_row": deque(maxlen=1000),
            "broker": deque(maxlen=1000),
        }
        self._captured: dict[int, float] = {}  # event id -> its frame's capture time (Unix s)
        self._lock = threading.RLock()
        self._storage_fault = Fault(STORAGE_FAULT, "disk")
        self._storage_lines: list[str] = []
        self._build(config)

    # -- parts ---------------------------------------------------------------------------------

    def _build(self, config: MonitorConfig) -> None:
        """The parts a config makes (not started)."""
        self.config = config
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self.http: Any = None
        s = config.storage
        self.evidence = Evidence(
            s.path / CLIPS, s.pre_s, s.post_s, s.clip_max_s, self.storage_problem, self.log
        )
        self.runners = {rig.name: self._runner(rig) for rig in config.rigs}
        self.retention = Retention(s, self._busy, self.store.clip_deleted)
        self.publisher = self._publisher()
        self.opcua = self._opcua()

    def _opcua(self) -> OpcUaServer | None:
        """The OPC UA server for the config and rigs now (None: none asked for)."""
        if self.config.opcua is None:
            return None
        return OpcUaServer(self.config.opcua, self.entities(), self.config.storage.path, self.log)

    def _publisher(self) -> MonitorPublisher | None:
        """The broker's part for the config and rigs now (None: no broker)."""
        if self.config.mqtt is None:
            return None
        return MonitorPublisher(
            self.config.mqtt,
            self.store,
            self.entities(),
            self.acknowledge,
            self._published,
            self.picture,
            self.log,
        )

    def entities(self) -> list[RigEntities]:
        """What each rig shows a plant's systems: its ROIs and alarm rules."""
        return [
            RigEntities(
                r.name,
                r.config.location,
                [roi.name for roi in r.settings.rois],
                [a.name for a in r.settings.alarms],
            )
            for r in self.runners.values()
        ]

    def _start_outputs(self) -> None:
        started: list[Any] = []
        try:
            self._start_publisher()
            started.append(self.publisher)
            if self.config.http.listen is not None:
                from .http import HttpServer

                self.http = HttpServer(self, self.config.http)
                self.http.start()
                started.append(self.http)
                self.log(f"monitor: HTTP on {self.http.url}")
            if self.opcua is not None:
                self.opcua.start()
                started.append(self.opcua)
                self.log(f"monitor: OPC UA on {self.config.opcua.endpoint}")  # type: ignore[union-attr]
        except BaseException:
            for part in reversed(started):
                if part is not None:
                    part.stop()
            self.publisher, self.http, self.opcua = None, None, None
            raise

    def _start_publisher(self) -> None:
        """Connect to the broker and tell it every rig's alarm states."""
        if self.publisher is None:
            return
        self.publisher.start()
        for runner in self.runners.values():
            self._alarm_states(runner)

    def _alarm_states(self, runner: RigRunner) -> None:
        if self.publisher is not None:
            raised = {a["rule"] for a in runner.raised()}
            states = {a.name: "ON" if a.name in raised else "OFF" for a in runner.settings.alarms}
            self.publisher.alarm_states(runner.name, states)

    def _runner(self, rig: RigConfig, config: MonitorConfig | None = None) -> RigRunner:
        c = config or self.config
        return RigRunner(
            rig,
            c.storage,
            c.failsafe,
            self.evidence,
            self.emit,
            self.measured,
            self.log,
            self.storage_problem,
        )

    def measured(self, sink: RigSink, fused: FusedFrame) -> None:
        """A rig's fused frame: its summary to the broker, its readings to OPC UA (each at
        its rate)."""
        if self.publisher is not None:
            self.publisher.measurement(sink.name, fused)
        if self.opcua is not None:
            self.opcua.measured(sink.name, fused)

    def _busy(self) -> set[Any]:
        busy = self.evidence.active_folders()
        for r in self.runners.values():
            if r.sink.continuous is not None:
                busy |= r.sink.continuous.active
        return busy

    def start(self) -> None:
        """Start every part: the broker, the HTTP and OPC UA servers first (each may refuse
        with one InputError line: what had started is stopped, nothing else starts), then the
        rigs and the clock."""
        self._start_outputs()
        for runner in self.runners.values():
            runner.start()
        for target, name in ((self._clock, "monitor clock"), (self._sweeper, "storage")):
            thread = threading.Thread(target=target, name=name, daemon=True)
            thread.start()
            self._threads.append(thread)
        self.log(
            f"monitor: watching {len(self.runners)} rigs ({', '.join(self.runners)}), "
            f"storage {self.config.storage.path}"
        )

    def stop(self, reason: str = "stopped") -> None:
        """Stop the rigs, finish the clips and recordings, say so to the broker, close."""
        self._stop_parts(reason)
        self._flush_backlog()
        if self.backlog:  # a disk still full: the log keeps them
            self.log(
                f"storage: {len(self.backlog)} events could not be written to "
                f"{self.store.path}; here they are, one JSON line each:"
            )
            for event in self.backlog:
                self.log(json.dumps(jsonable(event)))
        self.store.close()

    def _stop_parts(self, reason: str) -> None:
        """Everything but the event store stopped (see :meth:`stop`)."""
        self._stop.set()
        for runner in self.runners.values():
            runner.stop()
        for thread in self._threads:
            thread.join(5.0)
        self.evidence.close()
        for runner in self.runners.values():
            if runner.sink.continuous is not None:
                runner.sink.continuous.join()
        if self.publisher is not None:
            self.publisher.stop(reason)
        if self.http is not None:
            self.http.stop()
        if self.opcua is not None:
            self.opcua.stop()

    def reload(self, config: MonitorConfig) -> None:
        """Apply a new config while running: a rig changed (its entry or its settings
        file's content), added or removed is restarted, added or stopped on its own; any
        other change (storage, http, mqtt, failsafe) restarts every part. The event store
        stays open."""
        old = self.config
        same_rest = old.model_copy(update={"rigs": []}) == config.model_copy(update={"rigs": []})
        if not same_rest:
            self.log("monitor: reloading every part (storage, http, mqtt or failsafe changed)")
            self._restart(config)
            return
        keep = {r.name: r for r in config.rigs if self._unchanged(r)}
        for name, runner in list(self.runners.items()):
            if name not in keep:
                runner.stop()
                del self.runners[name]
                self.log(f"{name}: stopped (reload)")
        for rig in config.rigs:
            if rig.name not in self.runners:
                runner = self._runner(rig, config)
                self.runners[rig.name] = runner
                runner.start()
                self.log(f"{rig.name}: started (reload)")
        self.config = config
        if self.publisher is not None and self.publisher.entities != self.entities():
            self.publisher.stop("reloading")
            self.publisher = self._publisher()
            self._start_publisher()
        if self.opcua is not None and self.opcua.rigs != self.entities():
            self.opcua.stop()
            self.opcua = self._opcua()
            self.opcua.start()  # type: ignore[union-attr]

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
        """Every part stopped and started again from ``config``; if it cannot start (a port
        taken, a broker away), the old config is started again and the error raised."""
        old = self.config
        self._stop_parts("reloading")
        if config.storage.path != old.storage.path:
            self.store.close()
            self.store = EventStore(config.storage.path / STORE_NAME)
        try:
            self._build(config)
            self.start()
        except BaseException:
            self._stop_parts("reloading")
            if config.storage.path != old.storage.path:
                self.store.close()
                self.store = EventStore(old.storage.path / STORE_NAME)
            self._build(old)
            self.start()
            raise

    # -- events --------------------------------------------------------------------------------

    def emit(self, sink: RigSink, events: list[dict[str, Any]], fused: FusedFrame | None) -> None:
        """A rig's events (module docstring): clip, row, outbox, line; then the picture of a
        new clip (the slow part, after the alarm is out)."""
        runner = self.runners.get(sink.name)
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
            if drawn is not None and fused is not None:
                fixed = runner.settings.viewer.fixed_range_c if runner else None
                self.evidence.draw(fused, drawn, event, fixed)
        if runner is not None:
            self._alarm_states(runner)
            if self.opcua is not None:
                raised = {a["rule"] for a in runner.raised()}
                for event in events:
                    rule = event["rule"]
                    self.opcua.event({**event, "rig": sink.name},
                                     None if rule == SENSOR_FAULT else rule in raised)  # fmt: skip

    def record(
        self, event: dict[str, Any], captured_s: float | None = None, unix_time: bool = True
    ) -> None:
        """Write, publish and tell one event (with ``rig``); ``captured_s``: its frame's
        capture time (Unix s), for the latency figures; ``unix_time``: its ``time_s`` is a
        Unix time (a rig on a live clock; else it is stamped with now)."""
        time_s = event.get("time_s")
        event["time_utc"] = utc_of(time_s if unix_time and time_s else time.time())
        event["state"] = event["event"]  # the lifecycle's word for it, as the store's column
        why = None
        with self._lock:
            self.event_counts[(event["rig"], event["event"])] += 1
            self._flush_backlog()
            try:
                event["id"] = self.store.add(event, outbox=self.publisher is not None)
            except sqlite3.Error as exc:
                self.backlog.append(event)
                why = (
                    f"event {event['rig']} {event['rule']} not written to {self.store.path} "
                    f"({exc}): kept in memory until it can be"
                )
            else:
                if captured_s is not None:
                    self.latency_s["event_row"].append(time.time() - captured_s)
                    self._captured[event["id"]] = captured_s
        if why is not None:
            self.storage_problem(why)
        if self.publisher is not None:
            if why is None:
                self.publisher.wake()
            else:
                self.publisher.publish_direct(event)
        self.log(f"{event['rig']}: {event_line(event)}")

    def _flush_backlog(self) -> None:
        """Write the events the store could not take, in order, while it takes them."""
        with self._lock:
            while self.backlog:
                try:
                    self.backlog[0]["id"] = self.store.add(self.backlog[0])
                except sqlite3.Error:
                    return
                self.backlog.pop(0)

    def _published(self, event: dict[str, Any]) -> None:
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

    def storage_problem(self, line: str) -> None:
        """Something could not be kept: a ``storage_fault`` (raised once; cleared by a sweep
        with nothing new to tell and space enough)."""
        self.log(f"storage: {line}")
        with self._lock:
            self._storage_lines.append(line)
            event = self._storage_fault.update(time.time(), True, line)
        if event is not None:
            self.record({**event, "rig": MONITOR})

    # -- the clock -----------------------------------------------------------------------------

    def _clock(self) -> None:
        watchdog_s = watchdog_interval_s()
        last = time.monotonic()
        last_dog = last_status = last_opcua = float("-inf")
        last_told: dict[str, tuple[str, str]] = {}  # each rig's state and health, as published
        while not self._stop.wait(TICK_S):
            now = time.monotonic()
            dt, last = now - last, now
            for runner in list(self.runners.values()):
                self._watch(runner, now, dt)
            alive = all(r.alive for r in self.runners.values())
            if watchdog_s is not None and now - last_dog >= watchdog_s and alive:
                notify("WATCHDOG=1")
                last_dog = now
            if self.opcua is not None:
                self.opcua.flush()
                if now - last_opcua >= 1.0:
                    last_opcua = now
                    for r in self.status()["rigs"]:
                        self.opcua.status(r)
            if self.publisher is not None:
                stale = set(self.stale_rigs())
                told = {
                    r.name: (r.status.state, self._health(r, stale)) for r in self.runners.values()
                }
                if now - last_status >= STATUS_EVERY_S or told != last_told:
                    last_status, last_told = now, told
                    for r in self.status()["rigs"]:
                        self.publisher.rig_status(r["name"], r)

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

    def _sweeper(self) -> None:
        while True:
            self.sweep()
            if self._stop.wait(SWEEP_S):
                return

    def sweep(self) -> None:
        """Apply the storage rule, write what the store could not take; clear the storage
        fault when nothing new went wrong and space is enough."""
        try:
            low = self.retention.sweep()
        except OSError as exc:
            low = f"{self.config.storage.path}: cannot sweep ({exc.strerror or exc})"
        self._flush_backlog()
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
        return {
            "version": __version__,
            "started_utc": self.started_utc,
            "uptime_s": round(now - self.started_mono, 1),
            "rigs": rigs,
            "storage": {
                "path": str(path),
                "free_bytes": free_bytes(path),
                "event_store_bytes": self.store.size_bytes(),
                "events_not_stored": len(self.backlog),
                "pictures_skipped": self.evidence.pictures_skipped,
                "deleted": dict(self.retention.deleted),
                "fault": self._storage_fault.raised,
            },
            "mqtt": None
            if self.publisher is None
            else {
                "broker": self.publisher.target.where,
                "prefix": self.publisher.target.prefix,
                "sent": self.publisher.sent,
                "unacknowledged": self.publisher.connection.pending,
            },
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

    def evidence_of(self, event: dict[str, Any]) -> list[str]:
        """What :meth:`evidence_file` may give for an event: all of it while its clip is
        kept, nothing otherwise."""
        return list(EVIDENCE_FILES) if event.get("clip") and event.get("clip_kept", True) else []

    def picture(self, rig: str, what: str, width: int | None = None) -> Picture | None:
        """A rig's latest ``overlay`` (JPEG) or ``thermal`` (PNG) picture (:mod:`.live`)."""
        runner = self.runners.get(rig)
        return None if runner is None else runner.live.picture(what, width)

    def trend(self, rig: str) -> list[dict[str, Any]] | None:
        """A rig's readings over the last hour (:mod:`.live`)."""
        runner = self.runners.get(rig)
        return None if runner is None else list(runner.live.trend.points)
