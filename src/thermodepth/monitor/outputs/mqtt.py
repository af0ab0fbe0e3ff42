"""The monitor on an MQTT broker (paho-mqtt), each rig under its own prefix.

Topics under the URL's prefix ``P`` (``mqtt://broker/plant`` -> ``plant/line1/alarms``):

- ``P/RIG/alarms``: every event of the rig (alarms, escalations, acknowledgements, clears,
  sensor faults) as JSON with its event store ``id``, QoS 1, sent from the event store's
  outbox: kept on disk while the broker is away and across a restart of the monitor (at least
  once: after a restart the broker may get again what it had not acknowledged).
- ``P/RIG/measurements``: a summary of the rig's latest frame, QoS 0, at most
  ``measurements_hz`` a second.
- ``P/RIG/status``: the rig's figures as ``/api/status`` gives them, retained, every
  :data:`STATUS_EVERY_S` and when its state changes.
- ``P/RIG/alarm_states``: ``{"RULE": "ON" or "OFF", ...}``, retained, at start and at every
  event of the rig.
- ``P/RIG/snapshot/overlay.jpg`` and ``P/RIG/snapshot/thermal.png``: the rig's live overlay
  (JPEG, :data:`SNAPSHOT_WIDTH` pixels wide) and thermal image (PNG) as the dashboard draws
  them, raw bytes, retained, QoS 0, at most ``snapshots_hz`` a second (0: none), for a
  central dashboard (``thermodepth dashboard``) that cannot read the monitor's disk.
- ``P/RIG/events/recent``: the rig's latest :data:`RECENT_EVENTS` events (a JSON list,
  oldest first), retained, so that a dashboard started later lists the events behind the
  alarms it shows active.
- ``P/RIG/ack``: acknowledge a raised alarm, ``{"rule": "hot", "by": "jane"}``; the answer on
  ``P/RIG/ack/result`` (``{"ok": true, "events": [...]}`` or ``{"ok": false, "error": ...}``).
- ``P/monitor/alarms``: the monitor's own events (storage faults); ``P/monitor/status``:
  ``{"state": "running"}`` retained while it runs, the way it stopped, and the broker's last
  will ``{"state": "died"}``.
"""

from __future__ import annotations

import json
import threading
import time
from collections import deque
from typing import Any

from ...io.measurements import jsonable
from ...pipeline import FusedFrame
from ...sinks.mqtt import MqttConnection, MqttTarget, default_client_id, measurement_message
from ..config import MONITOR, MqttConfig
from ..logs import logger
from ..supervisor import AckRefusedError
from ..workers import Worker
from .base import Output, OutputContext, RigEntities
from .homeassistant import Discovery

STATUS_EVERY_S = 10.0
SNAPSHOT_WIDTH = 640
SNAPSHOTS = {"overlay.jpg": ("overlay", SNAPSHOT_WIDTH), "thermal.png": ("thermal", None)}
"""A snapshot topic's leaf: the picture (:meth:`~..live.LiveView.picture`) and its width."""
WORKER_LIMIT_S = 30.0
RECENT_EVENTS = 20


