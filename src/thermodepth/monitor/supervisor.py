"""Each rig supervised on a thread of its own (:class:`RigRunner`): its source opened, its
session run, and whatever ends it (an error, a camera unplugged, a stall the monitor's clock
saw) followed by a reopening after a backoff of 1, 2, 4 ... 30 s, for ever. A stalled source
is asked to recover before it is reopened (a USB reset of a PureThermal board). The rig's
pipeline, and so its alarms' states, live across reopenings. One rig's fault never stops or
slows another: they share nothing but the monitor's outputs.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from ..alarms import RuleState
from ..calibration import Calibration
from ..errors import ThermodepthError
from ..pipeline import FusedFrame, Pipeline, Settings
from ..session import run_session
from ..sources import open_source, split_spec
from .config import FailsafeConfig, RigConfig, StorageConfig
from .evidence import Evidence, PreTrigger
from .failsafe import SENSOR_FAULT, SensorWatch
from .live import LiveView
from .logs import rig_logger
from .rig import PacedSource, RigSink, RigStatus
from .storage import CONTINUOUS, ContinuousRecorder
from .workers import BACKOFF_S

MB = 1e6


def monitor_spec(spec: str) -> str:
    """The spec a monitor opens: the simulator in real time (``pace=real``), as a camera."""
    kind, arg = split_spec(spec.strip())[0]
    if kind != "sim" or "pace=real" in arg:
        return spec.strip()
    return f"sim:{arg},pace=real" if arg else "sim:pace=real"


class AckRefusedError(Exception):
    """An acknowledgement that cannot be: ``status`` 404 (no such rig or rule) or 409 (not
    raised), ``message`` one line saying which."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status, self.message = status, message


class ClipNotReadyError(Exception):
    """An event's clip asked for while it is still being recorded (the seconds after the
    trigger): served once it is closed, never torn."""


