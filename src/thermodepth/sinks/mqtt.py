"""Publishing a run to an MQTT broker (paho-mqtt): alarms, measurement summaries and the
rig's status, for a plant's message bus.

Topics under the URL's prefix (``mqtt://broker:1883/plant/rig1`` -> ``plant/rig1/...``):

- ``alarms``: every alarm event (raised and cleared) as JSON, QoS 1. While the broker is
  away they are queued (up to ``mqtt.max_queued``) and delivered, in order, when it returns.
- ``measurements``: a summary of the latest fused frame (hottest reading and where, ROIs,
  flags), QoS 0, at most ``mqtt.measurements_hz`` a second; none is queued while away.
- ``status``: ``{"state": "running", ...}`` retained while the run goes, the way it ended on a
  clean stop, and the broker's last will ``{"state": "died"}`` if the run dies without one.

The password never goes on the command line (it would show in the process list): it comes
from ``THERMODEPTH_MQTT_PASSWORD`` or ``mqtt.password_file``.
"""

from __future__ import annotations

import json
import os
import socket
import threading
import time
import urllib.parse
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..alarms import KINDS
from ..errors import FieldError, InputError, ThermodepthError
from ..io.measurements import jsonable
from ..pipeline import FusedFrame, MqttSettings
from .base import BaseSink, RunContext, SessionResult

PASSWORD_ENV = "THERMODEPTH_MQTT_PASSWORD"
INSTALL = "--mqtt needs paho-mqtt: pip install 'thermodepth[mqtt]'"
DELIVERY_WAIT_S = 10.0  # at the end: how long queued alarms may take to reach the broker


@dataclass(frozen=True)
class MqttTarget:
    """Where to publish: ``mqtt://[USER@]HOST[:PORT]/PREFIX`` (``mqtts://``: TLS, port 8883
    by default; ``mqtt://``: 1883)."""

    tls: bool
    host: str
    port: int
    prefix: str
    username: str | None

    @classmethod
    def parse(cls, url: str) -> MqttTarget:
        """The target of ``url``; FieldError (field ``mqtt``) if it is not one, or if it
        holds a password."""
        parts = urllib.parse.urlsplit(url)
        if parts.scheme not in ("mqtt", "mqtts") or not parts.hostname:
            raise FieldError("mqtt", f"{url!r}: expected mqtt://[USER@]HOST[:PORT]/PREFIX")
        if parts.password is not None:
            raise FieldError(
                "mqtt",
                f"a password in the URL would show in the process list: put it in "
                f"{PASSWORD_ENV} or in the settings' mqtt.password_file",
            )
        prefix = parts.path.strip("/")
        if not prefix or "+" in prefix or "#" in url or parts.query:
            raise FieldError(
                "mqtt", f"{url!r}: give a topic prefix without wildcards (/plant/rig1)"
            )
        try:
            port = parts.port or (8883 if parts.scheme == "mqtts" else 1883)
        except ValueError:
            raise FieldError("mqtt", f"{url!r}: the port is not a number") from None
        user = urllib.parse.unquote(parts.username) if parts.username else None
        return cls(parts.scheme == "mqtts", parts.hostname, port, prefix, user)

    @property
    def where(self) -> str:
        return f"{'mqtts' if self.tls else 'mqtt'}://{self.host}:{self.port}"


def read_password(settings: MqttSettings) -> str | None:
    """The broker's password: the settings' ``password_file`` (its first line), else
    ``THERMODEPTH_MQTT_PASSWORD``, else None."""
    if settings.password_file is not None:
        try:
            return Path(settings.password_file).read_text(encoding="utf-8").splitlines()[0]
        except (OSError, IndexError) as exc:
            why = "it is empty" if isinstance(exc, IndexError) else exc.strerror or exc
            raise InputError(
                f"{settings.password_file}: cannot read the MQTT password ({why})"
            ) from None
    return os.environ.get(PASSWORD_ENV)