class MqttOutput(Output):
    """The monitor's broker connection (module docstring), for the rigs of ``context`` (and
    their Home Assistant discovery when the config asks)."""

    name = "mqtt"
    outbox = True

    def __init__(self, config: MqttConfig, context: OutputContext) -> None:
        self.config, self.context = config, context
        self.store, self.entities = context.store, context.rigs
        self.rigs = [e.name for e in self.entities]
        self.log = logger("mqtt")
        self.target = MqttTarget.parse(config.url)
        will = json.dumps({"state": "died"})
        self.connection = MqttConnection(
            self.target,
            config,
            self.log.warning,
            (self.topic(MONITOR, "status"), will),
            config.client_id or default_client_id(),
        )
        self.sent = 0
        self._sent_to = 0  # the newest outbox id handed to the client
        self._wake = threading.Event()
        self._last_measurement: dict[str, float] = {}
        self._last_status = float("-inf")
        self._told: dict[str, tuple[str, str]] = {}  # each rig's state and health, as published
        self._recent: dict[str, deque[dict[str, Any]]] = {}
        self._announced = False
        self._workers = [Worker("mqtt outbox", self._drain, 1.0, WORKER_LIMIT_S, self.log)]
        if config.snapshots_hz > 0:
            every_s = 1.0 / config.snapshots_hz
            self._workers.append(Worker("mqtt snapshots", self._snapshots, every_s, WORKER_LIMIT_S))

    def topic(self, rig: str, leaf: str) -> str:
        return f"{self.target.prefix}/{rig}/{leaf}"

    def describe(self) -> str:
        return describe(self.config)

    def start(self) -> None:
        """Connect (one InputError line when the broker refuses; one warning when it cannot
        be reached yet: the monitor starts, and the outbox waits) and listen for
        acknowledgements; nothing is published until :meth:`announce`."""
        self.connection.connect(required=False)
        for rig in self.rigs:
            self.connection.subscribe(self.topic(rig, "ack"), self._ack_command)

    def announce(self, raised: dict[str, set[str]]) -> None:
        """The monitor runs: say so, tell every rig's alarm states, publish discovery."""
        self._announced = True
        self._status(MONITOR, {"state": "running", "rigs": self.rigs, "since_utc": utc_now()})
        for rig in self.entities:
            self._alarm_states(rig, raised.get(rig.name, set()))
            recent = self.store.events(RECENT_EVENTS, rig.name)[::-1]
            self._recent[rig.name] = deque(recent, maxlen=RECENT_EVENTS)
            self._publish_recent(rig.name)
        if self.config.homeassistant:
            prefix, where = self.target.prefix, self.config.discovery_prefix
            Discovery(self.connection, prefix, where, self.entities, self.log).start()

    def workers(self) -> list[Worker]:
        return list(self._workers)

    def fits(self, rigs: list[RigEntities]) -> bool:
        return rigs == self.entities

    def _status(self, rig: str, status: dict[str, Any]) -> None:
        payload = json.dumps(jsonable(status))
        self.connection.publish(self.topic(rig, "status"), payload, qos=1, retain=True)

    def _alarm_states(self, rig: RigEntities, raised: set[str]) -> None:
        """Whether each alarm rule of a rig is raised (``ON``) or not (``OFF``), retained."""
        states = {rule: "ON" if rule in raised else "OFF" for rule in rig.rules}
        self.connection.publish(self.topic(rig.name, "alarm_states"), json.dumps(states), 1, True)

    def events(self, rig: str, events: list[dict[str, Any]], raised: set[str]) -> None:
        """The rig's alarm states and latest events (the events themselves go from the
        outbox)."""
        entity = next((e for e in self.entities if e.name == rig), None)
        if entity is None:
            return
        self._alarm_states(entity, raised)
        recent = self._recent.setdefault(rig, deque(maxlen=RECENT_EVENTS))
        recent.extend(e for e in events if "id" in e)
        self._publish_recent(rig)

    def _publish_recent(self, rig: str) -> None:
        payload = json.dumps(jsonable(list(self._recent.get(rig, ()))))
        self.connection.publish(self.topic(rig, "events/recent"), payload, 1, True)

    def tick(self, now_mono: float) -> None:
        """Every rig's figures, retained, every STATUS_EVERY_S and when its state or health
        changes."""
        rigs = self.context.rig_status()
        told = {r["name"]: (r["state"], r["health"]) for r in rigs}
        if now_mono - self._last_status >= STATUS_EVERY_S or told != self._told:
            self._last_status, self._told = now_mono, told
            for r in rigs:
                self._status(r["name"], r)

    def wake(self) -> None:
        self._wake.set()

    def _drain(self, worker: Worker) -> None:
        limit = max(1, self.config.max_queued // 2)
        while not worker.stopping.is_set():
            worker.beat()
            self._wake.wait(1.0)
            self._wake.clear()
            if self.connection.pending >= limit:
                continue  # the broker is away: the rest waits on disk
            for event in self.store.outbox(
                limit - self.connection.pending, self._sent_to, self.name
            ):
                if not self._send(event):
                    break
                self._sent_to = event["id"]

    def _send(self, event: dict[str, Any]) -> bool:
        def acked() -> None:
            if "id" in event:
                self.store.delivered(event["id"], self.name)
            self.context.delivered(event)

        payload = json.dumps(jsonable(event))
        ok = self.connection.publish(self.topic(event["rig"], "alarms"), payload, 1, on_ack=acked)
        self.sent += ok
        return ok

    def _snapshots(self, worker: Worker) -> None:
        every_s = 1.0 / self.config.snapshots_hz
        while not worker.stopping.wait(every_s):
            worker.beat()
            if not self.connection.connected:
                continue  # QoS 0: a picture not sent now is worth nothing later
            for rig in self.rigs:
                for leaf, (what, width) in SNAPSHOTS.items():
                    found = self.context.picture(rig, what, width)
                    if found is not None:
                        topic = self.topic(rig, f"snapshot/{leaf}")
                        self.connection.publish(topic, found.data, 0, True)

    def send_now(self, event: dict[str, Any]) -> None:
        """An event the store could not keep: sent from memory."""
        if not self._send(event):
            self.log.error("MQTT: queue full, event not sent: %s %s", event["rig"], event["rule"])

    def measured(self, rig: str, fused: FusedFrame) -> None:
        """A frame's summary, at most ``measurements_hz`` a second per rig."""
        now = time.monotonic()
        if now - self._last_measurement.get(rig, float("-inf")) < 1 / self.config.measurements_hz:
            return
        self._last_measurement[rig] = now
        payload = json.dumps(jsonable(measurement_message(fused)))
        self.connection.publish(self.topic(rig, "measurements"), payload)

    def _ack_command(self, topic: str, payload: bytes) -> None:
        rig = topic.split("/")[-2]
        try:
            command = json.loads(payload)
        except ValueError:
            command = None
        reply: dict[str, Any]
        if not (
            isinstance(command, dict)
            and isinstance(command.get("rule"), str)
            and isinstance(command.get("by"), str)
            and command["by"].strip()
        ):
            reply = {"ok": False, "error": 'expected {"rule": NAME, "by": WHO}'}
        else:
            try:
                reply = {
                    "ok": True,
                    "events": self.context.acknowledge(rig, command["rule"], command["by"]),
                }
            except AckRefusedError as exc:
                reply = {"ok": False, "error": exc.message}
        if not reply["ok"]:
            self.log.warning("MQTT %s: acknowledgement refused: %s", topic, reply["error"])
        self.connection.publish(self.topic(rig, "ack/result"), json.dumps(jsonable(reply)), 1)

    def status(self) -> dict[str, Any]:
        return {
            "broker": self.target.where,
            "prefix": self.target.prefix,
            "connected": self.connection.connected,
            "sent": self.sent,
            "unacknowledged": self.connection.pending,
        }

    def stop(self, reason: str = "stopped") -> None:
        """Say how the monitor stopped (only if it had said it runs) and disconnect."""
        self._wake.set()
        if self._announced:
            self._status(MONITOR, {"state": reason, "until_utc": utc_now()})
        self.connection.close(wait_s=5.0)


def describe(config: MqttConfig) -> str:
    """The output of an ``mqtt`` section in one line."""
    ha = (
        f"Home Assistant discovery on (under {config.discovery_prefix}/)"
        if config.homeassistant
        else "Home Assistant discovery off"
    )
    snapshots = f"snapshots {config.snapshots_hz:g}/s" if config.snapshots_hz else "no snapshots"
    return f"MQTT {config.url} (readings {config.measurements_hz:g}/s, {snapshots}); {ha}"


def utc_now() -> str:
    from datetime import datetime, timezone

    return datetime.now(timezone.utc).isoformat(timespec="seconds")
