"""The simulated rig as a source (``sim``): FramePairs from :class:`thermodepth.sim.Rig`.

As fast as it can render by default (times from 0 s); in real time when paced
(``sim:pace=real``), as a live rig is, its frames stamped in Unix time as a live camera's are,
and then it can misbehave when told (``sim:faults=...``), as the monitor's tests need:

=======================  ======================================================================
fault                    what the simulated camera does
=======================  ======================================================================
``unplug@T+D``           at T s it is unplugged for D s: the stream stops with "device lost",
                         and opening it fails, until T + D
``stall@T``              at T s it stops sending, until it is closed and opened again (as a
                         PureThermal that stalls after hours)
``corrupt@T+D``          from T for D s its thermal frames are garbage (random values)
``ffc-storm@T+D``        from T for D s its shutter closes again and again (0.9 s of 1 s)
``vox-ramp@T``           from T on its sensor (VOx) temperature rises 1 K/s, out of any fitted
                         range
=======================  ======================================================================

Times are seconds since the simulated device was first opened in this process: it is a
device, so reopening it goes on where it was (the registry of devices by spec).
"""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..errors import FieldError, InputError
from ..frames import FfcState, StreamEvent, match_of
from ..sim import Rig, camera_pose, plate_scene
from .base import DeviceLostError, Source

FAULTS = ("unplug", "stall", "corrupt", "ffc-storm", "vox-ramp")
_FAULT = re.compile(
    r"^(unplug|stall|corrupt|ffc-storm|vox-ramp)@(\d+(?:\.\d+)?)s(?:\+(\d+(?:\.\d+)?)s)?$"
)
VOX_RAMP_K_PER_S = 1.0
BASE_FPA_K = 308.15


@dataclass(frozen=True)
class Fault:
    """One fault: ``kind`` (:data:`FAULTS`) from ``at_s`` for ``for_s`` seconds (None: for
    ever, or once for a stall)."""

    kind: str
    at_s: float
    for_s: float | None = None

    def active(self, t_s: float) -> bool:
        return t_s >= self.at_s and (self.for_s is None or t_s < self.at_s + self.for_s)


def parse_faults(text: str) -> tuple[Fault, ...]:
    """``unplug@20s+5s,stall@40s,...`` (joined by ``,`` or ``;``) -> faults; FieldError
    (``source``) naming the part that is not one."""
    faults = []
    for part in filter(None, re.split(r"[,;]", text)):
        m = _FAULT.match(part.strip())
        if m is None:
            raise FieldError(
                "source",
                f"faults: {part!r}: expected KIND@Ts or KIND@Ts+Ds, KIND one of "
                + ", ".join(FAULTS),
            )
        kind, at, span = m.group(1), float(m.group(2)), m.group(3)
        if kind in ("unplug", "corrupt", "ffc-storm") and span is None:
            raise FieldError("source", f"faults: {part!r}: {kind} needs a duration (+Ds)")
        faults.append(Fault(kind, at, None if span is None else float(span)))
    return tuple(faults)


@dataclass
class SimDevice:
    """A simulated device's state across openings: when it was first opened (monotonic and
    Unix s) and the stalls it has gone through."""

    t0: float = field(default_factory=time.monotonic)
    t0_unix: float = field(default_factory=time.time)
    stalled: set[float] = field(default_factory=set)

    def now_s(self) -> float:
        return time.monotonic() - self.t0


_DEVICES: dict[str, SimDevice] = {}
_DEVICES_LOCK = threading.Lock()


def sim_device(key: str) -> SimDevice:
    """The simulated device of a spec, made when first opened."""
    with _DEVICES_LOCK:
        return _DEVICES.setdefault(key, SimDevice())


