"""The monitor's plant outputs, one file each behind one interface (:class:`~.base.Output`):

==================  ===========================================================================
module              what
==================  ===========================================================================
:mod:`.base`        the interface, what the monitor gives an output, a rig as outputs see it
:mod:`.mqtt`        MQTT: each rig under its prefix, events from the outbox, acknowledgements
:mod:`.homeassistant`  Home Assistant's MQTT discovery (with MQTT)
:mod:`.opcua`       an OPC UA server: readings, alarm states and events
:mod:`.modbus`      a Modbus TCP server: readings, health, alarm states, acknowledging coils
:mod:`.rtsp`        an RTSP server: each rig's live video as H.264
==================  ===========================================================================

:data:`OUTPUT_BUILDERS` makes each from its section of the config (``None``: not asked for),
in the order they start; a new output is one more file and one more entry.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from ..config import MonitorConfig
from .base import Output, OutputContext, RigEntities


class OutputKind(NamedTuple):
    """How an output is made from the config (``build``: None when its section is absent)
    and how it is told in one line without making it (``describe``: ``monitor --check``)."""

    build: Callable[[MonitorConfig, OutputContext], Output | None]
    describe: Callable[[MonitorConfig], str | None]


def _mqtt(config: MonitorConfig, context: OutputContext) -> Output | None:
    if config.mqtt is None:
        return None
    from .mqtt import MqttOutput

    return MqttOutput(config.mqtt, context)


def _opcua(config: MonitorConfig, context: OutputContext) -> Output | None:
    if config.opcua is None:
        return None
    from .opcua import OpcUaOutput

    return OpcUaOutput(config.opcua, context)


def _modbus(config: MonitorConfig, context: OutputContext) -> Output | None:
    if config.modbus is None:
        return None
    from .modbus import ModbusOutput

    return ModbusOutput(config.modbus, context)


def _rtsp(config: MonitorConfig, context: OutputContext) -> Output | None:
    if config.rtsp is None:
        return None
    from .rtsp import RtspOutput

    return RtspOutput(config.rtsp, context)


def _describe_mqtt(config: MonitorConfig) -> str | None:
    from .mqtt import describe

    return None if config.mqtt is None else describe(config.mqtt)


def _describe_opcua(config: MonitorConfig) -> str | None:
    from .opcua import describe

    return None if config.opcua is None else describe(config.opcua)


def _describe_modbus(config: MonitorConfig) -> str | None:
    from .modbus import describe

    return None if config.modbus is None else describe(config.modbus)


def _describe_rtsp(config: MonitorConfig) -> str | None:
    from .rtsp import describe

    return None if config.rtsp is None else describe(config.rtsp)


OUTPUT_BUILDERS: dict[str, OutputKind] = {
    "mqtt": OutputKind(_mqtt, _describe_mqtt),
    "opcua": OutputKind(_opcua, _describe_opcua),
    "modbus": OutputKind(_modbus, _describe_modbus),
    "rtsp": OutputKind(_rtsp, _describe_rtsp),
}
"""Each output by the config section that asks for it."""


def build_outputs(config: MonitorConfig, context: OutputContext) -> list[Output]:
    """The outputs a config asks for, in :data:`OUTPUT_BUILDERS`' order (not started)."""
    built = (kind.build(config, context) for kind in OUTPUT_BUILDERS.values())
    return [output for output in built if output is not None]


def describe_outputs(config: MonitorConfig) -> list[str]:
    """What each output a config asks for would serve, a line each (none: none asked)."""
    told = (kind.describe(config) for kind in OUTPUT_BUILDERS.values())
    return [line for line in told if line is not None]


__all__ = [
    "OUTPUT_BUILDERS",
    "Output",
    "OutputContext",
    "OutputKind",
    "RigEntities",
    "build_outputs",
    "describe_outputs",
]