def alarm_message(event: dict[str, Any], fused: FusedFrame) -> dict[str, Any]:
    """An alarm event as published: the rule, what happened (``alarm`` or ``clear``), the
    value and threshold (C), the frame and its thermal time (s), the VOx temperature (C) and
    where: the hottest hotspot's centroid (m, depth camera frame) or the ROI's name."""
    message = {
        "event": event["event"],
        "rule": event["rule"],
        "level": event.get("level", "alarm"),
        "condition": event.get("condition"),
        "value_c": event["value_c"],
        **{k: event[k] for k in KINDS if k in event},
        "frame": event["frame"],
        "time_s": event["time_s"],
        "vox_temp_c": None if fused.vox_temp_c != fused.vox_temp_c else round(fused.vox_temp_c, 3),
    }
    for key in ("by", "at_utc"):
        if key in event:
            message[key] = event[key]
    if "hotspot" in event:
        message["position_m"] = event["hotspot"]["centroid_m"]
        message["distance_m"] = event["hotspot"]["distance_m"]
    if "roi" in event:
        message["roi"] = event["roi"]
    return message


def measurement_message(fused: FusedFrame) -> dict[str, Any]:
    """A frame's summary as published: time, VOx, the hottest hotspot (max C, centroid m,
    distance m, resolvable), the count of hotspots, each ROI's statistics and the OR of the
    flags of everything measured; each line's length, max and where, each isotherm's area."""
    hot = fused.hotspots[0] if fused.hotspots else None
    flags = 0
    for item in (*fused.hotspots, *fused.rois):
        flags |= int(getattr(item, "flags", 0))
    return {
        "frame": fused.index,
        "time_s": round(fused.thermal_time_s, 4),
        "vox_temp_c": round(fused.vox_temp_c, 3),
        "hottest": None
        if hot is None
        else {
            "max_c": round(hot.max_c, 3),
            "position_m": [round(x, 4) for x in hot.centroid_m],
            "distance_m": round(hot.distance_m, 4),
            "resolvable": hot.resolvable,
        },
        "hotspots": len(fused.hotspots),
        "rois": {r.name: {k: v for k, v in r.__dict__.items() if k != "name"} for r in fused.rois},
        "flags": flags,
        # lines and isotherms (their figures, not the profiles): only when there are some
        **(
            {
                "lines": {
                    p.name: {k: v for k, v in p.as_dict(profile=False).items() if k != "name"}
                    for p in fused.lines
                }
            }
            if fused.lines
            else {}
        ),
        **(
            {
                "isotherms": {
                    i.name: {k: v for k, v in i.as_dict().items() if k != "name"}
                    for i in fused.isotherms
                }
            }
            if fused.isotherms
            else {}
        ),
    }