class SimSource(Source):
    """Pairs from a simulated rig: the paper's plate with a 70 C chip, 1 m away, by default.

    rig: any :class:`~thermodepth.sim.Rig` (its true calibration is the source's); thermal,
    depth: the default rig's cameras (a name of
    :data:`~thermodepth.sim.cameras.THERMAL_CAMERAS`, a depth mode ``WxH[@FPS]``; None: the
    Lepton 3 beside a D435 at 1280x720); frames: stop after so many pairs (None: never);
    paced: in real time, as a live rig (faults need it); faults: what goes wrong when
    (module docstring); device: the key of the simulated device (its time and stalls go on
    across openings).
    """

    name = "sim"
    paired_by = "the simulator"

    def __init__(
        self,
        rig: Rig | None = None,
        frames: int | None = None,
        thermal: str | None = None,
        depth: str | None = None,
        paced: bool = False,
        faults: tuple[Fault, ...] = (),
        device: str = "sim",
    ) -> None:
        self.faults = faults
        self.paced = paced or bool(faults)
        self.live = self.paced
        self.device = sim_device(device) if self.paced else None
        start_s = self.device.now_s() if self.device is not None else 0.0
        unplugged = next((f for f in faults if f.kind == "unplug" and f.active(start_s)), None)
        if unplugged is not None:
            raise InputError(
                f"{device}: no simulated device (unplugged at {unplugged.at_s:g} s for "
                f"{unplugged.for_s:g} s)"
            )
        ramp = next((f for f in faults if f.kind == "vox-ramp"), None)
        fpa = (lambda t: BASE_FPA_K + VOX_RAMP_K_PER_S * max(0.0, t - ramp.at_s)) if ramp else None
        if rig is None:
            extra: dict[str, Any] = {"start_s": start_s}
            if fpa is not None:
                extra["fpa"] = fpa
            rig = Rig.of_cameras(
                plate_scene(chip_temp_c=70.0), camera_pose(1.0), thermal, depth, **extra
            )
        self.rig = rig
        self.cameras = {"thermal": thermal or "lepton3", "depth": depth or "1280x720"}
        self.frames = frames
        self.calibration = self.rig.calibration
        self._closed = threading.Event()
        self._rng = np.random.default_rng(self.rig.seed + 7)

    def events(self) -> Iterator[StreamEvent]:
        for pair in self.rig.frames(self.frames):
            if self.device is not None:
                # released when its time comes (its thermal time is device time)
                if self._closed.wait(max(0.0, pair.thermal_time_s - self.device.now_s())):
                    return
                pair = self._misbehave(pair)
                unix = self.device.t0_unix
                pair = replace(
                    pair,
                    depth_time_s=pair.depth_time_s + unix,
                    thermal_time_s=pair.thermal_time_s + unix,
                )
            elif self._closed.is_set():
                return
            yield match_of(pair)

    def _misbehave(self, pair: Any) -> Any:
        """The pair as the faults active at its time make it (module docstring)."""
        assert self.device is not None
        t = pair.thermal_time_s
        for f in self.faults:
            if not f.active(t):
                continue
            if f.kind == "unplug":
                raise DeviceLostError(f"sim: unplugged at {f.at_s:g} s (for {f.for_s:g} s)")
            if f.kind == "stall" and f.at_s not in self.device.stalled:
                self.device.stalled.add(f.at_s)
                self._closed.wait()  # sends nothing more until it is closed
            if f.kind == "corrupt":
                garbage = self._rng.integers(0, 65536, pair.thermal.shape, dtype=np.uint16)
                pair = replace(pair, thermal=garbage)
            if f.kind == "ffc-storm" and (t - f.at_s) % 1.0 < 0.9:
                pair = replace(
                    pair, telemetry=replace(pair.telemetry, ffc_state=FfcState.IN_PROGRESS)
                )
        return pair

    def close(self) -> None:
        """Stop: a paced rig waiting for its next frame, or stalled, returns at once."""
        self._closed.set()

    def settings(self) -> dict[str, Any]:
        return {
            "source": "sim",
            "seed": self.rig.seed,
            "with_ir": self.rig.with_ir,
            **self.cameras,
            **({"paced": True} if self.paced else {}),
            **({"faults": [f.__dict__ for f in self.faults]} if self.faults else {}),
        }


__all__ = ["FAULTS", "Fault", "SimSource", "parse_faults"]
