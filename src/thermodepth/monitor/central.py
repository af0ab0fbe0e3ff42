"""One screen for many monitors: ``thermodepth dashboard --mqtt URL`` serves the monitor's
pages and API (:mod:`.http`) for every rig that publishes under the URL's prefix, from what
the monitors publish (:mod:`.publish`) and nothing of their disks.

A rig is named by its topic path under the prefix: a monitor publishing under
``plant/edge1`` with a rig ``line3``, seen by a dashboard of ``mqtt://broker/plant``, gives
the rig ``edge1/line3`` (a monitor publishing under ``plant`` itself: ``line3``). What each
topic gives:

- ``RIG/status`` (retained, every 10 s): the rig's figures, as its monitor's ``/api/status``;
- ``RIG/measurements`` (1 Hz by default): its hottest reading and ROIs, its freshness, and its
  trend (:class:`~.live.Trend`);
- ``RIG/alarms``: its events, kept in the dashboard's own event store (each once, by its
  monitor's id: delivery is at least once), each raising one with the rig's latest overlay
  as its snapshot (or its first, for a rig not yet pictured); the active alarms follow them
  at once (the status may be 10 s old);
- ``RIG/events/recent`` (retained): its latest events, so that a dashboard started later
  still lists the events behind the alarms it shows active;
- ``RIG/snapshot/overlay.jpg`` and ``thermal.png``: its live pictures;
- ``EDGE/monitor/status``: whether the monitor runs: a rig whose monitor has **stopped** (said
  so on its way out) shows as stopped at once, is not stale and cannot be acknowledged; one
  whose monitor **died** (the broker's last will) is stale;
- ``RIG/ack/result``: the answer to an acknowledgement sent on ``RIG/ack``.

A rig is stale when its status says so, its monitor died, or nothing came from it for
:data:`SILENT_S`. An empty retained message on ``RIG/status`` (or ``EDGE/monitor/status``)
retires the rig (every rig of that monitor) from every dashboard: :meth:`CentralDashboard.retire`
sends them, for a monitor that is gone for good (``POST /api/retire``).
"""

from __future__ import annotations

import json
import os
import queue
import sqlite3
import tempfile
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .. import __version__
from ..alarms import RAISED
from ..pipeline import MqttSettings
from ..sinks.mqtt import MqttConnection, MqttTarget, default_client_id
from .config import MONITOR
from .live import Picture, Trend, VideoFrame, encode
from .logs import logger
from .outputs.mqtt import SNAPSHOTS, STATUS_EVERY_S
from .storage import free_bytes
from .store import EventStore, counts_by_rig
from .supervisor import AckRefusedError

SILENT_S = 2.5 * STATUS_EVERY_S
ACK_WAIT_S = 5.0
QUIET_KEPT = 10_000
"""Events known only from the retained recent lists, remembered for their live copy."""
EVENT_WINS_S = 2.0  # an event newer than this outranks a status published before it
RECENT = "events/recent"
LEAVES = ("status", "measurements", "alarms", RECENT, "ack/result",
          *(f"snapshot/{k}" for k in SNAPSHOTS))  # fmt: skip
RETAINED = ("status", "alarm_states", RECENT, *(f"snapshot/{k}" for k in SNAPSHOTS))
"""What a monitor keeps retained for each rig: emptied when the rig is retired."""


@dataclass
class RemoteRig:
    """What the dashboard knows of one rig (monotonic times)."""

    status: dict[str, Any] | None = None
    heard_s: float = float("-inf")
    measured_s: float = float("-inf")
    measured: dict[str, Any] | None = None
    active: dict[str, dict[str, Any]] = field(default_factory=dict)
    changed_s: dict[str, float] = field(default_factory=dict)  # rule -> its last event's time
    pictures: dict[str, bytes] = field(default_factory=dict)
    trend: Trend = field(default_factory=Trend)
    unpictured: list[int] = field(default_factory=list)  # raised before its first overlay


def _decoded(data: bytes) -> NDArray[np.uint8] | None:
    """A JPEG or PNG as BGR uint8 (None: not a picture)."""
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    return None if img is None else np.asarray(img, dtype=np.uint8)


def split_topic(prefix: str, topic: str) -> tuple[str, str] | None:
    """(rig, leaf) of a topic under ``prefix`` (None: not one of :data:`LEAVES`)."""
    rel = topic.removeprefix(f"{prefix}/")
    if rel == topic:
        return None
    for leaf in LEAVES:
        if rel.endswith(f"/{leaf}"):
            rig = rel[: -len(leaf) - 1]
            return (rig, leaf) if rig else None
    return None


