"""Alarm rules and their lifecycle: raised, escalated, acknowledged, cleared.

A rule watches one subject of every measured frame (the hottest hotspot, or an ROI) and one
condition on it:

- ``above_c`` / ``below_c``: its value (the hotspot's max; an ROI's ``stat``) beyond a limit;
- ``rise_c_per_min``: the value rising faster than this, over the last ``rise_window_s``;
- ``delta_c``: the value above a reference ROI's mean by more than this (``relative_to``), the
  way a busbar is compared with its neighbour under the same load;
- ``area_cm2_above``: an isotherm's area on the surfaces (:mod:`thermodepth.isotherms`) above
  this many cm^2 (its events carry ``value_cm2``, and ``value_c`` None).
- ``priority_at_most``: the ROI's severity class (:mod:`thermodepth.severity`) as urgent as
  this priority or more (its priority number at most this); no class is not.

The condition must hold ``for_s`` seconds (or, as before, ``for_frames`` frames in a row) to
raise the rule (an on-delay: frame rates differ per camera). It clears once the value is back
past ``clear_below_c`` (``clear_above_c`` for a ``below_c`` rule; hysteresis, default the limit
itself) for ``clear_for_s`` seconds. A ``latch`` rule stays raised after that until someone
acknowledges it (:meth:`AlarmTracker.acknowledge`, who and when kept; it may come from another
thread than the frames'). Any raised rule may be acknowledged. A rule of level ``alarm``
raised while a ``warning`` rule on the same subject is raised is an escalation.

Every change of state is an event, a plain dict ready for JSON lines: ``event`` ``alarm``
(raised), ``escalated``, ``acknowledged`` or ``clear``, with the rule, its level, the
condition in words, the frame and its time, the value and what it was measured on.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any

import numpy as np

from .measure import Hotspot, RoiStats

LEVELS = ("warning", "alarm")
RAISED = ("alarm", "escalated")
"""The events that raise a rule (a raise, and a raise that escalates)."""
KINDS = ("above_c", "below_c", "rise_c_per_min", "delta_c", "area_cm2_above", "priority_at_most")
STATS = ("max", "mean", "min")


@dataclass(frozen=True)
class AlarmRule:
    """One rule (module docstring); exactly one of ``above_c``, ``below_c``,
    ``rise_c_per_min``, ``delta_c`` (with ``relative_to``). what: ``"hotspot"`` (the hottest
    hotspot's max) or an ROI's name, whose ``stat`` is watched (``max``; ``min`` for a
    ``below_c`` rule unless given)."""

    name: str
    above_c: float | None = None
    for_frames: int = 1
    what: str = "hotspot"
    level: str = "alarm"
    below_c: float | None = None
    rise_c_per_min: float | None = None
    rise_window_s: float = 60.0
    delta_c: float | None = None
    relative_to: str | None = None
    stat: str | None = None
    area_cm2_above: float | None = None
    for_s: float | None = None
    clear_below_c: float | None = None
    clear_above_c: float | None = None
    clear_for_s: float = 0.0
    latch: bool = False
    priority_at_most: int | None = None

    def __post_init__(self) -> None:
        given = [k for k in KINDS if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(
                f"alarm {self.name!r}: give exactly one of above_c, below_c, rise_c_per_min, "
                f"delta_c, area_cm2_above, priority_at_most (got {', '.join(given) or 'none'})"
            )
        if self.for_frames < 1:
            raise ValueError(f"alarm {self.name!r}: for_frames must be >= 1, got {self.for_frames}")
        if self.level not in LEVELS:
            raise ValueError(f"alarm {self.name!r}: level must be warning or alarm")
        if (self.delta_c is None) != (self.relative_to is None):
            raise ValueError(f"alarm {self.name!r}: delta_c and relative_to go together")
        if self.kind == "priority_at_most" and self.what == "hotspot":
            raise ValueError(f"alarm {self.name!r}: priority_at_most watches an ROI's severity")
        if self.clear_below_c is not None and self.kind not in ("above_c", "delta_c"):
            raise ValueError(f"alarm {self.name!r}: clear_below_c is for above_c or delta_c")
        if self.clear_above_c is not None and self.kind != "below_c":
            raise ValueError(f"alarm {self.name!r}: clear_above_c is for a below_c rule")
        limit = self.limit
        if self.clear_below_c is not None and self.clear_below_c > limit:
            raise ValueError(f"alarm {self.name!r}: clear_below_c must be at or below {limit:g}")
        if self.clear_above_c is not None and self.clear_above_c < limit:
            raise ValueError(f"alarm {self.name!r}: clear_above_c must be at or above {limit:g}")

    @property
    def kind(self) -> str:
        """Which condition: ``above_c``, ``below_c``, ``rise_c_per_min`` or ``delta_c``."""
        return next(k for k in KINDS if getattr(self, k) is not None)

    @property
    def limit(self) -> float:
        value = getattr(self, self.kind)
        assert value is not None
        return float(value)

    @property
    def watched(self) -> str:
        """The statistic of an ROI the rule watches."""
        return self.stat or ("min" if self.kind == "below_c" else "max")

    def condition(self) -> str:
        """The rule in words: ``above 60 C for 5 frames``."""
        words = {
            "above_c": f"above {self.limit:g} C",
            "below_c": f"below {self.limit:g} C",
            "rise_c_per_min": f"rising faster than {self.limit:g} C/min",
            "delta_c": f"more than {self.limit:g} C above {self.relative_to}",
            "area_cm2_above": f"area above {self.limit:g} cm2",
            "priority_at_most": f"severity priority {self.limit:g} or more urgent",
        }[self.kind]
        if self.for_s is not None:
            return f"{words} for {self.for_s:g} s"
        return f"{words} for {self.for_frames} frame{'s' if self.for_frames != 1 else ''}"

    def met(self, value: float) -> bool:
        """The condition holds for ``value`` (a rate for a rise rule, a difference for a
        delta rule)."""
        if not np.isfinite(value):
            return False
        if self.kind == "priority_at_most":
            return value <= self.limit
        return value < self.limit if self.kind == "below_c" else value > self.limit

    def gone(self, value: float) -> bool:
        """The value is back past the clear limit (the hysteresis); NaN (nothing measured:
        no hotspot above the threshold, an ROI without a valid pixel) is."""
        if not np.isfinite(value):
            return True
        if self.kind == "below_c":
            return value > (self.limit if self.clear_above_c is None else self.clear_above_c)
        if self.kind == "priority_at_most":
            return value > self.limit
        clear = self.clear_below_c if self.clear_below_c is not None else self.limit
        return value <= clear

    @property
    def history_bound(self) -> bool:
        """Whether the rule's state at a frame depends only on a bounded past (the frames of
        its delay and window): not so for a latch (it waits for a person), hysteresis (it
        stays raised while the value lingers between the limits) or a clear delay (it stays
        raised through every dip shorter than that)."""
        hysteresis = self.clear_below_c is not None or self.clear_above_c is not None
        return not (self.latch or hysteresis or self.clear_for_s > 0)

    @property
    def memory_s(self) -> float:
        """Seconds of past frames a history-bound rule's state depends on (besides
        ``for_frames``): its on-delay and its rise window."""
        window = self.rise_window_s if self.kind == "rise_c_per_min" else 0.0
        return (self.for_s or 0.0) + window


@dataclass
class RuleState:
    """Where a rule is: ``raised``; when its condition began (``since_s``) or its value came
    back (``back_s``); frames in a row (``count``); acknowledged (by whom, when)."""

    raised: bool = False
    since_s: float | None = None
    back_s: float | None = None
    count: int = 0
    acknowledged: dict[str, str] | None = None
    history: deque[tuple[float, float]] = field(default_factory=deque)


class AlarmTracker:
    """The rules' states over a stream of measured frames (module docstring)."""

    def __init__(self, rules: Sequence[AlarmRule]) -> None:
        self.rules = list(rules)
        self.states = {r.name: RuleState() for r in self.rules}
        self._last: tuple[float, int] = (float("nan"), -1)
        self._lock = threading.Lock()  # an acknowledgement may come from another thread

    @property
    def raised(self) -> list[str]:
        """The names of the rules raised now."""
        return [name for name, s in self.states.items() if s.raised]

    def value_of(
        self,
        rule: AlarmRule,
        hotspots: Sequence[Hotspot],
        by_name: dict[str, RoiStats],
        areas_cm2: Mapping[str, float] | None = None,
    ) -> tuple[float, Any]:
        """The value a rule watches in a frame (NaN: nothing to watch), and its subject
        (``areas_cm2``: the isotherms' areas by name, for an area rule)."""
        if rule.kind == "area_cm2_above":
            return (areas_cm2 or {}).get(rule.what, float("nan")), by_name.get(rule.what)
        if rule.what == "hotspot":
            hot = hotspots[0] if hotspots else None
            return (hot.max_c if hot else float("nan")), hot
        roi = by_name.get(rule.what)
        if rule.kind == "priority_at_most":  # the class's priority; NaN: none
            priority = (roi.severity or {}).get("priority") if roi else None
            return (float("nan") if priority is None else float(priority)), roi
        value = getattr(roi, f"{rule.watched}_c") if roi and roi.n else float("nan")
        if rule.kind == "delta_c":
            ref = by_name.get(rule.relative_to or "")
            value = value - ref.mean_c if ref and ref.n else float("nan")
        return value, roi

    @staticmethod
    def _rate(state: RuleState, rule: AlarmRule, time_s: float, value: float) -> float:
        """The value's rise over the rule's window, C per minute (NaN until it spans half of
        it): a least-squares slope of the finite values in the window."""
        h = state.history
        if np.isfinite(value):
            h.append((time_s, value))
        while h and h[0][0] < time_s - rule.rise_window_s:
            h.popleft()
        if len(h) < 3 or h[-1][0] - h[0][0] < 0.5 * rule.rise_window_s:
            return float("nan")
        t, v = np.array(h).T
        t = t - t.mean()
        return float(60.0 * (t @ (v - v.mean())) / (t @ t))

    def update(
        self,
        time_s: float,
        frame_index: int,
        hotspots: Sequence[Hotspot],
        rois: Iterable[RoiStats],
        areas_cm2: Mapping[str, float] | None = None,
    ) -> list[dict[str, Any]]:
        """The events of a measured frame (``areas_cm2``: its isotherms' areas by name)."""
        with self._lock:
            by_name = {r.name: r for r in rois}
            return self._events(time_s, frame_index, hotspots, by_name, areas_cm2)

    def _events(
        self,
        time_s: float,
        frame_index: int,
        hotspots: Sequence[Hotspot],
        by_name: dict[str, RoiStats],
        areas_cm2: Mapping[str, float] | None = None,
    ) -> list[dict[str, Any]]:
        events: list[dict[str, Any]] = []
        self._last = (time_s, frame_index)
        for rule in self.rules:
            s = self.states[rule.name]
            value, subject = self.value_of(rule, hotspots, by_name, areas_cm2)
            watched = self._rate(s, rule, time_s, value) if rule.kind == "rise_c_per_min" else value
            if not s.raised:
                if rule.met(watched):
                    s.count += 1
                    s.since_s = time_s if s.since_s is None else s.since_s
                    waited = (
                        time_s - s.since_s >= rule.for_s
                        if rule.for_s is not None
                        else s.count >= rule.for_frames
                    )
                    if waited:
                        s.raised, s.back_s, s.acknowledged = True, None, None
                        kind = "escalated" if self._escalates(rule) else "alarm"
                        events.append(_event(kind, rule, time_s, frame_index, watched, subject))
                else:
                    s.count, s.since_s = 0, None
                continue
            if rule.gone(watched) and not rule.met(watched):
                s.back_s = time_s if s.back_s is None else s.back_s
                if time_s - s.back_s >= rule.clear_for_s and (
                    not rule.latch or s.acknowledged is not None
                ):
                    events.append(self._clear(rule, s, time_s, frame_index, watched, subject))
            else:
                s.back_s = None
        return events

    def _escalates(self, rule: AlarmRule) -> bool:
        """A rule of level alarm raised while a warning rule on its subject is raised."""
        return rule.level == "alarm" and any(
            r.level == "warning" and r.what == rule.what and self.states[r.name].raised
            for r in self.rules
        )

    def _clear(
        self, rule: AlarmRule, s: RuleState, time_s: float, frame: int, value: float, subject: Any
    ) -> dict[str, Any]:
        s.raised, s.count, s.since_s, s.back_s = False, 0, None, None
        event = _event("clear", rule, time_s, frame, value, subject)
        if s.acknowledged is not None:
            event["acknowledged"] = s.acknowledged
        s.acknowledged = None
        return event

    def acknowledge(
        self, rule_name: str, by: str, at_utc: str | None = None
    ) -> list[dict[str, Any]]:
        """Acknowledge a raised rule: who (``by``) and when (UTC, now by default) are kept.
        Returns its events at once, at the time and frame of the last update: the
        ``acknowledged`` event and, for a latched rule whose value has come back, its
        ``clear``. KeyError for an unknown rule, ValueError for one not raised."""
        rule = next((r for r in self.rules if r.name == rule_name), None)
        if rule is None:
            raise KeyError(rule_name)
        with self._lock:
            s = self.states[rule_name]
            if not s.raised:
                raise ValueError(f"alarm {rule_name!r} is not raised")
            when = at_utc or datetime.now(timezone.utc).isoformat(timespec="seconds")
            s.acknowledged = {"by": by, "at_utc": when}
            time_s, frame = self._last
            event = _event("acknowledged", rule, time_s, frame, float("nan"), None)
            event.update(s.acknowledged)
            events = [event]
            if rule.latch and s.back_s is not None:
                events.append(self._clear(rule, s, time_s, frame, float("nan"), None))
            return events