class RigRunner:
    """One rig (module docstring). ``emit(sink, events, fused)``: where its events go;
    ``measured(sink, fused)``: told of each fused frame; ``log``: one line each of what
    ``on_storage_fault``: what its continuous recording could not keep. It logs to its own
    logger (``thermodepth.monitor.rig.NAME``)."""

    def __init__(
        self,
        config: RigConfig,
        storage: StorageConfig,
        failsafe: FailsafeConfig,
        evidence: Evidence,
        emit: Callable[[RigSink, list[dict[str, Any]], FusedFrame | None], None],
        measured: Callable[[RigSink, FusedFrame], None],
        on_storage_fault: Callable[[str], None],
    ) -> None:
        self.config, self.log = config, rig_logger(config.name)
        self.settings = Settings.load(config.settings) if config.settings else Settings()
        self.settings_text = (
            config.settings.read_text(encoding="utf-8") if config.settings else None
        )
        s = self.settings
        self.calibration = Calibration.load(s.calibration) if s.calibration else None
        self.spec = monitor_spec(config.source)
        kind = split_spec(self.spec)[0][0]
        self.replay = kind == "recording" and (config.pace or "recorded") == "recorded"
        self.ends = kind == "recording" and not self.replay
        self.paced = kind == "sim"
        self.wall_clock = not self.ends  # its frames carry Unix times
        self.status = RigStatus(config.name, config.location, config.source)
        self.watch = SensorWatch(failsafe, config.stall_s, None)
        continuous = (
            ContinuousRecorder(
                storage.path / CONTINUOUS / config.name, storage.segment_s, on_storage_fault
            )
            if storage.continuous
            else None
        )
        pre = PreTrigger(storage.pre_s, int(storage.pre_max_mb * MB))
        self.live = LiveView([r.roi() for r in s.rois], s.viewer.fixed_range_c)
        self.sink = RigSink(
            config.name, self.status, pre, evidence, continuous, self.watch, emit, measured,
            self.live,
        )  # fmt: skip
        self.pipeline: Pipeline | None = None
        self._carried: dict[str, RuleState] = {}  # rules' states from before a reload
        self.source: PacedSource | None = None
        self._stop = threading.Event()
        self._stalled: str | None = None
        self.thread = threading.Thread(target=self._run, name=f"rig {config.name}", daemon=True)

    @property
    def name(self) -> str:
        return self.config.name

    def carry_over(self, old: RigRunner) -> list[str]:
        """Before it starts, in place of ``old`` (the same rig, before a reload): each alarm
        rule unchanged keeps its state (raised, acknowledged: not raised again), and with
        the same source its sensor faults stay as they were. Returns the rules kept."""
        if old.pipeline is not None:
            rules = {r.name: r for r in old.pipeline.alarms.rules}
            self._carried = {
                a.name: old.pipeline.alarms.states[a.name]
                for a in self.settings.alarms
                if rules.get(a.name) == a.rule()
            }
        if old.config.source == self.config.source and old.config.stall_s == self.config.stall_s:
            self.watch = old.watch
            self.sink.watch = old.watch
        return sorted(self._carried)

    def say(self, line: str, level: int = logging.INFO) -> None:
        """A line of the rig's log, its name first."""
        self.log.log(level, "%s: %s", self.name, line)

    def warm_up(self) -> None:
        """Compile the numba kernels its frames run (:meth:`Pipeline.warm_up`) before it
        starts: with its settings and its calibration or, when its source will tell it, the
        simulated rig's (the kernels are the same). Settings it cannot load are left for its
        opening to say (its log, its reopening)."""
        from ..sim import default_calibration

        try:
            calibration = self.calibration or default_calibration()
            Pipeline(self.settings, calibration, warn=lambda _: None).warm_up()
        except ThermodepthError:
            pass

    def start(self) -> None:
        self.thread.start()

    def _open(self) -> PacedSource:
        c = self.config
        inner = open_source(
            self.spec,
            self.calibration,
            max_skew_s=c.max_skew_s,
            thermal_latency_s=c.thermal_latency_s,
            warn=lambda line: self.say(line, logging.WARNING),
            depth_mode=c.depth_mode,
        )
        index_from = 0 if self.source is None else self.source.last_index + 1
        source = PacedSource(
            inner, self.replay, self.paced, index_from, self.status.lag_s, self.status.count_drop
        )
        try:
            source.require_pairs()
            if self.pipeline is None:
                self.pipeline = Pipeline(
                    self.settings,
                    inner.calibration or self.calibration,
                    warn=lambda line: self.say(line, logging.WARNING),
                )
                self.watch.vox_range_c = self.pipeline.model.vox_range_c
                self.pipeline.alarms.states.update(self._carried)
        except BaseException:
            source.close()
            raise
        return source

    def _run(self) -> None:
        attempt, opened = 0, 0
        while not self._stop.is_set():
            try:
                self.source = self._open()
            except ThermodepthError as exc:
                self._reopen_later(attempt, f"cannot open ({exc})")
                attempt += 1
                continue
            if self._stop.is_set():  # stopped while it opened: stop() closed the one before
                self.source.close()
                break
            opened += 1
            self.status.reconnects = opened - 1
            frames = self.status.frames
            why = self._session(self.source)
            if self._stop.is_set():
                break
            if self._stalled is not None:
                self.status.stalls += 1
                recovery = self.source.recover()
                self.status.last_recovery = recovery
                why = f"stalled ({self._stalled})" + (f"; {recovery}" if recovery else "")
                self._stalled = None
            elif why == "end" and self.ends:
                self.status.state = "ended"
                self.say(f"{self.spec} replayed to its end")
                return
            attempt = 0 if self.status.frames > frames else attempt + 1
            self._reopen_later(attempt, why)
        self.status.state = "stopped"

    def _session(self, source: PacedSource) -> str:
        """Run one session; why it ended."""
        assert self.pipeline is not None
        try:
            result = run_session(source, self.pipeline, sinks=[self.sink])
        except ThermodepthError as exc:
            self.status.last_error = str(exc)
            return str(exc)
        except Exception as exc:  # a bug must not silence the rig: said, and reopened
            self.status.last_error = f"{type(exc).__name__}: {exc}"
            self.log.error("%s: unexpected error", self.name, exc_info=True)
            return self.status.last_error
        if result.error:
            return f"{result.stopped}: {result.error}"
        return result.stopped

    def _reopen_later(self, attempt: int, why: str) -> None:
        if self._stop.is_set():
            return
        wait_s = BACKOFF_S[min(attempt, len(BACKOFF_S) - 1)]
        self.status.state = "reopening"
        self.status.last_error = why
        self.say(f"{why}; reopening in {wait_s:g} s", logging.WARNING)
        self._stop.wait(wait_s)

    def abort_stalled(self, why: str) -> None:
        """Close a stalled source from the monitor's clock (its session then ends, the source
        is asked to recover, and it is reopened)."""
        source = self.source
        if source is None or self._stalled is not None or self.status.state != "running":
            return
        self._stalled = why
        self.status.state = "reopening"
        source.close()

    def stop(self, timeout_s: float = 10.0) -> None:
        self._stop.set()
        if self.source is not None:
            self.source.close()
        if self.thread.is_alive():
            self.thread.join(timeout_s)
        if self.thread.is_alive():  # it ends after its current step (it checks _stop)
            self.say(f"still busy {timeout_s:g} s after it was asked to stop", logging.WARNING)
        self.status.state = "stopped"

    @property
    def alive(self) -> bool:
        """Its thread runs (or ended as asked: a replay's end, a stop)."""
        return self.thread.is_alive() or self.status.state in ("ended", "stopped")

    def acknowledge(self, rule: str, by: str) -> list[dict[str, Any]]:
        """Acknowledge a raised rule (``sensor_fault``: every raised sensor fault); its
        events. AckRefusedError when the rig has no such rule or it is not raised."""
        if rule == SENSOR_FAULT:
            try:
                return self.watch.acknowledge(by, time.time())
            except ValueError:
                raise AckRefusedError(409, f"{self.name}: {rule} is not raised") from None
        if rule not in {a.name for a in self.settings.alarms}:
            raise AckRefusedError(404, f"{self.name}: no alarm rule {rule!r}")
        try:
            if self.pipeline is None:
                raise ValueError(rule)
            return self.pipeline.alarms.acknowledge(rule, by)
        except ValueError:
            raise AckRefusedError(409, f"{self.name}: {rule!r} is not raised") from None

    def raised(self) -> list[dict[str, Any]]:
        """The alarms and sensor faults raised now, with their levels and, once
        acknowledged, by whom and when (``acknowledged``: ``by``, ``at_utc``)."""
        out: list[dict[str, Any]] = []
        if self.pipeline is not None:
            alarms = self.pipeline.alarms
            for rule in alarms.rules:
                state = alarms.states[rule.name]
                if state.raised:
                    out.append({"rule": rule.name, "level": rule.level})
                    if state.acknowledged is not None:
                        out[-1]["acknowledged"] = dict(state.acknowledged)
        out += [{"rule": SENSOR_FAULT, "level": "alarm", "fault": f} for f in self.watch.raised]
        return out
