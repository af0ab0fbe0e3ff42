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
from collections.abc import Callable
from typing import Any

from ..io.measurements import jsonable
from ..pipeline import FusedFrame
from ..sinks.mqtt import MqttConnection, MqttTarget, default_client_id, measurement_message
from .config import MONITOR, MqttConfig
from .homeassistant import Discovery, RigEntities
from .live import Picture
from .store import EventStore
from .supervisor import AckRefusedError

STATUS_EVERY_S = 10.0
SNAPSHOT_WIDTH = 640
SNAPSHOTS = {"overlay.jpg": ("overlay", SNAPSHOT_WIDTH), "thermal.png": ("thermal", None)}
"""A snapshot topic's leaf: the picture (:meth:`~.live.LiveView.picture`) and its width."""
Acknowledge = Callable[[str, str, str], list[dict[str, Any]]]
Pictures = Callable[[str, str, int | None], Picture | None]


class MonitorPublisher:
    """The monitor's broker connection (module docstring), for the rigs of ``entities`` (and
    their Home Assistant discovery when the config asks). ``acknowledge(rig, rule, by)``:
    what an acknowledge command does; ``published(event)``: told when the broker has an
    event; ``picture(rig, what, width)``: a rig's live picture, for the snapshots; ``log``:
    one line each of what happens."""

    def __init__(
        self,
        config: MqttConfig,
        store: EventStore,
        entities: list[RigEntities],
        acknowledge: Acknowledge,
        published: Callable[[dict[str, Any]], None],
        picture: Pictures,
        log: Callable[[str], None],
    ) -> None:
        self.config, self.store, self.entities = config, store, entities
        self.rigs = [e.name for e in entities]
        self.acknowledge, self.published, self.log = acknowledge, published, log
        self.picture = picture
        self.target = MqttTarget.parse(config.url)
        will = json.dumps({"state": "died"})
        self.connection = MqttConnection(
            self.target,
            config,
            log,
            (self.topic(MONITOR, "status"), will),
            config.client_id or default_client_id(),
        )
        self.sent = 0
        self._sent_to = 0  # the newest outbox id handed to the client
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._last_measurement: dict[str, float] = {}
        self._threads = [threading.Thread(target=self._drain, name="mqtt outbox", daemon=True)]
        if config.snapshots_hz > 0:
            self._threads.append(
                threading.Thread(target=self._snapshots, name="mqtt snapshots", daemon=True)
            )

    def topic(self, rig: str, leaf: str) -> str:
        return f"{self.target.prefix}/{rig}/{leaf}"

    def start(self) -> None:
        """Connect (one InputError line when the broker refuses; one warning when it cannot
        be reached yet: the monitor starts, and the outbox waits), say the monitor runs,
        listen for acknowledgements and start sending the outbox."""
        self.connection.connect(required=False)
        self._status(MONITOR, {"state": "running", "rigs": self.rigs, "since_utc": utc_now()})
        for rig in self.rigs:
            self.connection.subscribe(self.topic(rig, "ack"), self._ack_command)
        if self.config.homeassistant:
            prefix, where = self.target.prefix, self.config.discovery_prefix
            Discovery(self.connection, prefix, where, self.entities, self.log).start()
        for thread in self._threads:
            thread.start()

    def _status(self, rig: str, status: dict[str, Any]) -> None:
        payload = json.dumps(jsonable(status))
        self.connection.publish(self.topic(rig, "status"), payload, qos=1, retain=True)

    def rig_status(self, rig: str, status: dict[str, Any]) -> None:
        """A rig's figures, retained."""
        self._status(rig, status)

    def alarm_states(self, rig: str, states: dict[str, str]) -> None:
        """Whether each alarm rule of a rig is raised (``ON``) or not (``OFF``), retained."""
        self.connection.publish(self.topic(rig, "alarm_states"), json.dumps(states), 1, True)

    def wake(self) -> None:
        """New rows in the outbox."""
        self._wake.set()

    def _drain(self) -> None:
        limit = max(1, self.config.max_queued // 2)
        while not self._stop.is_set():
            self._wake.wait(1.0)
            self._wake.clear()
            if self.connection.pending >= limit:
                continue  # the broker is away: the rest waits on disk
            for event in self.store.outbox(limit - self.connection.pending, self._sent_to):
                if not self._send(event):
                    break
                self._sent_to = event["id"]

    def _send(self, event: dict[str, Any]) -> bool:
        def acked() -> None:
            if "id" in event:
                self.store.delivered(event["id"])
            self.published(event)

        payload = json.dumps(jsonable(event))
        ok = self.connection.publish(self.topic(event["rig"], "alarms"), payload, 1, on_ack=acked)
        self.sent += ok
        return ok

    def _snapshots(self) -> None:
        every_s = 1.0 / self.config.snapshots_hz
        while not self._stop.wait(every_s):
            if not self.connection.connected:
                continue  # QoS 0: a picture not sent now is worth nothing later
            for rig in self.rigs:
                for leaf, (what, width) in SNAPSHOTS.items():
                    found = self.picture(rig, what, width)
                    if found is not None:
                        topic = self.topic(rig, f"snapshot/{leaf}")
                        self.connection.publish(topic, found.data, 0, True)

    def publish_direct(self, event: dict[str, Any]) -> None:
        """An event the store could not keep: sent from memory."""
        if not self._send(event):
            self.log(f"MQTT: queue full, event not sent: {event['rig']} {event['rule']}")

    def measurement(self, rig: str, fused: FusedFrame) -> None:
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
                    "events": self.acknowledge(rig, command["rule"], command["by"]),
                }
            except AckRefusedError as exc:
                reply = {"ok": False, "error": exc.message}
        if not reply["ok"]:
            self.log(f"MQTT {topic}: acknowledgement refused: {reply['error']}")
        self.connection.publish(self.topic(rig, "ack/result"), json.dumps(jsonable(reply)), 1)

    def stop(self, reason: str = "stopped") -> None:
        self._stop.set()
        self._wake.set()
        for thread in self._threads:
            if thread.is_alive():
                thread.join(5.0)
        self._status(MONITOR, {"state": reason, "until_utc": utc_now()})
        self.connection.close(wait_s=5.0)


def utc_now() -> str:
    from datetime import datetime, timezone

    return datetime.now(timezone.utc).isoformat(timespec="seconds")
