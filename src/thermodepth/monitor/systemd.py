"""systemd's notify protocol (sd_notify(3)): ``READY=1`` once the monitor runs, ``RELOADING=1``
and ``READY=1`` around a reload, ``STOPPING=1``, ``STATUS=...`` lines, and ``WATCHDOG=1`` at
half the unit's ``WatchdogSec`` while the monitor's clock goes round and every rig's thread
lives (so that systemd restarts a monitor that hangs). Each is a datagram to the unix socket
``$NOTIFY_SOCKET`` names (a leading ``@``: Linux's abstract namespace); without it (not under
systemd) nothing is sent.
"""

from __future__ import annotations

import os
import socket
import time


def notify(*fields: str) -> bool:
    """Send ``fields`` (``READY=1``, ``STATUS=...``) to systemd; False when not under it (or
    the socket cannot take them)."""
    address = os.environ.get("NOTIFY_SOCKET")
    if not address:
        return False
    if address.startswith("@"):
        address = "\0" + address[1:]
    message = "\n".join(fields).encode()
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC) as s:
            s.setblocking(False)  # a reader that does not read drops the datagram, never
            s.connect(address)  # hangs the monitor's clock (or its stop)
            s.sendall(message)
    except OSError:
        return False
    return True


def watchdog_interval_s() -> float | None:
    """How often to send ``WATCHDOG=1`` (s): half the ``$WATCHDOG_USEC`` systemd set for this
    process (``$WATCHDOG_PID``, when set, must be ours), None when it asks for none."""
    usec = os.environ.get("WATCHDOG_USEC", "")
    pid = os.environ.get("WATCHDOG_PID")
    if not usec.isdigit() or int(usec) == 0 or (pid and pid != str(os.getpid())):
        return None
    return int(usec) / 2e6


def reloading() -> bool:
    """``RELOADING=1`` with ``MONOTONIC_USEC`` (systemd >= 253 wants it for Type=notify-reload)."""
    return notify(
        "RELOADING=1", f"MONOTONIC_USEC={time.clock_gettime_ns(time.CLOCK_MONOTONIC) // 1000}"
    )
