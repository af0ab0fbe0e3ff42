"""Home Assistant's MQTT discovery (``mqtt.homeassistant: true``): each rig a device whose
entities Home Assistant finds by itself.

Per rig (its device: ``identifiers`` ``thermodepth_PREFIX_RIG``, named ``thermodepth RIG``,
its ``location`` as the suggested area):

==========================  =================================================================
entity                      state
==========================  =================================================================
sensor ``Hottest``          the hottest hotspot's max (C) from ``PREFIX/RIG/measurements``
sensor ``ROI max``          each ROI's max (C), from the same
binary_sensor ``Alarm R``   each alarm rule, ``heat``: ON while raised (``PREFIX/RIG/alarm_states``,
                            retained)
binary_sensor ``Health``    ``problem``: ON while the rig is stale or a sensor fault is raised
                            (``PREFIX/RIG/status``)
==========================  =================================================================

Temperatures are ``device_class: temperature``, ``unit_of_measurement: °C``, ``state_class:
measurement``. Every entity is available while the monitor runs (``PREFIX/monitor/status``,
whose last will says it died); the measurements only while the rig also has fresh data.

Configs are retained at ``DISCOVERY/COMPONENT/NODE/OBJECT/config`` (``DISCOVERY`` defaults to
``homeassistant``, ``NODE`` is ``thermodepth_`` and the prefix), published again whenever Home
Assistant says ``online`` on ``DISCOVERY/status`` (its birth message), and removed (an empty
retained config) when a rig or a rule is no longer in the config: the monitor reads back the
configs retained under its node when it connects.
"""

from __future__ import annotations

import json
import logging
import re
from typing import Any

from ... import __version__
from ...sinks.mqtt import MqttConnection
from .base import RigEntities

AVAILABLE = "{{ 'online' if value_json.state == 'running' else 'offline' }}"
RIG_UP = "{{ 'online' if value_json.up == 1 else 'offline' }}"
TEMPERATURE = {"device_class": "temperature", "unit_of_measurement": "°C",
               "state_class": "measurement"}  # fmt: skip


def slug(text: str) -> str:
    """Letters, digits and ``_`` only, as Home Assistant's ids want them."""
    return re.sub(r"[^A-Za-z0-9_]+", "_", text).strip("_").lower()


def configs(prefix: str, discovery: str, rigs: list[RigEntities]) -> dict[str, dict[str, Any]]:
    """Every discovery config (module docstring), by topic."""
    node = f"thermodepth_{slug(prefix)}"
    return {k: v for rig in rigs for k, v in rig_configs(node, prefix, discovery, rig).items()}


def rig_configs(
    node: str, prefix: str, discovery: str, rig: RigEntities
) -> dict[str, dict[str, Any]]:
    """The discovery configs of one rig, by topic."""
    topic = f"{prefix}/{rig.name}"
    device = {
        "identifiers": [f"{node}_{slug(rig.name)}"],
        "name": f"thermodepth {rig.name}",
        "manufacturer": "thermodepth",
        "model": "depth + radiometric thermal camera",
        "sw_version": __version__,
        **({"suggested_area": rig.location} if rig.location else {}),
    }
    monitor = {"topic": f"{prefix}/monitor/status", "value_template": AVAILABLE}
    fresh = {"topic": f"{topic}/status", "value_template": RIG_UP}
    out: dict[str, dict[str, Any]] = {}

    def add(component: str, key: str, entity: dict[str, Any], measured: bool) -> None:
        object_id = slug(f"{rig.name}_{key}")
        out[f"{discovery}/{component}/{node}/{object_id}/config"] = {
            "unique_id": f"{node}_{object_id}",
            "object_id": f"thermodepth_{object_id}",
            "device": device,
            "availability": [monitor, fresh] if measured else [monitor],
            "availability_mode": "all",
            **entity,
        }

    add("sensor", "hottest", {
        "name": "Hottest",
        "state_topic": f"{topic}/measurements",
        "value_template": "{{ value_json.hottest.max_c if value_json.hottest else none }}",
        **TEMPERATURE,
    }, True)  # fmt: skip
    for roi in rig.rois:
        add("sensor", f"roi_{roi}", {
            "name": f"{roi} max",
            "state_topic": f"{topic}/measurements",
            "value_template": f"{{{{ value_json.rois[{json.dumps(roi)}].max_c }}}}",
            **TEMPERATURE,
        }, True)  # fmt: skip
    for rule in rig.rules:
        add("binary_sensor", f"alarm_{rule}", {
            "name": f"Alarm {rule}",
            "device_class": "heat",
            "state_topic": f"{topic}/alarm_states",
            "value_template": f"{{{{ value_json[{json.dumps(rule)}] }}}}",
            "payload_on": "ON",
            "payload_off": "OFF",
        }, False)  # fmt: skip
    add("binary_sensor", "health", {
        "name": "Health",
        "device_class": "problem",
        "state_topic": f"{topic}/status",
        "value_template": "{{ 'OFF' if value_json.health == 'ok' else 'ON' }}",
        "payload_on": "ON",
        "payload_off": "OFF",
    }, False)  # fmt: skip
    return out


class Discovery:
    """Keeps Home Assistant's discovery configs on the broker (module docstring) through
    ``connection``; ``log``: where it says what it does."""

    def __init__(
        self,
        connection: MqttConnection,
        prefix: str,
        discovery: str,
        rigs: list[RigEntities],
        log: logging.Logger,
    ) -> None:
        self.connection, self.discovery, self.log = connection, discovery, log
        self.node = f"thermodepth_{slug(prefix)}"
        self.configs = configs(prefix, discovery, rigs)
        self.removed: list[str] = []

    def start(self) -> None:
        """Publish every config; listen for Home Assistant's birth message and for configs
        retained under our node that are ours no more."""
        self.publish()
        self.connection.subscribe(f"{self.discovery}/status", self._birth)
        for component in ("sensor", "binary_sensor"):
            ours = f"{self.discovery}/{component}/{self.node}/+/config"
            self.connection.subscribe(ours, self._seen)

    def publish(self) -> None:
        for topic, config in self.configs.items():
            self.connection.publish(topic, json.dumps(config), qos=1, retain=True)

    def _birth(self, topic: str, payload: bytes) -> None:
        if payload.strip() == b"online":
            self.log.info("Home Assistant is online: discovery configs published again")
            self.publish()

    def _seen(self, topic: str, payload: bytes) -> None:
        if payload and topic not in self.configs:
            self.removed.append(topic)
            self.connection.publish(topic, "", qos=1, retain=True)
            self.log.info("Home Assistant: %s removed (no longer in the config)", topic)