def monitor_of(rig: str) -> str:
    """The monitor's own name beside a rig's (``edge1/line3`` -> ``edge1/monitor``)."""
    parent = rig.rpartition("/")[0]
    return f"{parent}/{MONITOR}" if parent else MONITOR


class CentralDashboard:
    """The rigs seen on a broker (module docstring), answering what :mod:`.http` asks of a
    monitor. ``url``: ``mqtt://[USER@]HOST[:PORT]/PREFIX``; ``folder``: its event store and
    event snapshots; ``settings``: the broker's (password file, CA, timeouts)."""

    def __init__(self, url: str, folder: Path, settings: MqttSettings) -> None:
        self.target = MqttTarget.parse(url)
        self.prefix, self.log = self.target.prefix, logger("central")
        self.folder = folder
        (folder / "snapshots").mkdir(parents=True, exist_ok=True)
        self.store = EventStore(folder / "events.sqlite")
        self.events, self.event = self.store.events, self.store.event  # as /api/events asks
        self.started_s = time.monotonic()
        self.started_utc = datetime.now(timezone.utc).isoformat(timespec="seconds")
        self.rigs: dict[str, RemoteRig] = {}
        self.monitors: dict[str, str] = {}
        self.event_counts: Counter[tuple[str, str]] = Counter()
        self.acks_sent = 0
        self._lock = threading.Lock()
        self._videos: dict[tuple[str, str], tuple[bytes, VideoFrame]] = {}  # decoded once
        self._answers: dict[str, queue.Queue[dict[str, Any]]] = {}
        self._quiet: dict[str, int] = {}  # events known from a recent list only: their ids
        self._ack_locks: dict[str, threading.Lock] = {}
        will = (f"{self.prefix}/dashboard/status", json.dumps({"state": "died"}))
        client_id = settings.client_id or f"{default_client_id()}-dashboard"
        self.connection = MqttConnection(self.target, settings, self.log.warning, will, client_id)

    # -- the broker ----------------------------------------------------------------------------

    def start(self) -> None:
        """Connect (an InputError line when the broker refuses; a warning when it is away:
        the pages show every rig stale until it is back) and listen under the prefix."""
        self.connection.connect(required=False)
        self.connection.subscribe(f"{self.prefix}/#", self._message)
        self._say("running")

    def stop(self) -> None:
        self._say("stopped")
        self.connection.close(wait_s=2.0)
        self.store.close()

    def _say(self, state: str) -> None:
        payload = json.dumps({"state": state, "version": __version__})
        self.connection.publish(f"{self.prefix}/dashboard/status", payload, 1, True)

    def _message(self, topic: str, payload: bytes) -> None:
        where = split_topic(self.prefix, topic)
        if where is None:
            return
        rig, leaf = where
        if not payload:
            if leaf == "status":  # retired: a rig, or every rig of a monitor
                self._forget(rig)
            return
        if leaf.startswith("snapshot/"):
            r = self._rig(rig)
            with self._lock:
                r.pictures[leaf.removeprefix("snapshot/")] = bytes(payload)
                unpictured: list[int] = []
                if leaf.endswith(".jpg"):
                    unpictured, r.unpictured = r.unpictured, []
            for event_id in unpictured:
                self._keep_snapshot(event_id, bytes(payload))
            return
        try:
            message = json.loads(payload)
        except ValueError:
            self.log.warning("MQTT %s: not JSON, ignored", topic)
            return
        if leaf == RECENT and isinstance(message, list):
            for event in message:
                if isinstance(event, dict):
                    self._event(rig, event, live=False)
            return
        if not isinstance(message, dict):
            return
        if leaf == "status" and rig.rpartition("/")[2] == MONITOR:
            with self._lock:
                self.monitors[rig] = str(message.get("state"))
        elif leaf == "status" and "health" in message:
            self._status(rig, message)
        elif leaf == "measurements":
            self._measured(rig, message)
        elif leaf == "alarms":
            self._event(rig, message)
        elif leaf == "ack/result":
            waiting = self._answers.get(rig)
            if waiting is not None:
                waiting.put(message)

    def _rig(self, rig: str) -> RemoteRig:
        with self._lock:
            found = self.rigs.setdefault(rig, RemoteRig())
        found.heard_s = time.monotonic()
        return found

    def _forget(self, name: str) -> None:
        """A rig retired, or with ``EDGE/monitor``, that monitor and all its rigs."""
        with self._lock:
            if name.rpartition("/")[2] == MONITOR:
                self.monitors.pop(name, None)
                gone = [r for r in self.rigs if monitor_of(r) == name]
            else:
                gone = [name] if name in self.rigs else []
            for rig in gone:
                del self.rigs[rig]
                for view, _ in SNAPSHOTS.values():  # its decoded pictures go with it
                    self._videos.pop((rig, view), None)
        for rig in gone:
            self.log.info("%s: retired", rig)

    def monitor_state(self, rig: str) -> str:
        """The state its monitor last said: ``running``, ``stopped``, ``died``, ...
        (``running`` when it has not said)."""
        with self._lock:
            return self.monitors.get(monitor_of(rig), "running")

    def retire(self, name: str) -> list[str]:
        """Retire a rig (``edge1/line3``) or a monitor and its rigs (``edge1``, or
        ``monitor`` for one publishing under the prefix itself) from every dashboard: its
        retained messages emptied on the broker. Only what is not running can go
        (AckRefusedError 409; 404: unknown). Returns the rigs retired."""
        monitor = name if name.rpartition("/")[2] == MONITOR else f"{name}/{MONITOR}"
        with self._lock:
            of_monitor = [r for r in self.rigs if monitor_of(r) == monitor]
            rigs = of_monitor or ([name] if name in self.rigs else [])
            whole = bool(of_monitor) or monitor in self.monitors
        if not rigs and not whole:
            raise AckRefusedError(404, f"no rig or monitor {name!r}")
        if not self.connection.connected:
            raise AckRefusedError(409, "not connected to the broker: whether it runs is not known")
        live = [r for r in rigs if r not in self.stale_rigs() and not self._stopped(r)]
        if live:
            raise AckRefusedError(409, f"still running: {', '.join(live)}")
        for rig in rigs:
            for leaf in RETAINED:
                self.connection.publish(f"{self.prefix}/{rig}/{leaf}", b"", 1, True)
        if whole:
            self.connection.publish(f"{self.prefix}/{monitor}/status", b"", 1, True)
            self._forget(monitor)
        for rig in rigs:
            self._forget(rig)
        return rigs

    def _stopped(self, rig: str) -> bool:
        return self.monitor_state(rig) not in ("running", "died")

    def _status(self, rig: str, status: dict[str, Any]) -> None:
        r = self._rig(rig)
        now = time.monotonic()
        with self._lock:
            r.status = status
            said = {a["rule"]: a for a in status.get("active_alarms", [])}
            for rule in set(said) | set(r.active):
                if now - r.changed_s.get(rule, float("-inf")) < EVENT_WINS_S:
                    continue
                if rule in said:
                    r.active[rule] = said[rule]
                else:
                    r.active.pop(rule, None)

    def _measured(self, rig: str, m: dict[str, Any]) -> None:
        r = self._rig(rig)
        r.measured, r.measured_s = m, time.monotonic()
        hot = m.get("hottest")
        rois = m.get("rois") or {}
        r.trend.add(
            m.get("time_s", 0.0),
            None if hot is None else hot.get("max_c"),
            {k: (v.get("max_c") if v.get("n") else None) for k, v in rois.items()},
        )

    def _event(self, rig: str, event: dict[str, Any], live: bool = True) -> None:
        """An event of a rig, kept once; a ``live`` one (not from the retained recent list)
        also moves the rig's active alarms and gets the rig's overlay as its snapshot."""
        r = self._rig(rig)
        kind, rule = event.get("event"), event.get("rule")
        if not isinstance(kind, str) or not isinstance(rule, str):
            self.log.warning("MQTT %s/%s/alarms: not an event, ignored", self.prefix, rig)
            return
        copy = {k: v for k, v in event.items() if k not in ("id", "clip_kept")}
        copy.update(rig=rig, origin=f"{rig}#{event.get('id', time.time_ns())}")
        copy.setdefault("level", "alarm")
        copy.setdefault("time_utc", datetime.now(timezone.utc).isoformat())
        try:
            event_id = self.store.add(copy)
        except sqlite3.IntegrityError:  # had it already: delivered again, or first from the
            with self._lock:  # recent list (then this live copy still does what it does)
                event_id = self._quiet.pop(copy["origin"], -1)
            if not live or event_id < 0:
                return
        else:
            with self._lock:
                self.event_counts[rig, kind] += 1
                if not live:
                    self._quiet[copy["origin"]] = event_id
                    while len(self._quiet) > QUIET_KEPT:
                        self._quiet.pop(next(iter(self._quiet)))
                    return
        with self._lock:
            r.changed_s[rule] = time.monotonic()
            if kind in RAISED:
                r.active[rule] = {"rule": rule, "level": copy["level"]}
                if copy.get("fault"):
                    r.active[rule]["fault"] = copy["fault"]
            elif kind == "acknowledged" and rule in r.active:
                r.active[rule]["acknowledged"] = {
                    "by": copy.get("by"),
                    "at_utc": copy.get("at_utc"),
                }
            elif kind == "clear":
                r.active.pop(rule, None)
            overlay = r.pictures.get("overlay.jpg")
            if kind in RAISED and overlay is None:
                r.unpictured.append(event_id)  # the rig's first overlay will be its snapshot
        if kind in RAISED and overlay is not None:
            self._keep_snapshot(event_id, overlay)

    def _keep_snapshot(self, event_id: int, jpeg: bytes) -> None:
        """The rig's overlay when its event came, as the event's PNG (renamed into place)."""
        img = _decoded(jpeg)
        if img is None:
            return
        fd, tmp = tempfile.mkstemp(dir=self.folder / "snapshots", suffix=".part")
        with os.fdopen(fd, "wb") as f:
            f.write(encode(img, "png"))
        os.replace(tmp, self._snapshot_path(event_id))

    def _snapshot_path(self, event_id: int) -> Path:
        return self.folder / "snapshots" / f"{int(event_id)}.png"

    # -- what the pages ask --------------------------------------------------------------------

    def stale_rigs(self) -> list[str]:
        """The rigs without fresh data: their status says so, their monitor died, or nothing
        came from them for SILENT_S; a rig whose monitor stopped on purpose is stopped, not
        stale."""
        now = time.monotonic()
        with self._lock:
            return [
                name
                for name, r in sorted(self.rigs.items())
                if r.status is not None
                and self.monitors.get(monitor_of(name), "running") in ("running", "died")
                and (
                    r.status.get("health") == "stale"
                    or self.monitors.get(monitor_of(name), "running") == "died"
                    or now - r.heard_s > SILENT_S
                    or not self.connection.connected
                )
            ]

    def unhealthy_workers(self) -> list[str]:
        """None: the dashboard's only loop is the broker client's own."""
        return []

    def status(self) -> dict[str, Any]:
        """``/api/status`` for every rig heard of (those with a status), with the dashboard's
        own storage and broker, and each monitor's state."""
        now = time.monotonic()
        stale = set(self.stale_rigs())
        rigs = []
        with self._lock:
            for name, r in sorted(self.rigs.items()):
                if r.status is None:
                    continue
                d = {**r.status, "name": name, "monitor": monitor_of(name)}
                if r.measured is not None:
                    m = r.measured
                    d["hottest"] = m.get("hottest")
                    d["rois"] = m.get("rois") or {}
                    d["vox_temp_c"] = m.get("vox_temp_c")
                    d["last_frame_age_s"] = round(now - r.measured_s, 2)
                d["active_alarms"] = [dict(a) for a in r.active.values()]
                d["up"] = int(name not in stale)
                d["health"] = "stale" if name in stale else r.status.get("health", "ok")
                said = self.monitors.get(monitor_of(name), "running")
                if said != "running":  # what it last told is no longer so
                    d["state"], d["up"], d["fps"] = said, 0, 0.0
                    d["health"] = "stale" if name in stale else said
                    d["last_frame_age_s"] = round(now - max(r.measured_s, r.heard_s), 2)
                rigs.append(d)
            monitors = dict(sorted(self.monitors.items()))
            counts = dict(self.event_counts)
        mqtt = {
            "broker": self.target.where,
            "prefix": self.prefix,
            "connected": self.connection.connected,
            "sent": self.acks_sent,
            "unacknowledged": self.connection.pending,
        }
        return {
            "version": __version__,
            "started_utc": self.started_utc,
            "uptime_s": round(now - self.started_s, 1),
            "central": True,
            "rigs": rigs,
            "monitors": monitors,
            "storage": {
                "path": str(self.folder),
                "free_bytes": free_bytes(self.folder),
                "event_store_bytes": self.store.size_bytes(),
                "events_not_stored": 0,
                "pictures_skipped": 0,
                "deleted": {"continuous": 0, "clips": 0},
                "fault": False,
            },
            "mqtt": mqtt,
            "outputs": {"mqtt": mqtt},
            "workers": [],
            "event_counts": counts_by_rig(counts),
            "latency_s": {},
        }

    def evidence_of(self, event: dict[str, Any]) -> list[str]:
        """The snapshot, when one was kept: the clip and cloud stay on the monitor's disk."""
        return ["snapshot.png"] if self._snapshot_path(event["id"]).exists() else []

    def report_file(self, name: str) -> Path | None:
        """A central dashboard keeps no inspection reports (each monitor keeps its own)."""
        return None

    def evidence_file(self, event_id: int, what: str) -> Path | None:
        path = self._snapshot_path(event_id)
        return path if what == "snapshot.png" and path.exists() else None

    def picture(self, rig: str, what: str, width: int | None = None) -> Picture | None:
        """A rig's latest published ``overlay`` (JPEG) or ``thermal`` (PNG) picture, made
        smaller when ``width`` asks (its frame's time is not published: None)."""
        leaf = next(k for k, (w, _) in SNAPSHOTS.items() if w == what)
        with self._lock:
            r = self.rigs.get(rig)
            data = None if r is None else r.pictures.get(leaf)
        if data is None:
            return None
        img = None if width is None else _decoded(data)
        if img is not None and width is not None and width < img.shape[1]:
            data = encode(img, "jpeg" if leaf.endswith(".jpg") else "png", width)
        return Picture(data, None)

    def video(self, rig: str, view: str, hz: float) -> VideoFrame | None:
        """A rig's latest published ``overlay`` or ``thermal`` picture for a video stream (as
        published: at ``mqtt.snapshots_hz``, without the monitor's title and colour scale),
        decoded once per picture."""
        leaf = next(k for k, (w, _) in SNAPSHOTS.items() if w == view)
        with self._lock:
            r = self.rigs.get(rig)
            data = None if r is None else r.pictures.get(leaf)
            kept = self._videos.get((rig, view))
        if data is None:
            return None
        if kept is not None and kept[0] is data:
            return kept[1]
        img = _decoded(data)
        if img is None:
            return None
        made = VideoFrame(img, None)
        with self._lock:
            self._videos[(rig, view)] = (data, made)
        return made

    def trend(self, rig: str) -> list[dict[str, Any]] | None:
        with self._lock:
            r = self.rigs.get(rig)
            return None if r is None else list(r.trend.points)

    def lines(self, rig: str) -> dict[str, Any] | None:
        """Profiles are not published (MQTT carries each line's figures): none here."""
        return None

    def acknowledge(self, rig: str, rule: str, by: str) -> list[dict[str, Any]]:
        """Acknowledge through the rig's command topic and wait for its monitor's answer:
        its events, or AckRefusedError (404 no such rig, 409 refused by the monitor or its
        monitor not running, 504 no answer within ACK_WAIT_S)."""
        with self._lock:
            if self.rigs.get(rig) is None or self.rigs[rig].status is None:
                raise AckRefusedError(404, f"no rig {rig!r}")
            said = self.monitors.get(monitor_of(rig), "running")
            if said != "running":
                raise AckRefusedError(409, f"{rig}: its monitor has {said}: nobody to ask")
            one_at_a_time = self._ack_locks.setdefault(rig, threading.Lock())
        with one_at_a_time:  # the answers of a rig come on one topic
            answers: queue.Queue[dict[str, Any]] = queue.Queue()
            self._answers[rig] = answers
            try:
                payload = json.dumps({"rule": rule, "by": by})
                self.connection.publish(f"{self.prefix}/{rig}/ack", payload, 1)
                self.acks_sent += 1
                reply = answers.get(timeout=ACK_WAIT_S)
            except queue.Empty:
                raise AckRefusedError(
                    504, f"{rig}: its monitor did not answer within {ACK_WAIT_S:g} s"
                ) from None
            finally:
                self._answers.pop(rig, None)
        if not reply.get("ok"):
            raise AckRefusedError(409, str(reply.get("error", "refused")))
        return list(reply.get("events", []))
