"""What every notification target (``notify:``; :mod:`.webhook`, :mod:`.email`) shares: its
delivery from the event store's outbox, retried, limited per hour, with a digest of what was
held back.

Each target is an outbox output of its own: the events its ``events`` let through get a row
of its name in the outbox (:mod:`..store`), kept on disk until the target has them, across a
restart of the monitor. One supervised worker per target (``notify KIND:NAME``) sends them,
oldest first, one message per event (its ``id`` tells a receiver a repeat: at least once):

- a temporary failure (the receiver away, refusing, timing out, an HTTP 5xx or 429, an SMTP
  4xx) is retried after :data:`BACKOFF_S` (1 s, 2 s, ... 5 min), the rows waiting on disk;
- a permanent one (an HTTP 4xx, an SMTP 5xx: the message itself is refused) is not: counted
  (``failed``), logged, its rows out of the outbox;
- at most ``max_per_hour`` messages go in any :data:`HOUR_S`; the events beyond are held back
  and, once the hour allows one more message, go together as one digest listing them (at most
  :data:`DIGEST_MAX` a message).

An event the store could not take (a full disk) waits in memory (:data:`MEMORY_MAX`, oldest
dropped and counted) and goes the same way. A rig's thread only sets an event (:meth:`wake`).
The counts since start and the rows waiting show in ``/api/status``'s ``outputs``. Tests make
:data:`BACKOFF_S` and :data:`HOUR_S` short by setting them.
"""

from __future__ import annotations

import ssl
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any

from ...app.report import Period
from ...io.measurements import jsonable
from ..config import EmailConfig, NotifyTarget, WebhookConfig
from ..logs import logger
from ..workers import Worker
from .base import Output, OutputContext

BACKOFF_S = (1.0, 2.0, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0)
"""The waits before each retry of a temporary failure (the last repeated)."""
HOUR_S = 3600.0
"""The window of ``max_per_hour``."""
DIGEST_MAX = 200
"""Events listed in one digest at most (the rest: the next)."""
MEMORY_MAX = 1000
"""Events the store could not take, kept in memory for a target at most."""
PICTURE_WAIT_S = 10.0
"""How long a message waits for its event's overlay to be drawn (then goes without)."""
WAKE_S = 1.0
UNMADE_TRIES = 3
"""A message that cannot be made (not a receiver's answer: an error of ours, a file gone)
is tried so many times, then counted in ``failed`` and given up, so that it cannot stop
its target for ever."""
LIMIT_S = 120.0
"""How long a target's worker may be down before the monitor is unwell."""


class DeliveryError(Exception):
    """A message not delivered: ``retry`` when it may be later (temporary)."""

    def __init__(self, message: str, retry: bool) -> None:
        super().__init__(message)
        self.message, self.retry = message, retry


