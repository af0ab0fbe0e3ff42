"""A run live in Foxglove (``run --foxglove [HOST:PORT]``; the ``foxglove`` extra:
foxglove-sdk): the messages ``export`` writes (:mod:`.bag`; the temperature on the depth
grid as its 16UC1 centikelvin image only, which Foxglove colours), served by foxglove-sdk's
WebSocket server as ROS 2 messages (``ros2msg`` schemas, CDR), at most :data:`MAX_HZ`
pairs and fused frames a second, the others not even built (the sink's ``max_hz``), and
``/tf_static`` once a second, so that a client that connects later has it: a live rig never
waits for a viewer.

Open Foxglove, "Open connection", Foxglove WebSocket, ``ws://HOST:PORT``.
"""

from __future__ import annotations

from typing import Any

from ..errors import FieldError, InputError
from ..io.ros import typestore

INSTALL = "the live Foxglove view needs the foxglove extra: pip install 'thermodepth[foxglove]'"
MAX_HZ = 5.0
DEFAULT_ADDRESS = "127.0.0.1:8765"


def parse_address(text: str) -> tuple[str, int]:
    """``HOST:PORT`` (port 0: any free one); FieldError (``foxglove``) otherwise."""
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or int(port) > 65535:
        raise FieldError("foxglove", f"{text!r}: expected HOST:PORT ({DEFAULT_ADDRESS})")
    return host, int(port)


class FoxgloveWriter:
    """ROS messages to a Foxglove WebSocket server on ``address`` (module docstring)."""

    def __init__(self, address: str = DEFAULT_ADDRESS) -> None:
        try:
            import foxglove
        except ImportError:
            raise InputError(INSTALL) from None
        host, port = parse_address(address)
        self.store = typestore()
        try:
            self.server = foxglove.start_server(name="thermodepth", host=host, port=port)
        except Exception as exc:  # the SDK says why in its own error type
            raise InputError(f"Foxglove: cannot serve on {address} ({exc})") from None
        self.port = int(self.server.port)
        self.url = f"ws://{host}:{self.port}"
        self._channels: dict[str, Any] = {}

    def write(
        self, topic: str, msgtype: str, msg: Any, time_s: float, latched: bool = False
    ) -> None:
        """One message to the clients subscribed to ``topic``."""
        from foxglove import Channel, Schema

        channel = self._channels.get(topic)
        if channel is None:
            text = self.store.generate_msgdef(msgtype, ros_version=2)[0]
            schema = Schema(name=msgtype, encoding="ros2msg", data=text.encode())
            channel = self._channels[topic] = Channel(topic, schema=schema, message_encoding="cdr")
        channel.log(bytes(self.store.serialize_cdr(msg, msgtype)), log_time=round(time_s * 1e9))

    def close(self) -> None:
        self.server.stop()
