"""Fail-safe: a monitor that has quietly stopped seeing is the worst failure, so a rig whose
data cannot be trusted raises a ``sensor_fault`` alarm, through the same outputs as a
temperature alarm, and clears it when its data are good again:

==============  =====================================================================
fault           when
==============  =====================================================================
``no_data``     no new frame for the rig's ``stall_s`` (``ffc_grace_s`` more while its
                shutter is closing; ``startup_s`` for its first), reopening included
``vox_range``   the sensor (VOx / FPA) temperature beyond the range its compensation
                was fitted on, by more than ``vox_margin_c``
``shutter``     the shutter closed ``shutter_max_s`` on end, or more than
                ``shutter_max_share`` of the last ``shutter_window_s``
``corrupt``     most of a frame's pixels cannot be values of its kind, for ``corrupt_s``
==============  =====================================================================

The monitor's own ``storage_fault`` (a disk that fills anyway) goes through the same
:class:`Fault`. Events are dicts as :mod:`thermodepth.alarms` makes them, with ``fault``
naming which, and ``condition`` saying what was seen.
"""

from __future__ import annotations

import itertools
from collections import deque
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any

import numpy as np

from ..pipeline import FusedFrame, PixelFlag
from .config import FailsafeConfig

SENSOR_FAULT = "sensor_fault"
STORAGE_FAULT = "storage_fault"
SENSOR_FAULTS = ("no_data", "vox_range", "shutter", "corrupt")
CORRUPT_SHARE = 0.5
"""A frame more than half of whose pixels cannot be values of their kind is corrupt."""