class Notifier(Output):
    """One notification target (module docstring); a kind says how a message is sent
    (:meth:`send`) and told (:func:`describe`)."""

    outbox = True

    def __init__(self, config: NotifyTarget, context: OutputContext) -> None:
        self.config, self.context = config, context
        self.store = context.store
        self.name = config.target_name()
        self.log = logger("notify")
        public = context.config.http.public_url
        self.public_url = None if public is None else public.rstrip("/")
        self.delivered = self.digests = self.held = self.retries = self.failed = 0
        self.lost = 0  # events the store could not take, dropped from a full memory
        self.last_error: str | None = None
        self._wake = threading.Event()
        self._memory: deque[dict[str, Any]] = deque()
        self._memory_lock = threading.Lock()
        self._sent_mono: deque[float] = deque()  # the last hour's messages
        self._held: set[int] = set()  # ids held back by the hourly limit
        # a beat between attempts; one attempt may take its timeout a few times over
        every_s = WAKE_S + 4 * config.timeout_s
        self._worker = Worker(f"notify {self.name}", self._deliver, every_s, LIMIT_S, self.log)

    @property
    def section(self) -> str:
        return "notify"

    def describe(self) -> str:
        return describe(self.config)

    def start(self) -> None:
        """Nothing to bind: the receiver may be away now, its events wait."""

    def workers(self) -> list[Worker]:
        return [self._worker]

    def wants(self, event: dict[str, Any]) -> bool:
        return self.config.goes(event)

    def wake(self) -> None:
        self._wake.set()

    def send_now(self, event: dict[str, Any]) -> None:
        """An event the store could not take: kept in memory for the worker (the oldest
        dropped, counted and logged, beyond :data:`MEMORY_MAX`)."""
        if not self.wants(event):
            return
        with self._memory_lock:
            if len(self._memory) >= MEMORY_MAX:
                gone = self._memory.popleft()
                self.lost += 1
                self.log.error("%s: memory full, event not sent: %s", self.name, label(gone))
            self._memory.append(event)
        self._wake.set()

    # -- the worker -----------------------------------------------------------------------------

    def _deliver(self, worker: Worker) -> None:
        attempt = 0
        while not worker.stopping.is_set():
            worker.beat()
            with self._memory_lock:
                memory = list(self._memory)
            pending = (memory + self.store.outbox(DIGEST_MAX, target=self.name))[:DIGEST_MAX]
            if not pending:
                self._wake.wait(WAKE_S)
                self._wake.clear()
                continue
            now = time.monotonic()
            while self._sent_mono and now - self._sent_mono[0] >= HOUR_S:
                self._sent_mono.popleft()
            if len(self._sent_mono) >= self.config.max_per_hour:
                self._held.update(e["id"] for e in pending if "id" in e)
                self.held = len(self._held)
                worker.stopping.wait(min(WAKE_S, self._sent_mono[0] + HOUR_S - now))
                continue
            held = any(e.get("id") in self._held for e in pending)
            batch = pending if held and len(pending) > 1 else pending[:1]
            try:
                try:
                    self.send(batch, digest=len(batch) > 1)
                except DeliveryError:
                    raise
                except Exception as exc:  # a message that cannot be made: tried a few times
                    self.log.error("%s: cannot make its message", self.name, exc_info=True)
                    raise DeliveryError(
                        f"cannot make its message ({type(exc).__name__}: {exc})",
                        retry=attempt + 1 < UNMADE_TRIES,
                    ) from exc
            except DeliveryError as exc:
                self.last_error = exc.message
                if exc.retry:
                    self.retries += 1
                    wait_s = BACKOFF_S[min(attempt, len(BACKOFF_S) - 1)]
                    attempt += 1
                    self.log.warning("%s: %s; again in %g s", self.name, exc.message, wait_s)
                    pause(worker, wait_s)
                    continue
                self.failed += len(batch)
                self.log.error(
                    "%s: %s; not retried: %s", self.name, exc.message, ", ".join(map(label, batch))
                )
            else:
                attempt = 0
                self.last_error = None
                self._sent_mono.append(time.monotonic())
                self.delivered += len(batch)
                self.digests += len(batch) > 1
            self._done(batch)

    def _done(self, batch: list[dict[str, Any]]) -> None:
        """The events of a message sent (or refused for good): out of memory and the outbox."""
        with self._memory_lock:
            for event in batch:
                if any(event is kept for kept in self._memory):
                    self._memory.remove(event)
        for event in batch:
            if "id" in event:
                self.store.delivered(event["id"], self.name)
                self._held.discard(event["id"])
        self.held = len(self._held)

    def send(self, events: list[dict[str, Any]], digest: bool) -> None:
        """Send one message: one event, or a digest of several held back (DeliveryError when
        it cannot)."""
        raise NotImplementedError

    def send_report(self, path: Path, period: Period, summary: str) -> None:
        """Send a scheduled inspection report (:mod:`..reports`; ``summary``: what it holds
        in a few words, or empty); DeliveryError when it cannot."""
        raise NotImplementedError

    def report_link(self, path: Path) -> str | None:
        """The report's address on the monitor's web server (``http.public_url`` set)."""
        return None if self.public_url is None else f"{self.public_url}/api/reports/{path.name}"

    # -- what a message tells -------------------------------------------------------------------

    def public(self, event: dict[str, Any]) -> dict[str, Any]:
        """An event as ``/api/events`` gives it (its ``evidence``), with ``links`` to it and
        its evidence when ``http.public_url`` is set."""
        out = {**jsonable(event), "evidence": self.context.evidence_of(event)}
        if self.public_url is not None and "id" in event:
            base = f"{self.public_url}/api/events/{event['id']}"
            out["links"] = {
                "event": base,
                "events_page": f"{self.public_url}/events",
                **{name: f"{base}/{name}" for name in out["evidence"]},
            }
        return out

    def snapshot(self, event: dict[str, Any]) -> Path | None:
        """The event's overlay (``snapshot.png``) when it has one: its picture is drawn after
        the event is out, so it is waited for up to :data:`PICTURE_WAIT_S`."""
        if "id" not in event or "snapshot.png" not in self.context.evidence_of(event):
            return None
        deadline = time.monotonic() + PICTURE_WAIT_S
        while True:
            found = self.context.evidence_file(event["id"], "snapshot.png")
            stopping = self._worker.stopping
            if found is not None or time.monotonic() >= deadline or stopping.wait(0.2):
                return found

    def ssl_context(self) -> ssl.SSLContext:
        """Certificates verified, against ``ca_file`` when given."""
        ca = self.config.ca_file
        return ssl.create_default_context(cafile=None if ca is None else str(ca))

    def status(self) -> dict[str, Any]:
        return {
            "target": target_of(self.config),
            "delivered": self.delivered,
            "digests": self.digests,
            "waiting": self.store.waiting(self.name) + len(self._memory),
            "held_back": self.held,
            "retries": self.retries,
            "failed": self.failed,
            "lost": self.lost,
            "last_error": self.last_error,
        }

    def stop(self, reason: str = "stopped") -> None:
        self._wake.set()


