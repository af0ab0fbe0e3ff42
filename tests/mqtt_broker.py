"""A Mosquitto broker of the tests' own, on a free loopback port, and a subscriber that
collects what arrives (helpers for tests/test_mqtt.py)."""

from __future__ import annotations

import contextlib
import json
import os
import queue
import shutil
import socket
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

MOSQUITTO = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
MOSQUITTO_PASSWD = shutil.which("mosquitto_passwd") or "/usr/bin/mosquitto_passwd"


def missing() -> str | None:
    """Why a broker cannot be started here (None: it can)."""
    for exe, what in ((MOSQUITTO, "the broker"), (MOSQUITTO_PASSWD, "mosquitto_passwd")):
        if not os.access(exe, os.X_OK):
            return f"the Debian package mosquitto is not installed ({what}: {exe} absent)"
    return None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Broker:
    """A mosquitto process with a password file (user ``rig``), on 127.0.0.1 only."""

    def __init__(self, password: str = "s3cret", persistence: bool = False) -> None:
        self.dir = Path(tempfile.mkdtemp(prefix="mosquitto-"))
        self.port = free_port()
        self.password = password
        self.log = self.dir / "mosquitto.log"
        self.proc: subprocess.Popen[bytes] | None = None
        passwd = self.dir / "passwd"
        subprocess.run(
            [MOSQUITTO_PASSWD, "-b", "-c", str(passwd), "rig", password],
            check=True,
            capture_output=True,
        )
        lines = [
            f"listener {self.port} 127.0.0.1",
            "allow_anonymous false",
            f"password_file {passwd}",
            f"log_dest file {self.log}",
            "log_type all",
            f"persistence {'true' if persistence else 'false'}",
            f"persistence_location {self.dir}/",
        ]
        if os.geteuid() == 0:  # else it drops to user mosquitto, who cannot read our files
            lines.append("user root")
        self.conf = self.dir / "mosquitto.conf"
        self.conf.write_text("\n".join(lines) + "\n", encoding="utf-8")

    def start(self, timeout_s: float = 5.0) -> None:
        """Start and wait for the log's "running" line (after the listener is bound)."""
        offset = self.log.stat().st_size if self.log.exists() else 0
        self.proc = subprocess.Popen(
            [MOSQUITTO, "-c", str(self.conf)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        t0 = time.monotonic()
        while True:
            if self.proc.poll() is not None:
                raise RuntimeError(f"mosquitto exited with code {self.proc.returncode}")
            if self.log.exists():
                with open(self.log, encoding="utf-8", errors="replace") as f:
                    f.seek(offset)
                    if " running" in f.read():
                        return
            if time.monotonic() - t0 > timeout_s:
                self.stop()
                raise TimeoutError("mosquitto did not start")
            time.sleep(0.01)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc = None

    def cleanup(self) -> None:
        self.stop()
        shutil.rmtree(self.dir, ignore_errors=True)

    def url(self, prefix: str = "plant/rig1") -> str:
        return f"mqtt://rig@127.0.0.1:{self.port}/{prefix}"


def payload_of(payload: bytes) -> Any:
    """A message's JSON, or its text where it is none (Home Assistant's ``online``, an empty
    retained message that removes a discovery config)."""
    try:
        return json.loads(payload)
    except ValueError:
        return payload.decode("utf-8", errors="replace")


class Collector:
    """A subscriber to ``topic`` (QoS 1) with a fixed client id and a persistent session, so
    that a broker with persistence keeps its messages across a restart; ready once the
    broker acknowledged the subscription."""

    def __init__(self, broker: Broker, topic: str, client_id: str = "collector") -> None:
        import paho.mqtt.client as mqtt

        self.messages: queue.Queue[tuple[str, Any, bool]] = queue.Queue()
        self._subscribed = threading.Event()
        c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=client_id, clean_session=False)
        c.username_pw_set("rig", broker.password)
        c.reconnect_delay_set(1, 2)
        c.on_connect = lambda cl, ud, fl, rc, pr: cl.subscribe(topic, qos=1)
        c.on_subscribe = lambda cl, ud, mid, rcs, pr: self._subscribed.set()
        c.on_message = lambda cl, ud, m: self.messages.put(
            (m.topic, payload_of(m.payload), bool(m.retain))
        )
        c.connect("127.0.0.1", broker.port, keepalive=5)
        c.loop_start()
        self.client = c
        assert self._subscribed.wait(30), "the broker did not acknowledge the subscription"

    def drain(
        self, settle_s: float = 0.5, max_s: float = float("inf")
    ) -> list[tuple[str, Any, bool]]:
        """Everything received until nothing came for ``settle_s``, or for ``max_s`` at most
        (a stream that never pauses)."""
        out = []
        end = time.monotonic() + max_s
        while time.monotonic() < end:
            try:
                out.append(self.messages.get(timeout=settle_s))
            except queue.Empty:
                break
        return out

    def until(
        self, done: Callable[[list[tuple[str, Any, bool]]], bool], timeout_s: float = 120.0
    ) -> list[tuple[str, Any, bool]]:
        """Everything received until ``done(received)`` says so (AssertionError if not
        within ``timeout_s``, far beyond the need)."""
        out: list[tuple[str, Any, bool]] = []
        end = time.monotonic() + timeout_s
        while not done(out):
            left = end - time.monotonic()
            if left <= 0:
                raise AssertionError(f"not within {timeout_s} s ({len(out)} messages)")
            with contextlib.suppress(queue.Empty):
                out.append(self.messages.get(timeout=min(left, 0.5)))
        return out

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()
