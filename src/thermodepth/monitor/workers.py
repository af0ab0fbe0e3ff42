"""The monitor's own long-running loops, each a named, supervised :class:`Worker` (as every rig
is, :mod:`.supervisor`): the clock, the storage sweep, the evidence painter, the broker's
outbox and snapshots, the HTTP, OPC UA and Modbus servers.

A worker runs its loop on a thread of its own. An exception the loop does not handle is
logged with its traceback and the loop is started again after a backoff of 1, 2, 4 ... 30 s
(back to 1 s once it has run a minute); a loop that returns while it should run counts the
same. A loop says it is alive with :meth:`Worker.beat` at least every ``every_s``; one that
stops beating is hung. A worker is **down** while it waits to restart or is hung; down for
longer than its ``limit_s`` it is unhealthy: ``/healthz`` answers 503 naming it, and systemd's
watchdog is no longer fed (systemd then restarts the whole monitor). State and restart count
show in ``/api/status`` (``workers``), ``/metrics`` and the health page.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any

from .logs import logger

BACKOFF_S = (1.0, 2.0, 4.0, 8.0, 16.0, 30.0)
STEADY_S = 60.0
"""A loop that ran this long before it failed starts again after the shortest backoff."""

Loop = Callable[["Worker"], None]


class Worker:
    """One supervised loop (module docstring). ``loop(worker)`` runs until
    ``worker.stopping`` is set, calling ``worker.beat()`` at least every ``every_s`` (None: it
    cannot, as a server's own loop; then only a failure makes it down); ``limit_s``: how long
    it may be down before the monitor is unhealthy."""

    def __init__(
        self,
        name: str,
        loop: Loop,
        every_s: float | None,
        limit_s: float,
        log: logging.Logger | None = None,
    ) -> None:
        self.name, self.loop, self.every_s, self.limit_s = name, loop, every_s, limit_s
        self.log = log or logger("workers")
        self.stopping = threading.Event()
        self.state = "starting"
        self.restarts = 0
        self.last_error: str | None = None
        self.last_beat_mono = time.monotonic()
        self._failed_mono: float | None = None
        self._thread: threading.Thread | None = None

    def beat(self) -> None:
        """The loop is alive."""
        self.last_beat_mono = time.monotonic()

    def start(self) -> None:
        """Start its thread (once: a worker its part started early is not started again)."""
        if self._thread is not None:
            return
        self._thread = threading.Thread(target=self._supervise, name=self.name, daemon=True)
        self._thread.start()

    def _supervise(self) -> None:
        attempt = 0
        while not self.stopping.is_set():
            started = time.monotonic()
            self.state, self._failed_mono = "running", None
            self.beat()
            try:
                self.loop(self)
                if self.stopping.is_set():
                    break
                raise RuntimeError("its loop returned while it should run")
            except Exception as exc:
                self.restarts += 1
                self.last_error = f"{type(exc).__name__}: {exc}"
                self.log.error("worker %s failed; restarting", self.name, exc_info=True)
            attempt = 1 if time.monotonic() - started >= STEADY_S else attempt + 1
            self.state, self._failed_mono = "restarting", time.monotonic()
            self.stopping.wait(BACKOFF_S[min(attempt, len(BACKOFF_S)) - 1])
        self.state = "stopped"

    def down_s(self, now_mono: float) -> float:
        """How long it has been down (0: up): waiting to restart, or hung (no beat for more
        than ``every_s``)."""
        if self.state == "restarting" and self._failed_mono is not None:
            return now_mono - self._failed_mono
        if self.state == "running" and self.every_s is not None:
            return max(0.0, now_mono - self.last_beat_mono - self.every_s)
        return 0.0

    def healthy(self, now_mono: float) -> bool:
        return self.down_s(now_mono) <= self.limit_s

    def stop(self, timeout_s: float = 5.0) -> None:
        self.stopping.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout_s)
        self.state = "stopped"

    def as_dict(self, now_mono: float) -> dict[str, Any]:
        down = self.down_s(now_mono)
        return {
            "name": self.name,
            "state": "hung" if self.state == "running" and down > 0 else self.state,
            "restarts": self.restarts,
            "last_error": self.last_error,
            "down_s": round(down, 1),
            "limit_s": self.limit_s,
            "healthy": down <= self.limit_s,
        }


class Workers:
    """The monitor's workers by name, started and stopped together."""

    def __init__(self) -> None:
        self.all: dict[str, Worker] = {}

    def add(self, worker: Worker) -> Worker:
        if worker.name in self.all:
            raise ValueError(f"a worker named {worker.name!r} is there already")
        self.all[worker.name] = worker
        return worker

    def start(self, names: Iterable[str] | None = None) -> None:
        for name in self.all if names is None else names:
            self.all[name].start()

    def stop(self, timeout_s: float = 5.0) -> None:
        for worker in self.all.values():
            worker.stopping.set()
        for worker in self.all.values():
            worker.stop(timeout_s)

    def unhealthy(self, now_mono: float | None = None) -> list[str]:
        """The workers down for longer than their limit."""
        now = time.monotonic() if now_mono is None else now_mono
        return [w.name for w in self.all.values() if not w.healthy(now)]

    def status(self, now_mono: float | None = None) -> list[dict[str, Any]]:
        now = time.monotonic() if now_mono is None else now_mono
        return [w.as_dict(now) for w in self.all.values()]