def pause(worker: Worker, wait_s: float) -> None:
    """Wait (beating: a long backoff is not a hung worker) until ``wait_s`` is over or the
    worker stops."""
    end = time.monotonic() + wait_s
    while (left := end - time.monotonic()) > 0 and not worker.stopping.wait(min(left, WAKE_S)):
        worker.beat()


def label(event: dict[str, Any]) -> str:
    """An event in a few words: ``#12 line1 hot alarm``."""
    number = f"#{event['id']} " if "id" in event else ""
    return f"{number}{event.get('rig')} {event.get('rule')} {event.get('event')}"


def target_of(config: NotifyTarget) -> str:
    """Where a target sends, without secrets (a URL's user, path and query may hold one)."""
    if isinstance(config, WebhookConfig):
        from urllib.parse import urlsplit

        url = urlsplit(config.url)
        where = url.hostname or ""
        port = f":{url.port}" if url.port else ""
        return f"{url.scheme}://{where}{port}/..."
    assert isinstance(config, EmailConfig)
    return f"{', '.join(config.to)} via {config.smtp}"


def describe(config: NotifyTarget) -> str:
    """A target in one line (``monitor --check``), no secret in it."""
    rate = f"events {', '.join(config.events)}; at most {config.max_per_hour}/h, then a digest"
    if isinstance(config, WebhookConfig):
        return f"webhook {config.target_name()}: POST to {target_of(config)}, signed; {rate}"
    assert isinstance(config, EmailConfig)
    tls = "STARTTLS" if config.starttls else "no TLS"
    who = f", as {config.user}" if config.user else ""
    return (
        f"e-mail {config.target_name()}: from {config.sender} to {target_of(config)} "
        f"({tls}{who}); {rate}"
    )


def notifier(config: NotifyTarget, context: OutputContext) -> Notifier:
    """The output of a ``notify`` entry."""
    if isinstance(config, WebhookConfig):
        from .webhook import WebhookOutput

        return WebhookOutput(config, context)
    from .email import EmailOutput

    assert isinstance(config, EmailConfig)
    return EmailOutput(config, context)
