"""What every output of the monitor is: a small interface (:class:`Output`) the service drives
the same way for each, and what it gives them (:class:`OutputContext`).

An output is told each rig's fused frames (:meth:`Output.measured`, at the rig's rate: it keeps
its own), each rig's events once they are in the event store (:meth:`Output.events`), and the
monitor's clock (:meth:`Output.tick`). It starts in two steps: :meth:`Output.start` binds or
connects (one InputError line when it cannot) and says nothing to anyone; once every part of
the monitor has started, :meth:`Output.announce` tells the world (a broker's retained states,
discovery). Its long-running loops are :class:`~..workers.Worker` s the monitor supervises
(:meth:`Output.workers`). A reload keeps it when :meth:`Output.fits` the new rigs, else builds it
again.
"""

from __future__ import annotations

import socket
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple

from ...errors import InputError

if TYPE_CHECKING:
    from ...pipeline import FusedFrame, Settings
    from ..config import MonitorConfig
    from ..live import Picture, VideoFrame
    from ..store import EventStore
    from ..workers import Worker

Acknowledge = Callable[[str, str, str], list[dict[str, Any]]]
"""``acknowledge(rig, rule, by)``: the events of an acknowledgement (AckRefusedError when it
cannot be)."""
Pictures = Callable[[str, str, "int | None"], "Picture | None"]
"""``picture(rig, what, width)``: a rig's live ``overlay`` (JPEG) or ``thermal`` (PNG)."""
Videos = Callable[[str, str, float], "VideoFrame | None"]
"""``video(rig, view, hz)``: a rig's latest ``overlay`` or ``thermal`` picture framed for a
video stream playing at ``hz``."""


class RigEntities(NamedTuple):
    """What a rig shows a plant's systems: its name, location, ROIs and alarm rules (each in
    its settings' order), and which rules latch (wait for an acknowledgement)."""

    name: str
    location: str | None
    rois: list[str]
    rules: list[str]
    latched: tuple[str, ...] = ()

    @classmethod
    def of(cls, name: str, location: str | None, settings: Settings) -> RigEntities:
        """A rig's entities from its settings."""
        return cls(
            name,
            location,
            [roi.name for roi in settings.rois],
            [a.name for a in settings.alarms],
            tuple(a.name for a in settings.alarms if a.latch),
        )


def entities_of(config: MonitorConfig) -> list[RigEntities]:
    """Every rig's entities as a config sets them up (its settings files read), in its
    order; for what is told before the monitor runs (``--check``, a register map)."""
    from ...pipeline import Settings

    return [
        RigEntities.of(r.name, r.location, Settings.load(r.settings) if r.settings else Settings())
        for r in config.rigs
    ]


@dataclass
class OutputContext:
    """What the monitor gives an output's builder: the config, the rigs, the event store (its
    outbox), how to acknowledge, the live pictures, whom to tell when an event has been
    delivered (``delivered(event)``: the latency figures), the rigs' status now
    (``rig_status()``: ``/api/status``'s ``rigs``), an event's evidence as the HTTP API
    gives it (``evidence_of(event)``: its names; ``evidence_file(id, name)``: the file, None
    while there is none) and the rigs' video pictures (``video``)."""

    config: MonitorConfig
    rigs: list[RigEntities]
    store: EventStore
    acknowledge: Acknowledge
    picture: Pictures
    delivered: Callable[[dict[str, Any]], None]
    rig_status: Callable[[], list[dict[str, Any]]]
    evidence_of: Callable[[dict[str, Any]], list[str]]
    evidence_file: Callable[[int, str], Path | None]
    video: Videos


class Output:
    """One of the monitor's outputs (module docstring); every method but :meth:`describe` and
    :meth:`start` may be left as it is."""

    name: str
    """Its name in ``/api/status``'s ``outputs`` (and its rows' in the outbox): unique."""
    outbox: ClassVar[bool] = False
    """Its events are delivered from the event store's outbox (kept on disk until it has
    them: rows of its own, under its :attr:`name`)."""

    @property
    def section(self) -> str:
        """The config section it is made from (its key in ``OUTPUT_BUILDERS``)."""
        return self.name

    def wants(self, event: dict[str, Any]) -> bool:
        """Whether an event goes into the outbox for it (an outbox output)."""
        return True

    def describe(self) -> str:
        """One line: what it serves or where it sends (``monitor --check``, the log)."""
        raise NotImplementedError

    def start(self) -> None:
        """Bind or connect, telling no one yet; InputError (one line) when it cannot."""
        raise NotImplementedError

    def announce(self, raised: dict[str, set[str]]) -> None:
        """Every part has started: say so (``raised``: each rig's raised rules)."""

    def workers(self) -> list[Worker]:
        """Its long-running loops, for the monitor to start, supervise and stop: the same
        workers at every call (made once, with the output)."""
        return []

    def measured(self, rig: str, fused: FusedFrame) -> None:
        """A rig's fused frame (the rig's thread: never wait here)."""

    def events(self, rig: str, events: list[dict[str, Any]], raised: set[str]) -> None:
        """A rig's events, stored (each with its ``id``); ``raised``: its rules raised now."""

    def wake(self) -> None:
        """New rows in the outbox (an outbox output)."""

    def send_now(self, event: dict[str, Any]) -> None:
        """An event the store could not keep, sent from memory (an outbox output)."""

    def tick(self, now_mono: float) -> None:
        """The monitor's clock (every :data:`~..service.TICK_S`)."""

    def fits(self, rigs: list[RigEntities]) -> bool:
        """Whether it can go on as it is with these rigs after a reload (else it is built
        again)."""
        return True

    def status(self) -> dict[str, Any]:
        """What ``/api/status`` shows of it (``outputs.NAME``)."""
        return {}

    def stop(self, reason: str = "stopped") -> None:
        """Stop (its workers are stopped by the monitor first)."""


def check_port(host: str, port: int, what: str) -> None:
    """InputError ``WHAT: cannot listen (why)`` when ``(host, port)`` cannot be bound now, an
    IPv6 host too: a port that is taken is one line before a server starts, not its
    traceback later."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    try:
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind((host, port))
    except OSError as exc:
        raise InputError(f"{what}: cannot listen ({exc.strerror or exc})") from None