@dataclass
class Fault:
    """One fault's state: raised once its condition has held ``on_s`` (s), cleared once it
    has been gone ``clear_s``; ``detail`` says what was last seen."""

    rule: str
    fault: str
    on_s: float = 0.0
    clear_s: float = 0.0
    raised: bool = False
    since: float | None = None
    back: float | None = None
    detail: str = ""
    acknowledged: dict[str, str] | None = None

    def update(
        self, now_s: float, active: bool, detail: str = "", frame: int | None = None
    ) -> dict[str, Any] | None:
        """The fault's event at time ``now_s`` (s) if its state changes, else None."""
        if active:
            self.back, self.detail = None, detail
            if self.raised:
                return None
            self.since = now_s if self.since is None else self.since
            if now_s - self.since < self.on_s:
                return None
            self.raised, self.acknowledged = True, None
            return self.event("alarm", now_s, frame)
        self.since = None
        if not self.raised:
            return None
        self.back = now_s if self.back is None else self.back
        if now_s - self.back < self.clear_s:
            return None
        self.raised = False
        event = self.event("clear", now_s, frame)
        if self.acknowledged is not None:
            event["acknowledged"] = self.acknowledged
        return event

    def event(self, kind: str, now_s: float, frame: int | None) -> dict[str, Any]:
        return {
            "event": kind,
            "rule": self.rule,
            "level": "alarm",
            "fault": self.fault,
            "condition": self.detail,
            "time_s": round(now_s, 4),
            "frame": frame,
            "value_c": None,
        }

    def acknowledge(self, by: str, now_s: float, frame: int | None) -> dict[str, Any]:
        """Who saw it and when (UTC): kept, and told by the event returned."""
        self.acknowledged = {
            "by": by,
            "at_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        }
        return {**self.event("acknowledged", now_s, frame), **self.acknowledged}


@dataclass
class SensorWatch:
    """The sensor faults of one rig (module docstring): ``frame`` for every fused frame,
    ``tick`` on the monitor's clock (no frame is also news). Times in seconds (the frames'
    clock: Unix time); vox_range_c: the compensation's fitted range (C; None: no VOx fault)."""

    config: FailsafeConfig
    stall_s: float
    vox_range_c: tuple[float, float] | None
    faults: dict[str, Fault] = field(init=False)
    last_frame: int | None = None  # none yet: a rig that never delivered
    _shutter: deque[tuple[float, bool]] = field(default_factory=deque)
    _closed_since: float | None = None

    def __post_init__(self) -> None:
        c = self.config
        on = {"corrupt": c.corrupt_s}
        clear = {"vox_range": c.clear_s, "shutter": c.clear_s, "corrupt": c.clear_s}
        self.faults = {
            name: Fault(SENSOR_FAULT, name, on.get(name, 0.0), clear.get(name, 0.0))
            for name in SENSOR_FAULTS
        }

    @property
    def raised(self) -> list[str]:
        return [name for name, f in self.faults.items() if f.raised]

    def _changes(self, now_s: float, states: dict[str, tuple[bool, str]]) -> list[dict[str, Any]]:
        events = []
        for name, (active, detail) in states.items():
            event = self.faults[name].update(now_s, active, detail, self.last_frame)
            if event is not None:
                events.append(event)
        return events

    def frame(self, fused: FusedFrame, now_s: float) -> list[dict[str, Any]]:
        """The fault events of a fused frame arriving at ``now_s``."""
        self.last_frame = fused.index
        c = self.config
        states: dict[str, tuple[bool, str]] = {"no_data": (False, "")}
        vox = fused.vox_temp_c
        if self.vox_range_c is not None and np.isfinite(vox):
            lo, hi = self.vox_range_c
            out = not lo - c.vox_margin_c <= vox <= hi + c.vox_margin_c
            states["vox_range"] = (
                out,
                f"VOx {vox:.2f} C outside the fitted {lo:g}-{hi:g} C (margin {c.vox_margin_c:g})",
            )
        states["shutter"] = self._shutter_state(fused.in_ffc, now_s)
        if not fused.in_ffc:
            bad = float(np.mean(fused.flags_thermal & PixelFlag.BAD_COUNTS > 0))
            states["corrupt"] = (
                bad > CORRUPT_SHARE,
                f"{100 * bad:.0f}% of the frame's pixels cannot be values of their kind",
            )
        return self._changes(now_s, states)

    def _shutter_state(self, closed: bool, now_s: float) -> tuple[bool, str]:
        c = self.config
        history = self._shutter
        history.append((now_s, closed))
        while history and history[0][0] < now_s - c.shutter_window_s:
            history.popleft()
        self._closed_since = (self._closed_since or now_s) if closed else None
        if self._closed_since is not None and now_s - self._closed_since >= c.shutter_max_s:
            return True, f"shutter closed for {now_s - self._closed_since:.1f} s"
        span = history[-1][0] - history[0][0]
        # the share of the time, not of the frames: frames that come late or are dropped
        # (a busy machine) would tilt a count towards the cheap frozen ones
        closed_s = sum(t1 - t0 for (t0, shut), (t1, _) in itertools.pairwise(history) if shut)
        share = closed_s / span if span > 0 else 0.0
        if span >= 0.5 * c.shutter_window_s and share > c.shutter_max_share:
            return True, f"shutter closed {100 * share:.0f}% of the last {span:.0f} s"
        return False, ""

    def tick(
        self, now_s: float, age_s: float, in_ffc: bool, first: bool = False
    ) -> list[dict[str, Any]]:
        """The no-data fault at ``now_s``, the last frame ``age_s`` old (s; the shutter
        closing when it came: ``in_ffc``; ``first``: none has come yet)."""
        limit = self.stall_s + (self.config.ffc_grace_s if in_ffc else 0.0)
        if first:
            limit = max(limit, self.config.startup_s)
        return self._changes(
            now_s, {"no_data": (age_s >= limit, f"no new frame for {age_s:.1f} s")}
        )

    def acknowledge(self, by: str, now_s: float) -> list[dict[str, Any]]:
        """Acknowledge every raised fault; their events. ValueError when none is raised."""
        raised = [f for f in self.faults.values() if f.raised]
        if not raised:
            raise ValueError(f"{SENSOR_FAULT} is not raised")
        return [f.acknowledge(by, now_s, self.last_frame) for f in raised]