class MqttConnection:
    """A paho client connected to one broker for as long as it is needed: it connects (one
    InputError line when it cannot or is refused), reconnects by itself (telling ``warn`` when
    the broker goes away and when it is back, and for how long: ``outages``), keeps QoS 1
    messages while the broker is away (up to ``settings.max_queued``), calls a message's
    ``on_ack`` when the broker has it, and hands what arrives on subscribed topics to their
    handler (resubscribed after every reconnection). ``will``: the last will's topic and
    payload (retained, QoS 1)."""

    def __init__(
        self,
        target: MqttTarget,
        settings: MqttSettings,
        warn: Callable[[str], None],
        will: tuple[str, str],
        client_id: str,
    ) -> None:
        self.target, self.settings, self.warn = target, settings, warn
        self.will, self.client_id = will, client_id
        self.client: Any = None
        self.outages: list[float] = []
        self._lock = threading.Lock()
        self._pending: dict[int, Callable[[], None]] = {}  # message id -> on_ack
        self._early: dict[int, float] = {}  # ids acknowledged before publish returned them
        self._handlers: dict[str, Callable[[str, bytes], None]] = {}
        self._lost_at: float | None = None
        self._connected = threading.Event()
        self._refused: str | None = None
        self._closing = False

    def connect(self, required: bool = True) -> None:
        """Connect; one InputError line when the broker refuses (a wrong password), or when
        it cannot be reached and ``required`` (else one line to ``warn``, and paho goes on
        trying in the background: messages wait until it is there)."""
        import paho.mqtt.client as mqtt

        t, s = self.target, self.settings
        client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=self.client_id)
        password = read_password(s)
        if t.username is not None or password is not None:
            client.username_pw_set(t.username or "", password)
        if t.tls:
            client.tls_set(ca_certs=None if s.ca_file is None else str(s.ca_file))
        client.will_set(self.will[0], self.will[1], qos=1, retain=True)
        client.reconnect_delay_set(min_delay=1, max_delay=5)
        client.max_queued_messages_set(s.max_queued)
        client.on_connect = self._on_connect
        client.on_disconnect = self._on_disconnect
        client.on_publish = self._on_publish
        client.on_message = self._on_message
        self.client = client
        try:
            if required:
                client.connect(t.host, t.port, keepalive=10)
            else:
                client.connect_async(t.host, t.port, keepalive=10)
        except (OSError, ValueError) as exc:
            why = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
            raise InputError(f"{t.where}: cannot reach the MQTT broker ({why})") from None
        client.loop_start()
        answered = self._connected.wait(s.connect_timeout_s)
        if answered and not self._refused:
            return
        if not required and not answered:
            self._lost_at = time.monotonic()
            self.warn(
                f"MQTT: cannot reach {t.where} yet; trying on, messages wait until it answers"
            )
            return
        client.loop_stop()
        client.disconnect()
        why = self._refused or f"no answer in {s.connect_timeout_s:g} s"
        raise InputError(f"{t.where}: the MQTT broker refused the connection: {why}")

    # -- paho's callbacks (its network thread) ---------------------------------------------

    def _on_connect(self, client: Any, userdata: Any, flags: Any, reason: Any, props: Any) -> None:
        if reason.is_failure:
            hint = " (wrong username or password?)" if reason.value in (134, 135) else ""
            self._refused = f"{reason} (reason code {reason.value}){hint}"
            client.disconnect()  # paho would try again for ever
            self._connected.set()
            return
        for topic in list(self._handlers):
            client.subscribe(topic, qos=1)
        if self._lost_at is not None:
            gone = time.monotonic() - self._lost_at
            self.outages.append(gone)
            self._lost_at = None
            self.warn(
                f"MQTT: {self.target.where} is back after {gone:.1f} s; "
                f"{self.pending} messages still to deliver"
            )
        self._connected.set()

    def _on_disconnect(
        self, client: Any, userdata: Any, flags: Any, reason: Any, props: Any
    ) -> None:
        if self._refused or self._closing or self._lost_at is not None:
            return
        self._lost_at = time.monotonic()
        self.warn(
            f"MQTT: lost {self.target.where} ({reason}); measuring goes on, alarms are "
            "queued until it is back"
        )

    def _on_publish(self, client: Any, userdata: Any, mid: int, reason: Any, props: Any) -> None:
        # called under paho's own locks: take only ours, briefly (never held around paho)
        with self._lock:
            on_ack = self._pending.pop(mid, None)
            if on_ack is None:
                self._early[mid] = time.monotonic()
        if on_ack is not None:
            on_ack()

    def _on_message(self, client: Any, userdata: Any, message: Any) -> None:
        import paho.mqtt.client as mqtt

        for pattern, handler in list(self._handlers.items()):
            if mqtt.topic_matches_sub(pattern, message.topic):
                handler(message.topic, bytes(message.payload))

    # -- use ----------------------------------------------------------------------------------

    @property
    def pending(self) -> int:
        """Messages with an ``on_ack`` the broker has not acknowledged yet."""
        with self._lock:
            return len(self._pending)

    def publish(
        self,
        topic: str,
        payload: str | bytes,
        qos: int = 0,
        retain: bool = False,
        on_ack: Callable[[], None] | None = None,
    ) -> bool:
        """Publish; False when paho's queue is full (the message is not sent)."""
        import paho.mqtt.client as mqtt

        info = self.client.publish(topic, payload, qos=qos, retain=retain)
        if info.rc == mqtt.MQTT_ERR_QUEUE_SIZE:
            return False
        with self._lock:
            acked = self._early.pop(info.mid, None) is not None
            if on_ack is not None and not acked:
                self._pending[info.mid] = on_ack
            stale = time.monotonic() - 60.0  # ids come round again after 65,535 messages
            self._early = {m: t for m, t in self._early.items() if t > stale}
        if on_ack is not None and acked:
            on_ack()
        return True

    def subscribe(self, topic: str, handler: Callable[[str, bytes], None]) -> None:
        """Hand every message on ``topic`` (wildcards allowed) to ``handler(topic, payload)``
        (paho's thread)."""
        self._handlers[topic] = handler
        self.client.subscribe(topic, qos=1)

    @property
    def connected(self) -> bool:
        return self._connected.is_set() and self._lost_at is None and not self._refused

    def close(self, wait_s: float = DELIVERY_WAIT_S) -> None:
        """Wait up to ``wait_s`` for the messages still unacknowledged (while the broker is
        there), then disconnect."""
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline and self.pending and self.connected:
            time.sleep(0.05)
        time.sleep(0.1)  # the last message's own acknowledgement
        self._closing = True
        self.client.disconnect()
        self.client.loop_stop()
        if self._lost_at is not None:
            self.outages.append(time.monotonic() - self._lost_at)


