"""Sinks: what consumes a session (:class:`Sink`, :mod:`.base`), one file each.

- :class:`RecorderSink` (:mod:`.recorder`): every raw event into a recording;
- :class:`MeasurementsSink` (:mod:`.measurements`): measurements, alarms and hotspots files;
- :class:`CallbackSink` (:mod:`.callback`): a function called with each fused frame;
- :class:`~.mqtt.MqttSink` (:mod:`.mqtt`): alarms, measurements and status to an MQTT broker;
- :class:`~.viewer.ViewerSink` (:mod:`.viewer`): the live 3D view in rerun.

A new sink is a :class:`BaseSink` subclass in its own file here; the application's ``run``
builds the sinks its options ask for (``thermodepth.app.run.SINK_BUILDERS``).
"""

from .base import BaseSink, RunContext, SessionResult, Sink, closing_attrs
from .callback import CallbackSink
from .measurements import MeasurementsSink
from .mqtt import MqttSink
from .recorder import RecorderSink

__all__ = [
    "BaseSink",
    "CallbackSink",
    "MeasurementsSink",
    "MqttSink",
    "RecorderSink",
    "RunContext",
    "SessionResult",
    "Sink",
    "closing_attrs",
]
