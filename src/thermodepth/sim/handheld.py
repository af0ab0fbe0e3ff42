"""A rig carried by hand: a person walks a closed path at a walking pace, looking where they
choose to look, with the step's bob, the hand's jitter and a few quick glances aside.

The path is a periodic cubic spline through waypoints (position, and a heading: yaw about the
world's up, pitch down), its knots spaced by the chord lengths, so the pace is nearly even
and the walk ends where and as it began. World frame as the scenes' (:mod:`.scene`): x right,
y down, z forward; the camera looks along +z at yaw 0, along +x at yaw 90 degrees. Times are
the frames' clock (seconds); the walk runs from ``start_s`` for ``duration_s``, standing still
before and after.

- Pace: the person eases in and out (a smoothstep speed ramp, ``ease_s``) and walks the loop
  at an even speed between; a walk too short to go round at ``max_pace_m_s`` goes part of
  the way out and back instead (at ``pace_m_s`` at most), so it still closes.
- Bob: each step lifts the camera ``bob_m`` (vertical sine at ``step_hz``), in proportion to
  the walking speed (none standing).
- Hand jitter: small smooth rotations about each axis, three sines each whose periods divide
  the walk (so it ends as it began), ``jitter_deg`` the largest amplitude.
- Glances: one every ``glance_every_s``, a quick turn of the head aside and back (a raised
  cosine in yaw, ``glance_deg`` over ``glance_s``: peak rate ~90-160 deg/s), views a mapper
  should drop for motion blur; the walk's own turns stay under ~60 deg/s.

Figures are stated choices for a person inspecting a machine or a room: walking ~0.4 m/s,
stepping at ~2 Hz with ~1 cm of vertical camera motion, a hand steady to a degree or two.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation

from ..camera import RigidTransform
from ..trajectory import Trajectory

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Waypoint:
    """Where the person passes (position_m, world, m) and where the camera looks there: yaw
    (degrees about the world's up; 0 along +z, 90 along +x) and pitch (degrees, down > 0)."""

    position_m: tuple[float, float, float]
    yaw_deg: float
    pitch_deg: float

    @classmethod
    def looking_at(cls, position_m: ArrayLike, target_m: ArrayLike) -> Waypoint:
        """A waypoint at ``position_m`` looking at ``target_m`` (both (3,), world, m)."""
        p = np.asarray(position_m, np.float64)
        d = np.asarray(target_m, np.float64) - p
        yaw = np.degrees(np.arctan2(d[0], d[2]))
        pitch = np.degrees(np.arctan2(d[1], np.hypot(d[0], d[2])))
        return cls((float(p[0]), float(p[1]), float(p[2])), float(yaw), float(pitch))


@dataclass(frozen=True)
class Gait:
    """How the person walks and holds the rig (module docstring; stated choices)."""

    pace_m_s: float = 0.4
    max_pace_m_s: float = 0.5
    ease_s: float = 1.5
    bob_m: float = 0.01
    step_hz: float = 2.0
    jitter_deg: float = 0.8
    glance_every_s: float = 10.0
    glance_deg: tuple[float, float] = (30.0, 40.0)
    glance_s: tuple[float, float] = (0.8, 1.0)


_JITTER_HZ = (0.35, 0.9, 1.7)  # the hand's slow sway, tremor-ish wobble, quick shake
_JITTER_SHARE = (1.0, 0.6, 0.3)  # of jitter_deg, per sine


class HandheldPath:
    """A walk through ``waypoints`` (a closed loop: it returns to the first) over
    ``duration_s`` from ``start_s``, as :class:`Gait` says; ``seed`` draws the jitter's
    phases and the glances. :meth:`poses` gives ``world_from_depth`` at any times."""

    def __init__(
        self,
        waypoints: Sequence[Waypoint],
        duration_s: float,
        seed: int = 0,
        start_s: float = 0.0,
        gait: Gait | None = None,
    ) -> None:
        if len(waypoints) < 3:
            raise ValueError("a closed walk needs three or more waypoints")
        if not duration_s > 0:
            raise ValueError("a walk lasts more than 0 s")
        self.gait = gait = gait or Gait()
        self.duration_s, self.start_s = float(duration_s), float(start_s)
        pos = np.array([w.position_m for w in waypoints] + [waypoints[0].position_m], float)
        chords = np.linalg.norm(np.diff(pos, axis=0), axis=1)
        if np.any(chords <= 0):
            raise ValueError("consecutive waypoints must differ in position")
        u = np.concatenate([[0.0], np.cumsum(chords)]) / chords.sum()
        yaw = np.degrees(np.unwrap(np.radians([w.yaw_deg for w in waypoints])))
        yaw = np.append(yaw, yaw[-1] + (yaw[0] - yaw[-1] + 180.0) % 360.0 - 180.0)  # closed
        self.turns = round((yaw[-1] - yaw[0]) / 360.0)  # whole turns round the loop
        pitch = [w.pitch_deg for w in waypoints] + [waypoints[0].pitch_deg]
        # the yaw less its steady turning is periodic, as are the position and the pitch
        self._position = CubicSpline(u, pos, bc_type="periodic")
        steady = yaw - 360.0 * self.turns * u
        steady[-1] = steady[0]  # equal but for rounding
        self._yaw = CubicSpline(u, steady, bc_type="periodic")
        self._pitch = CubicSpline(u, pitch, bc_type="periodic")
        dense = np.linspace(0.0, 1.0, 4001)
        speed = np.linalg.norm(self._position(dense, 1), axis=1)  # m per unit of u
        self.loop_m = float(np.trapezoid(speed, dense))
        self.ease_s = min(gait.ease_s, self.duration_s / 4)
        walking_s = self.duration_s - self.ease_s  # the ramps count half
        if self.loop_m / walking_s <= gait.max_pace_m_s:  # round the loop, once or more
            self.laps = max(1, round(gait.pace_m_s * walking_s / self.loop_m))
            self.out_and_back = 0.0
        else:  # out along the loop and back, the peak pace at pace_m_s
            self.laps = 0
            self.out_and_back = gait.pace_m_s * walking_s / (np.pi * self.loop_m)
            grid = np.linspace(self.start_s, self.end_s, 2001)
            for _ in range(3):  # the pace along the loop's start differs from its mean
                self.out_and_back *= gait.pace_m_s / self.speed_m_s(grid).max()
        rng = np.random.default_rng(seed)
        self._jitter_phase = rng.uniform(0.0, 2.0 * np.pi, (3, len(_JITTER_HZ)))
        self._jitter_cycles = [max(1, round(f * self.duration_s)) for f in _JITTER_HZ]
        self._glances = self._draw_glances(rng)

    def _draw_glances(self, rng: np.random.Generator) -> FloatArray:
        """(G, 3) rows start_s, length_s, amplitude_deg (signed): one per slot of the walk."""
        g = self.gait
        n = int(self.duration_s // g.glance_every_s)
        rows = []
        slot = (self.duration_s - 2 * self.ease_s) / max(n, 1)
        for i in range(n):
            length = rng.uniform(*g.glance_s)
            start = self.start_s + self.ease_s + i * slot + rng.uniform(0.0, slot - length)
            rows.append([start, length, rng.choice([-1.0, 1.0]) * rng.uniform(*g.glance_deg)])
        return np.array(rows, np.float64).reshape(-1, 3)

    @property
    def end_s(self) -> float:
        return self.start_s + self.duration_s

    def _progress(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The share of the walk done, p (0..1), at times ``t`` and its rate dp/dt (1/s): the
        speed ramps up as a smoothstep over ease_s, holds, and ramps down as it came."""
        e, d = self.ease_s, self.duration_s
        x = np.clip(t - self.start_s, 0.0, d)

        def ramp(y: FloatArray) -> tuple[FloatArray, FloatArray]:
            # distance (in units of the cruise speed) y seconds into the ramp, and the speed
            z = np.clip(y / e, 0.0, 1.0)
            return e * (z**3 - z**4 / 2) + np.maximum(y - e, 0.0), 3 * z**2 - 2 * z**3

        (a, ga), (b, gb) = ramp(x), ramp(d - x)
        total = d - e
        return np.where(x <= d / 2, a, total - b) / total, np.minimum(ga, gb) / total

    def _along(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The loop's parameter u (1 per lap) at times ``t`` and du/dt (1/s)."""
        p, rate = self._progress(t)
        if self.laps:
            return self.laps * p, self.laps * rate
        f = self.out_and_back
        return f * (1 - np.cos(2 * np.pi * p)) / 2, f * np.pi * np.sin(2 * np.pi * p) * rate

    def speed_m_s(self, times_s: ArrayLike) -> FloatArray:
        """The walking speed along the path (without the bob), m/s, at ``times_s`` (N,)."""
        u, du = self._along(np.asarray(times_s, np.float64).reshape(-1))
        return np.linalg.norm(self._position(u, 1), axis=1) * np.abs(du)

    def poses(self, times_s: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``world_from_depth`` rotations (N, 3, 3) and positions (N, 3) m at ``times_s``
        (N,), s; held before the start and after the end."""
        t = np.asarray(times_s, np.float64).reshape(-1)
        g = self.gait
        u, _ = self._along(t)
        x = np.clip(t - self.start_s, 0.0, self.duration_s)
        pos = self._position(u)
        lift = np.minimum(self.speed_m_s(t) / g.pace_m_s, 1.0)
        pos[:, 1] += g.bob_m * lift * np.sin(2 * np.pi * g.step_hz * x)
        angles = np.stack(
            [self._yaw(u) + 360.0 * self.turns * u, self._pitch(u), np.zeros_like(t)], axis=1
        )
        for i, (cycles, share) in enumerate(zip(self._jitter_cycles, _JITTER_SHARE, strict=True)):
            phase = 2 * np.pi * cycles * x[:, None] / self.duration_s + self._jitter_phase[:, i]
            angles += g.jitter_deg * share * np.sin(phase)
        for start, length, amplitude in self._glances:
            into = np.clip((t - start) / length, 0.0, 1.0)
            angles[:, 0] += amplitude * (1 - np.cos(2 * np.pi * into)) / 2
        yaw, pitch, roll = np.radians(angles).T
        rot = Rotation.from_euler("YXZ", np.stack([yaw, -pitch, roll], axis=1)).as_matrix()
        return rot.reshape(-1, 3, 3), pos

    def pose_at(self, time_s: float) -> RigidTransform:
        """``world_from_depth`` at ``time_s`` (what :class:`~.rig.Rig`'s trajectory takes)."""
        rot, pos = self.poses([time_s])
        return RigidTransform(rot[0], pos[0], "world", "depth")

    def trajectory(self, times_s: ArrayLike) -> Trajectory:
        """The true trajectory at ``times_s`` (increasing), s."""
        t = np.asarray(times_s, np.float64).reshape(-1)
        rot, pos = self.poses(t)
        return Trajectory(t, rot, pos)