class MqttSink(BaseSink):
    """Publishes the run to the broker at ``url`` (see the module docstring); ``warn`` hears
    the broker going away and coming back, with how long it was gone."""

    def __init__(
        self,
        url: str,
        settings: MqttSettings | None = None,
        warn: Callable[[str], None] | None = None,
    ) -> None:
        self.target = MqttTarget.parse(url)
        self.settings = settings or MqttSettings()
        self.warn = warn or (lambda message: None)
        self.connection: MqttConnection | None = None
        self.alarms_sent = 0
        self.alarms_acked = 0
        self.measurements_sent = 0
        self.dropped = 0
        self._last_summary = float("-inf")

    def topic(self, leaf: str) -> str:
        return f"{self.target.prefix}/{leaf}"

    def check(self) -> None:
        try:
            import paho.mqtt.client  # noqa: F401
        except ImportError:
            raise ThermodepthError(INSTALL) from None
        read_password(self.settings)

    def open(self, context: RunContext) -> None:
        client_id = self.settings.client_id or default_client_id()
        will = json.dumps({"state": "died", "source": context.source.name})
        self.connection = MqttConnection(
            self.target, self.settings, self.warn, (self.topic("status"), will), client_id
        )
        self.connection.connect()
        status = {"state": "running", "source": context.source.name, "since_utc": _now()}
        self.connection.publish(self.topic("status"), json.dumps(status), qos=1, retain=True)

    def _acked(self) -> None:
        self.alarms_acked += 1  # paho's thread, one at a time

    def frame(self, fused: FusedFrame) -> None:
        assert self.connection is not None, "open the sink first"
        for event in fused.events:
            payload = json.dumps(jsonable(alarm_message(event, fused)))
            if self.connection.publish(self.topic("alarms"), payload, 1, on_ack=self._acked):
                self.alarms_sent += 1
            else:
                self.dropped += 1
                self.warn(f"MQTT: {self.settings.max_queued} alarms queued already: one dropped")
        now = time.monotonic()
        if now - self._last_summary >= 1.0 / self.settings.measurements_hz:
            self._last_summary = now
            payload = json.dumps(jsonable(measurement_message(fused)))
            self.connection.publish(self.topic("measurements"), payload)
            self.measurements_sent += 1

    def close(self, result: SessionResult) -> None:
        if self.connection is None:
            return
        status = {"state": "stopped", "stopped": result.stopped, "until_utc": _now()}
        if result.error:
            status["error"] = result.error
        self.connection.publish(self.topic("status"), json.dumps(status), qos=1, retain=True)
        self.connection.close()

    def summary(self) -> str:
        missing = self.alarms_sent - self.alarms_acked
        outages = self.connection.outages if self.connection is not None else []
        away = (
            f"; the broker was away {len(outages)} times, {sum(outages):.1f} s in all"
            if outages
            else ""
        )
        lost = (
            f", {missing} NOT delivered (the broker did not come back in time)" if missing else ""
        )
        if self.dropped:
            lost += f", {self.dropped} dropped (the queue was full)"
        return (
            f"MQTT {self.target.where}/{self.target.prefix}: {self.alarms_sent} alarm events "
            f"published ({self.alarms_acked} acknowledged{lost}), "
            f"{self.measurements_sent} measurement summaries{away}"
        )


def default_client_id() -> str:
    """A client id no other process has: ``thermodepth-HOST-PID``."""
    return f"thermodepth-{socket.gethostname()}-{os.getpid()}"


def _now() -> str:
    from datetime import datetime, timezone

    return datetime.now(timezone.utc).isoformat(timespec="seconds")
