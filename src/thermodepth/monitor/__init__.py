"""The always-on monitor (``thermodepth monitor monitor.yaml``): rigs watched day and night,
each a session of its own with the monitor's sinks, not a second pipeline (docs/monitor.md).

==================  ===========================================================================
module              what
==================  ===========================================================================
:mod:`.config`      the config file: schema, paths, every problem a line
:mod:`.supervisor`  each rig on its own thread: opened, run, reopened with backoff, recovered
:mod:`.rig`         a rig's source on the live clock, its figures, its sink
:mod:`.failsafe`    ``sensor_fault`` (no data, VOx out of range, shutter, corrupt frames) and
                    ``storage_fault``
:mod:`.evidence`    the pre-trigger buffer, clips as recordings, overlay PNG and PLY
:mod:`.storage`     rolling continuous recordings; retention by age and free space
:mod:`.store`       the event store (SQLite, WAL, versioned schema) and the MQTT outbox
:mod:`.publish`     MQTT: each rig under its prefix, events at QoS 1 from the outbox, acks
:mod:`.http`        /healthz, /api/status, /api/events, /api/ack, /metrics
:mod:`.systemd`     the notify protocol and its watchdog
:mod:`.service`     :class:`Monitor`: the parts together, events' one way, the clock
==================  ===========================================================================
"""

from .config import MonitorConfig, load_config
from .service import Monitor

__all__ = ["Monitor", "MonitorConfig", "load_config"]
