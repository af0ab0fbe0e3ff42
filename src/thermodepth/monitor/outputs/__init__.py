"""The monitor's plant outputs, one file each behind one interface (:class:`~.base.Output`):

==================  ===========================================================================
module              what
==================  ===========================================================================
:mod:`.base`        the interface, what the monitor gives an output, a rig as outputs see it
:mod:`.mqtt`        MQTT: each rig under its prefix, events from the outbox, acknowledgements
:mod:`.homeassistant`  Home Assistant's MQTT discovery (with MQTT)
:mod:`.opcua`       an OPC UA server: readings, alarm states and events
:mod:`.modbus`      a Modbus TCP server: readings, health, alarm states, acknowledging coils
:mod:`.notify`      notifications' common delivery: the outbox, retries, the hourly limit
:mod:`.webhook`     a notification target: a signed JSON POST of each event
:mod:`.email`       a notification target: an e-mail of each event, its overlay attached
:mod:`.rtsp`        an RTSP server: each rig's live video as H.264
==================  ===========================================================================

:data:`OUTPUT_BUILDERS` makes each from its section of the config (none: not asked for; the
``notify`` list one output per target), in the order they start; a new output is one more
file and one more entry.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from ..config import MonitorConfig
from .base import Output, OutputContext, RigEntities


class OutputKind(NamedTuple):
    """How outputs are made from the config (``build``: none when its section is absent)
    and told a line each without making them (``describe``: ``monitor --check``)."""

    build: Callable[[MonitorConfig, OutputContext], list[Output]]
    describe: Callable[[MonitorConfig], list[str]]


def _mqtt(config: MonitorConfig, context: OutputContext) -> list[Output]:
    if config.mqtt is None:
        return []
    from .mqtt import MqttOutput

    return [MqttOutput(config.mqtt, context)]


def _opcua(config: MonitorConfig, context: OutputContext) -> list[Output]:
    if config.opcua is None:
        return []
    from .opcua import OpcUaOutput

    return [OpcUaOutput(config.opcua, context)]


def _modbus(config: MonitorConfig, context: OutputContext) -> list[Output]:
    if config.modbus is None:
        return []
    from .modbus import ModbusOutput

    return [ModbusOutput(config.modbus, context)]


def _notify(config: MonitorConfig, context: OutputContext) -> list[Output]:
    from .notify import notifier

    return [notifier(target, context) for target in config.notify]


def _rtsp(config: MonitorConfig, context: OutputContext) -> list[Output]:
    if config.rtsp is None:
        return []
    from .rtsp import RtspOutput

    return [RtspOutput(config.rtsp, context)]


def _describe_mqtt(config: MonitorConfig) -> list[str]:
    from .mqtt import describe

    return [] if config.mqtt is None else [describe(config.mqtt)]


def _describe_opcua(config: MonitorConfig) -> list[str]:
    from .opcua import describe

    return [] if config.opcua is None else [describe(config.opcua)]


def _describe_modbus(config: MonitorConfig) -> list[str]:
    from .modbus import describe

    return [] if config.modbus is None else [describe(config.modbus)]


def _describe_notify(config: MonitorConfig) -> list[str]:
    from .notify import describe

    return [describe(target) for target in config.notify]


def _describe_rtsp(config: MonitorConfig) -> list[str]:
    from .rtsp import describe

    return [] if config.rtsp is None else [describe(config.rtsp)]


OUTPUT_BUILDERS: dict[str, OutputKind] = {
    "mqtt": OutputKind(_mqtt, _describe_mqtt),
    "opcua": OutputKind(_opcua, _describe_opcua),
    "modbus": OutputKind(_modbus, _describe_modbus),
    "notify": OutputKind(_notify, _describe_notify),
    "rtsp": OutputKind(_rtsp, _describe_rtsp),
}
"""Each output by the config section that asks for it."""


def build_outputs(config: MonitorConfig, context: OutputContext) -> list[Output]:
    """The outputs a config asks for, in :data:`OUTPUT_BUILDERS`' order (not started)."""
    return [o for kind in OUTPUT_BUILDERS.values() for o in kind.build(config, context)]


def describe_outputs(config: MonitorConfig) -> list[str]:
    """What each output a config asks for would serve, a line each (none: none asked)."""
    return [line for kind in OUTPUT_BUILDERS.values() for line in kind.describe(config)]


__all__ = [
    "OUTPUT_BUILDERS",
    "Output",
    "OutputContext",
    "OutputKind",
    "RigEntities",
    "build_outputs",
    "describe_outputs",
]