def _event(
    kind: str, rule: AlarmRule, time_s: float, frame_index: int, value: float, subject: Any
) -> dict[str, Any]:
    event: dict[str, Any] = {
        "event": kind,
        "rule": rule.name,
        "level": rule.level,
        "condition": rule.condition(),
        "time_s": round(time_s, 4) if np.isfinite(time_s) else None,
        "frame": frame_index,
        rule.kind: rule.limit,
        "for_frames": rule.for_frames,
        "value_c": None if not np.isfinite(value) else round(value, 3),
    }
    if rule.kind == "area_cm2_above":  # an area, not a temperature
        event["value_cm2"], event["value_c"] = event["value_c"], None
    elif rule.kind == "priority_at_most":  # the value is a priority; the class says the rest
        event["value_c"] = None
        event["priority"] = int(value) if np.isfinite(value) else None
        if isinstance(subject, RoiStats) and subject.severity:
            event["severity"] = subject.severity
    if rule.for_s is not None:
        event["for_s"] = rule.for_s
    if isinstance(subject, Hotspot):
        event["hotspot"] = {
            k: v
            for k, v in subject.as_dict().items()
            if k in ("max_c", "mean_c", "centroid_m", "distance_m", "area_m2", "resolvable")
        }
    elif isinstance(subject, RoiStats):
        event["roi"] = subject.name
    return event


def event_line(event: dict[str, Any]) -> str:
    """An event as a line for people: ``ALARM hot [alarm]: 61.2 C (above 60 C for 5
    frames), frame 12``; an acknowledgement says by whom; an event of no frame (a rig that
    never delivered one) names none."""
    value = "" if event.get("value_c") is None else f": {event['value_c']} C"
    if event.get("value_cm2") is not None:
        value = f": {event['value_cm2']} cm2"
    elif event.get("priority") is not None:
        value = f": priority {event['priority']}"
    who = f" by {event['by']}" if event["event"] == "acknowledged" else ""
    frame = "" if event.get("frame") is None else f", frame {event['frame']}"
    return (
        f"{event['event'].upper()} {event['rule']} [{event.get('level', 'alarm')}]{value} "
        f"({event.get('condition', '')}){who}{frame}"
    )
