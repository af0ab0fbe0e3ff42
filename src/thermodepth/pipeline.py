"""The fusion pipeline: FramePair in, FusedFrame out.

For every frame pair:

1. registration, depth -> thermal: the nearest surface's Z and range per thermal pixel;
2. radiometry on the thermal grid: counts -> temperature with emissivity, reflected
   surroundings and the air along each pixel's own range; with a compensation model, the
   sensor's VOx effect is undone too (``radiance``: on the counts; ``paper``: eq. 20 on the
   reading, at the pixel's distance);
3. registration, thermal -> depth: temperature on the depth grid (occlusion-aware), with
   the ROIs' statistics summed while it samples; without ROIs, when first asked for (a run
   that only measures hotspots and alarms never needs it);
4. measurements: ROI statistics, hotspots in 3D, alarm rules.

One :class:`Settings` object (YAML) configures it all. Thermal pixels that no depth pixel
reaches (beyond the depth camera's range, invalid depth) are computed at a fallback
distance and flagged ``NO_DISTANCE``; a frame taken while the shutter is closed (FFC) is all
NaN, flagged ``SHUTTER``; invalid pixel values give NaN flagged ``BAD_COUNTS``; a frame without
a sensor (VOx) temperature is compensated at the model's reference VOx temperature, flagged
``NO_VOX``. The stream goes on.

The thermal pixel values are what the frame's telemetry or the calibration says
(:func:`~thermodepth.frames.thermal_output`): raw counts, or the camera's own temperature,
which the radiometry turns into the same signal. A frame most of whose values cannot be of that
kind (a kelvin output whose median is no temperature, counts beyond the ADC's range) is told in
one warning line, the first time (it is NaN, flagged ``BAD_COUNTS``, as any bad value).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Collection
from dataclasses import dataclass, field, replace
from enum import IntFlag
from functools import cached_property, partial
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import AfterValidator, Field, PrivateAttr, model_validator

from .alarms import AlarmRule, AlarmTracker
from .calibration import Calibration
from .camera import pixel_rays
from .compensation import CompensationModel, Flag, NoCompensation, load_model
from .conditions import ConditionsSchema, Radiometry, checked_condition
from .errors import FieldError, InputError, repeated
from .frames import FramePair, Telemetry, thermal_output
from .isotherms import IsothermArea, IsothermRoi, isotherm_area
from .lines import LineProfile, LineRoi, line_profile
from .materials import MATERIALS
from .measure import (
    DepthRangeRoi,
    Hotspot,
    PolygonRoi,
    RectRoi,
    Roi,
    RoiStats,
    find_hotspots,
    roi_region,
)
from .radiometry import (
    MAX_DISTANCE_M,
    PLANCK_PRESETS,
    RADIOMETRY_METHODS,
    TEMP_LIMITS_C,
    PlanckConstants,
    ThermalOutput,
    counts_from_kelvin,
)
from .registration import (
    INTERPOLATIONS,
    REGISTRATION_METHODS,
    Moments,
    Reason,
    Regions,
    Registration,
    ThermalOnDepth,
)
from .schema import PlanckSchema, StrictSchema, load_validated
from .severity import SeverityJudge, SeverityRow, SeveritySettings, all_tables, settings_problem

FloatArray = NDArray[np.float32]
GroupKey = tuple[float | None, float | None, str | None]
"""An ROI group's conditions: emissivity, reflected temperature (C), the reflector ROI that
sets it each frame (None where neither differs from the settings')."""

# Pipeline.warm_up's made-up frames: a wall at 30 C, 1 m away and nearer than any view table
# reaches (z < 0.1 m: the registration's other path); TLinear at 0.01 K a value
WARM_UP_TEMP_K = 303.15
WARM_UP_DISTANCES_M = (1.0, 0.05)
WARM_UP_TLINEAR_K = 0.01


class PixelFlag(IntFlag):
    """Per thermal pixel: the compensation's flags (same bits as
    :class:`thermodepth.compensation.Flag`) and the pipeline's own."""

    OK = 0
    DISTANCE_OUTSIDE = Flag.DISTANCE_OUTSIDE
    VOX_OUTSIDE = Flag.VOX_OUTSIDE
    TEMPERATURE_OUTSIDE = Flag.TEMPERATURE_OUTSIDE
    INVALID = Flag.INVALID
    NO_DISTANCE = 16  # no depth pixel reaches it: computed at the fallback distance
    BAD_COUNTS = 32  # no temperature from the value: NaN, beyond the ADC's range, no data
    SHUTTER = 64  # the frame shows the closed shutter (FFC), not the scene
    NO_VOX = 128  # the camera told no sensor temperature: compensated at the model's reference


# ---------------------------------------------------------------------------------------------
# Settings
# ---------------------------------------------------------------------------------------------


def _one_of(choices: Collection[str]) -> AfterValidator:
    """A pydantic check that a name is one of a ``method=`` registry's keys."""

    def check(name: str) -> str:
        if name not in choices:
            raise ValueError(f"choose from {sorted(choices)}")
        return name

    return AfterValidator(check)


# a temperature in the settings, C (radiometry.TEMP_LIMITS_C)
TempC = Annotated[float, Field(gt=TEMP_LIMITS_C[0], le=TEMP_LIMITS_C[1])]


class RadiometrySettings(ConditionsSchema):
    """The viewing conditions (:class:`~thermodepth.conditions.ConditionsSchema`: emissivity,
    ambient_temp_c, reflected_temp_c, humidity_pct, window), the radiometric model and the
    camera's Planck constants (a preset's name or R, B, F, O; None: a radiance compensation
    model's own, else paper2022)."""

    method: Annotated[str, _one_of(RADIOMETRY_METHODS)] = "flir"
    planck: Annotated[str, _one_of(PLANCK_PRESETS)] | PlanckSchema | None = None

    def constants(self) -> PlanckConstants | None:
        """The Planck constants the settings name, or None when they name none."""
        if self.planck is None or isinstance(self.planck, str):
            return None if self.planck is None else PLANCK_PRESETS[self.planck]
        return self.planck.constants()


class RegistrationSettings(StrictSchema):
    method: Annotated[str, _one_of(REGISTRATION_METHODS)] = "reproject"
    interpolation: Annotated[str, _one_of(INTERPOLATIONS)] = "nearest"


class HotspotSettings(StrictSchema):
    threshold_c: TempC = 50.0
    min_thermal_px: int = Field(default=1, ge=1)


def _polygon_area(vertices: list[tuple[float, float]]) -> float:
    """Area enclosed by a polygon of (u, v) vertices (shoelace formula), pixels^2."""
    u, v = np.asarray(vertices, np.float64).T
    return float(abs(np.dot(u, np.roll(v, -1)) - np.dot(v, np.roll(u, -1))) / 2)


class IsothermSettings(StrictSchema):
    """An isotherm's band: the pixels at or above ``above_c`` (C)."""

    above_c: TempC


SHAPES = ("rect", "polygon", "depth_range_m", "line", "isotherm")
"""The kinds of ROI; the last two (a line's profile, an isotherm's band and area) are
measured on the depth grid after it is sampled, not summed while it is."""


class RoiSettings(StrictSchema):
    """An ROI: one shape (``rect``, ``polygon``, ``depth_range_m``, ``line`` [[u0, v0],
    [u1, v1]] or ``isotherm`` {above_c}, optionally ``within`` another ROI) and, optionally
    (not for a line or an isotherm), the viewing conditions of what it covers where they
    differ from the settings' radiometry (a painted cabinet and a bare busbar in one view):
    ``emissivity`` and ``reflected_temp_c``."""

    name: str
    rect: tuple[int, int, int, int] | None = None
    polygon: list[tuple[float, float]] | None = Field(default=None, min_length=3)
    depth_range_m: tuple[float, float] | None = None
    line: tuple[tuple[float, float], tuple[float, float]] | None = None
    isotherm: IsothermSettings | None = None
    within: str | None = None
    emissivity: Annotated[float | None, checked_condition("emissivity")] = None
    reflected_temp_c: Annotated[float | None, checked_condition("reflected_temp_c")] = None
    # -- thermography (docs/thermography.md): severity class, material, reflector ----------
    severity: SeveritySettings | None = None
    material: Annotated[str, _one_of(MATERIALS)] | None = None
    reflector: bool = False
    reflects_for: list[str] = Field(default_factory=list)

    @property
    def own_emissivity(self) -> float | None:
        """The emissivity the ROI is read with where it differs from the settings': 1 for a
        reflector, else its ``emissivity``, else its ``material``'s, else None."""
        if self.reflector:
            return 1.0
        if self.emissivity is not None:
            return self.emissivity
        return None if self.material is None else MATERIALS[self.material].emissivity

    @model_validator(mode="after")
    def _reflector(self) -> RoiSettings:
        if self.reflector:
            if self.emissivity not in (None, 1.0) or self.material is not None:
                raise ValueError(
                    "a reflector is read at emissivity 1: give no emissivity or material"
                )
            if self.reflected_temp_c is not None or self.severity is not None:
                raise ValueError("a reflector has no reflected_temp_c or severity of its own")
        elif self.reflects_for:
            raise ValueError("reflects_for is for a reflector (reflector: true)")
        return self

    # -- end thermography --------------------------------------------------------------------

    @property
    def shape(self) -> str:
        """Which kind of ROI it is (:data:`SHAPES`)."""
        return next(k for k in SHAPES if getattr(self, k) is not None)

    @model_validator(mode="after")
    def _one_shape(self) -> RoiSettings:
        given = [k for k in SHAPES if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(
                "give exactly one of rect [u0, v0, u1, v1], polygon "
                "[[u, v], ...], depth_range_m [near, far], line [[u0, v0], [u1, v1]] "
                "or isotherm {above_c: C}"
            )
        # -- lines and isotherms (thermodepth.lines, thermodepth.isotherms) --
        if self.line is not None and self.line[0] == self.line[1]:
            raise ValueError(f"line {[list(p) for p in self.line]}: its ends are one pixel")
        if self.within is not None and self.isotherm is None:
            raise ValueError("within is for an isotherm (the ROI its band is confined to)")
        if given[0] in ("line", "isotherm") and (
            self.emissivity is not None or self.reflected_temp_c is not None
        ):
            raise ValueError(
                f"emissivity and reflected_temp_c are not for a {given[0]} (it reads the "
                "frame's temperatures, under the settings' radiometry)"
            )
        if self.rect is not None and not (
            self.rect[0] < self.rect[2] and self.rect[1] < self.rect[3]
        ):
            raise ValueError(f"rect {list(self.rect)}: expected u0 < u1 and v0 < v1 (pixels)")
        if self.polygon is not None and _polygon_area(self.polygon) == 0:
            raise ValueError(f"polygon {[list(p) for p in self.polygon]}: encloses no area")
        if self.depth_range_m is not None and not (
            0 <= self.depth_range_m[0] < self.depth_range_m[1]
        ):
            raise ValueError(
                f"depth_range_m {list(self.depth_range_m)}: expected 0 <= near < far (metres)"
            )
        return self

    def roi(self) -> Roi:
        if self.rect is not None:
            return RectRoi(self.name, *self.rect)
        if self.polygon is not None:
            return PolygonRoi(self.name, tuple(self.polygon))
        if self.line is not None:
            return LineRoi(self.name, self.line[0], self.line[1])
        if self.isotherm is not None:
            return IsothermRoi(self.name, self.isotherm.above_c, self.within)
        assert self.depth_range_m is not None
        return DepthRangeRoi(self.name, *self.depth_range_m)


class AlarmSettings(StrictSchema):
    """An alarm rule (:class:`~thermodepth.alarms.AlarmRule`; docs/pipeline.md): one
    condition (``above_c``, ``below_c``, ``rise_c_per_min`` over ``rise_window_s``, or
    ``delta_c`` against the ROI ``relative_to``; ``area_cm2_above`` for an isotherm) on
    ``what`` (``hotspot`` or an ROI, its ``stat``), held ``for_s`` seconds (or
    ``for_frames`` frames); cleared past ``clear_below_c`` / ``clear_above_c`` for
    ``clear_for_s``; ``latch``: raised until acknowledged; ``level``: warning or alarm."""

    name: str
    what: str = "hotspot"
    level: Literal["warning", "alarm"] = "alarm"
    above_c: TempC | None = None
    below_c: TempC | None = None
    rise_c_per_min: float | None = Field(default=None, gt=0)
    rise_window_s: float = Field(default=60.0, gt=0)
    delta_c: float | None = Field(default=None, gt=0)
    relative_to: str | None = None
    area_cm2_above: float | None = Field(default=None, gt=0)
    priority_at_most: int | None = Field(default=None, ge=1)  # an ROI's severity class
    stat: Literal["max", "mean", "min"] | None = None
    for_frames: int = Field(default=1, ge=1)
    for_s: float | None = Field(default=None, ge=0)
    clear_below_c: TempC | None = None
    clear_above_c: TempC | None = None
    clear_for_s: float = Field(default=0.0, ge=0)
    latch: bool = False

    def rule(self) -> AlarmRule:
        return AlarmRule(**self.model_dump())

    @model_validator(mode="after")
    def _a_rule(self) -> AlarmSettings:
        if self.for_s is not None and "for_frames" in self.model_fields_set:
            raise ValueError("give for_s (seconds) or for_frames, not both")
        self.rule()  # the rule's own checks, one line each
        return self


class ViewerSettings(StrictSchema):
    """The live viewer (``run --viewer``; docs/pipeline.md): at most ``max_hz`` frames a
    second logged (the others only counted), at most ``max_points`` points of each cloud
    (evenly strided), temperatures coloured on the fixed scale ``temp_range_c`` (C)."""

    max_hz: float = Field(default=5.0, gt=0)
    max_points: int = Field(default=60_000, ge=1000)
    temp_range_c: tuple[TempC, TempC] = (15.0, 80.0)

    @model_validator(mode="after")
    def _range(self) -> ViewerSettings:
        lo, hi = self.temp_range_c
        if not lo < hi:
            raise ValueError(f"temp_range_c {[lo, hi]}: expected low < high (C)")
        return self

    @property
    def fixed_range_c(self) -> tuple[float, float] | None:
        """The colour scale (C) when the settings give one (None: each run finds its own
        from its first frame with temperatures)."""
        return self.temp_range_c if "temp_range_c" in self.model_fields_set else None


class MqttSettings(StrictSchema):
    """Publishing to an MQTT broker (``run --mqtt URL``; docs/pipeline.md): a measurement
    summary at most ``measurements_hz`` times a second; alarms queued while the broker is
    away, up to ``max_queued`` (then the oldest are dropped, counted and told);
    ``password_file``: a file holding the password (else the environment's
    THERMODEPTH_MQTT_PASSWORD); ``ca_file``: the CA of an ``mqtts://`` broker (None: the
    system's); ``client_id``: None for one made from the host and process."""

    measurements_hz: float = Field(default=1.0, gt=0)
    max_queued: int = Field(default=10_000, ge=1)
    password_file: Path | None = None
    ca_file: Path | None = None
    client_id: str | None = None
    connect_timeout_s: float = Field(default=5.0, gt=0)


class Settings(StrictSchema):
    """Everything the pipeline needs, from one YAML file (paths relative to it); the
    ``viewer`` and ``mqtt`` sections are those of the run's sinks."""

    calibration: Path | None = None
    compensation: Path | None = None
    radiometry: RadiometrySettings = RadiometrySettings()
    registration: RegistrationSettings = RegistrationSettings()
    hotspots: HotspotSettings = HotspotSettings()
    rois: list[RoiSettings] = Field(default_factory=list)
    alarms: list[AlarmSettings] = Field(default_factory=list)
    severity_criteria: dict[str, list[SeverityRow]] = Field(default_factory=dict)
    fallback_distance_m: float | None = Field(default=None, gt=0, le=MAX_DISTANCE_M)
    viewer: ViewerSettings = ViewerSettings()
    mqtt: MqttSettings = MqttSettings()
    _path: Path | None = PrivateAttr(default=None)  # the file it was loaded from

    @property
    def where(self) -> str:
        """The settings file's name for messages (``settings`` when built in code)."""
        return str(self._path) if self._path else "settings"

    @classmethod
    def load(cls, path: str | Path) -> Settings:
        """Read and validate a settings YAML; one InputError line names file and field."""
        p = Path(path)
        s = load_validated(cls, p)
        base = p.parent
        mqtt = s.mqtt.model_copy(
            update={
                name: None if getattr(s.mqtt, name) is None else base / getattr(s.mqtt, name)
                for name in ("password_file", "ca_file")
            }
        )
        s = s.model_copy(
            update={
                "calibration": None if s.calibration is None else base / s.calibration,
                "compensation": None if s.compensation is None else base / s.compensation,
                "mqtt": mqtt,
            }
        )
        s._path = p
        return s

    @model_validator(mode="after")
    def _alarm_subjects(self) -> Settings:
        for kind, items in (("ROI", self.rois), ("alarm", self.alarms)):
            twice = repeated(i.name for i in items)
            if twice:
                raise ValueError(f"{kind} names must differ: {', '.join(map(repr, twice))} twice")
        names = {r.name for r in self.rois}
        for a in self.alarms:
            if a.what != "hotspot" and a.what not in names:
                raise ValueError(
                    f"alarm {a.name!r}: what={a.what!r} is neither 'hotspot' "
                    f"nor an ROI name ({', '.join(sorted(names)) or 'none'})"
                )
            if a.relative_to is not None and a.relative_to not in names:
                raise ValueError(
                    f"alarm {a.name!r}: relative_to={a.relative_to!r} is not an ROI name "
                    f"({', '.join(sorted(names)) or 'none'})"
                )
            if a.stat is not None and a.what == "hotspot":
                raise ValueError(f"alarm {a.name!r}: stat is for an ROI (a hotspot's max)")
        # -- lines and isotherms: within names an ROI of area; area rules watch isotherms --
        shapes = {r.name: r.shape for r in self.rois}
        for r in self.rois:
            if r.within is not None and shapes.get(r.within) not in SHAPES[:3]:
                raise ValueError(
                    f"ROI {r.name!r}: within={r.within!r} is not a rect, polygon or depth-range "
                    f"ROI ({', '.join(n for n, k in shapes.items() if k in SHAPES[:3]) or 'none'})"
                )
        isotherms = [n for n, k in shapes.items() if k == "isotherm"]
        for a in self.alarms:
            if a.area_cm2_above is not None and a.what not in isotherms:
                raise ValueError(
                    f"alarm {a.name!r}: area_cm2_above is for an isotherm ROI "
                    f"({', '.join(isotherms) or 'none'}), not {a.what!r}"
                )
            if a.area_cm2_above is not None and a.stat is not None:
                raise ValueError(f"alarm {a.name!r}: stat is not for an area rule")
        self._thermography_checks()
        return self

    # -- thermography (docs/thermography.md): severity tables, reflectors --------------------

    def _thermography_checks(self) -> None:
        by_name = {r.name: r for r in self.rois}
        severities = {r.name: r.severity for r in self.rois if r.severity is not None}
        why = settings_problem(self.severity_criteria, severities, list(by_name))
        if why:
            raise ValueError(why)
        for a in self.alarms:
            if a.priority_at_most is not None and a.what not in severities:
                raise ValueError(
                    f"alarm {a.name!r}: priority_at_most watches an ROI with a severity "
                    f"({', '.join(sorted(severities)) or 'none has one'})"
                )
        reflected: dict[str, str] = {}
        for r in self.rois:
            for name in r.reflects_for:
                target = by_name.get(name)
                if target is None or target.reflector:
                    raise ValueError(
                        f"roi {r.name!r}: reflects_for: {name!r} is not an ROI that is no reflector"
                    )
                if target.reflected_temp_c is not None:
                    raise ValueError(
                        f"roi {name!r}: reflected_temp_c and reflector {r.name!r} both set it"
                    )
                if name in reflected:
                    raise ValueError(
                        f"roi {name!r}: named by two reflectors ({reflected[name]!r}, {r.name!r})"
                    )
                reflected[name] = r.name

    def reflector_of(self, roi: str) -> str | None:
        """The reflector ROI whose reading is ``roi``'s reflected temperature, or None."""
        return next((r.name for r in self.rois if roi in r.reflects_for), None)

    # -- end thermography --------------------------------------------------------------------


# ---------------------------------------------------------------------------------------------
# The fused frame
# ---------------------------------------------------------------------------------------------


@dataclass(eq=False)
class FusedFrame:
    """One fused frame.

    Thermal grid (h, w): temp_thermal_c (compensated temperature, C), flags_thermal
    (:class:`PixelFlag`), z_thermal_m / range_thermal_m (nearest surface, NaN where none).
    Depth grid (H, W): temp_depth_c (C, NaN where reason_depth != Reason.OK), reason_depth
    (:class:`~thermodepth.registration.Reason`), both from :attr:`on_depth`, sampled by
    ``sample_depth`` when first asked for; depth (the raw uint16 frame).
    Measurements: hotspots (hottest first), rois, events (alarms raised or cleared); lines
    (:class:`~thermodepth.lines.LineProfile`) and isotherms
    (:class:`~thermodepth.isotherms.IsothermArea`) of the line and isotherm ROIs (their
    temperatures' figures are among ``rois`` too).
    """

    index: int
    depth_time_s: float
    thermal_time_s: float
    vox_temp_c: float  # NaN: the camera told none (PixelFlag.NO_VOX)
    in_ffc: bool
    temp_thermal_c: FloatArray
    flags_thermal: NDArray[np.uint8]
    z_thermal_m: FloatArray
    range_thermal_m: FloatArray
    sample_depth: Callable[[], ThermalOnDepth] = field(repr=False)
    depth: NDArray[np.uint16]
    calibration: Calibration
    hotspots: list[Hotspot] = field(default_factory=list)
    rois: list[RoiStats] = field(default_factory=list)
    events: list[dict[str, Any]] = field(default_factory=list)
    ir: NDArray[np.uint8] | None = None
    lines: list[LineProfile] = field(default_factory=list)
    isotherms: list[IsothermArea] = field(default_factory=list)

    @cached_property
    def on_depth(self) -> ThermalOnDepth:
        """The temperature on the depth grid and why a pixel has none (the registration's
        thermal -> depth of this frame), sampled once, when first asked for."""
        return self.sample_depth()

    @property
    def temp_depth_c(self) -> FloatArray:
        """Temperature (C) per depth pixel (H, W), NaN where reason_depth != Reason.OK."""
        return self.on_depth.values

    @property
    def reason_depth(self) -> NDArray[np.uint8]:
        """Why a depth pixel has no temperature (:class:`~thermodepth.registration.Reason`)."""
        return self.on_depth.reason

    @property
    def vox_label(self) -> str:
        """The VOx temperature as a line shows it: ``35.00 C``, or ``not told`` (NaN: the
        camera tells none)."""
        return "not told" if np.isnan(self.vox_temp_c) else f"{self.vox_temp_c:.2f} C"

    @cached_property
    def depth_m(self) -> FloatArray:
        """Depth Z in metres (H, W), NaN where invalid."""
        z = self.depth.astype(np.float32) * np.float32(self.calibration.depth_scale_m)
        z[self.depth == 0] = np.nan
        return z

    @cached_property
    def with_temperature(self) -> NDArray[np.intp]:
        """The flat indices (raster order) of the depth pixels that have a temperature."""
        return np.flatnonzero(self.reason_depth == Reason.OK)

    def points(self, every: int = 1) -> tuple[NDArray[np.float64], FloatArray]:
        """3D points (N, 3) in the depth camera's frame (m) of the depth pixels that have a
        temperature (every ``every``-th of them, in raster order), and their temperatures
        (N,) in C. Each is its pixel's cached ray (:func:`~thermodepth.camera.pixel_rays`)
        times its depth, as ``deproject`` gives it."""
        kept = self.with_temperature[::every]
        x, y = pixel_rays(self.calibration.depth)
        z = self.depth_m.ravel()[kept]
        pts = np.stack([x.ravel()[kept] * z, y.ravel()[kept] * z, z], axis=-1)
        return pts, self.temp_depth_c.ravel()[kept]

    def summary(self) -> dict[str, Any]:
        """Measurements as plain data (JSON lines)."""
        return {
            "frame": self.index,
            "thermal_time_s": round(self.thermal_time_s, 4),
            "depth_time_s": round(self.depth_time_s, 4),
            "vox_temp_c": round(self.vox_temp_c, 3),
            "in_ffc": self.in_ffc,
            "hotspots": [h.as_dict() for h in self.hotspots],
            "rois": [r.__dict__ for r in self.rois],
            "events": self.events,
            # lines and isotherms: only when the settings have them
            **({"lines": [p.as_dict() for p in self.lines]} if self.lines else {}),
            **({"isotherms": [i.as_dict() for i in self.isotherms]} if self.isotherms else {}),
        }


# ---------------------------------------------------------------------------------------------
# The pipeline
# ---------------------------------------------------------------------------------------------


class Pipeline:
    """Turns FramePairs into FusedFrames (see the module docstring).

    calibration: overrides ``settings.calibration`` (e.g. the one a source or recording
    carries). Raises InputError when neither gives one, or a frame's size does not match it.
    registration: one to share between pipelines of the same calibration and registration
    method (building one takes ~50 ms). model: the compensation model already loaded from
    ``settings.compensation`` (a batch ships it to workers that cannot read the file).
    warn: where the one line about frames whose values are not of the stated kind goes
    (default: Python's warnings).
    """

    def __init__(
        self,
        settings: Settings | None = None,
        calibration: Calibration | None = None,
        registration: Registration | None = None,
        model: CompensationModel | None = None,
        warn: Callable[[str], None] | None = None,
    ) -> None:
        self.settings = s = settings or Settings()
        self.warn = warn or (lambda line: warnings.warn(line, stacklevel=3))
        self._kind_told = False
        if calibration is None:
            if s.calibration is None:
                raise InputError(
                    "no calibration: give one in the settings (calibration: FILE) "
                    "or use a source that carries one"
                )
            calibration = Calibration.load(s.calibration)
        self.calibration = calibration
        if registration is None:
            registration = Registration(calibration, s.registration.method)
        elif registration.method != s.registration.method or (
            registration.calibration != calibration
        ):
            raise ValueError("the shared registration is of another calibration or method")
        self.registration = registration
        if model is None:
            model = load_model(s.compensation) if s.compensation is not None else NoCompensation()
        self.model: CompensationModel = model
        r = s.radiometry
        try:
            radiometry = self.model.radiometry(r.conditions(), r.constants(), r.method)
            self.radiometry = radiometry.with_output(calibration.thermal_output)
        except FieldError as exc:
            raise InputError(f"{s.compensation}: {exc.message}") from None
        self.rois = [roi.roi() for roi in s.rois]
        # lines and isotherms are measured on the sampled depth grid (measure_lines); the
        # others, ROIs of area, are summed while it is sampled
        self._lines = [r for r in self.rois if isinstance(r, LineRoi)]
        self._isotherms = [r for r in self.rois if isinstance(r, IsothermRoi)]
        area = [i for i, r in enumerate(self.rois) if not isinstance(r, LineRoi | IsothermRoi)]
        # where each ROI's pixels are, once: a fixed shape's box and mask, a depth range's
        # raw depth values (a line: its pixels); the registration sums them while it samples
        regions = {
            i: roi_region(self.rois[i], calibration.depth.shape, calibration.depth_scale_m)
            for i in (*area, *(i for i, r in enumerate(self.rois) if isinstance(r, LineRoi)))
        }
        # ROIs under the settings' conditions are summed while the frame's temperature is
        # sampled; each other set of conditions (an ROI's emissivity, reflected temperature,
        # the reflector whose reading is its reflected temperature) has its own temperatures
        # and its own sampling pass; the groups a reflector's reading sets come last, after
        # every reflector has been read
        groups: dict[GroupKey, list[int]] = {}
        for i in area:
            roi_settings = s.rois[i]
            reflector = s.reflector_of(roi_settings.name)
            key = (roi_settings.own_emissivity, roi_settings.reflected_temp_c, reflector)
            groups.setdefault(key, []).append(i)
        h_d = calibration.depth.height
        self._groups = [
            (key, members, Regions([regions[i] for i in members], h_d))
            for key, members in sorted(groups.items(), key=lambda kv: kv[0][2] is not None)
        ]
        self._index = {roi.name: i for i, roi in enumerate(self.rois)}
        self.severity = SeverityJudge(
            all_tables(s.severity_criteria),
            {r.name: r.severity for r in s.rois if r.severity is not None},
            float(r.ambient_temp_c),
        )
        for i, region in regions.items():
            roi = self.rois[i]
            if not isinstance(roi, DepthRangeRoi) and region.rows.start == region.rows.stop:
                h, w = calibration.depth.shape
                raise InputError(
                    f"{s.where}: rois.{i}: {roi.name!r} lies outside the {w}x{h} depth image "
                    f"(u 0..{w - 1}, v 0..{h - 1})"
                )
        self.alarms = AlarmTracker([a.rule() for a in s.alarms])

    # -- steps ------------------------------------------------------------------------------

    def check_sizes(self, pair: FramePair) -> None:
        """InputError naming the frame when an image's size is not its camera's."""
        cal = self.calibration
        for name, img, intr in (
            ("depth", pair.depth, cal.depth),
            ("thermal", pair.thermal, cal.thermal),
        ):
            if img.shape != intr.shape:
                raise InputError(
                    f"frame {pair.index}: the {name} image is {img.shape[1]}x{img.shape[0]} "
                    f"but the calibration's {name} camera is {intr.width}x{intr.height}"
                )

    def radiometry_of(self, pair: FramePair) -> Radiometry:
        """The radiometry of a pair's thermal values (their kind: the telemetry's, else the
        calibration's)."""
        output = thermal_output(pair.telemetry, self.calibration.thermal_output)
        return self.radiometry.with_output(output)

    def corrupt(self, pair: FramePair, radiometry: Radiometry) -> bool:
        """Whether most of a pair's values cannot be of their kind
        (:meth:`~thermodepth.radiometry.ThermalOutput.problem`: a corrupt frame, or a camera
        that sends another kind than stated): then none of its values is trusted. The first
        such frame is told through ``warn``."""
        if pair.telemetry.in_ffc:
            return False
        why = radiometry.output.problem(pair.thermal)
        if why is not None and not self._kind_told:
            self._kind_told = True
            self.warn(
                f"frame {pair.index}: {why} (its pixels are NaN, flagged bad_counts; later "
                "such frames are not told)"
            )
        return why is not None

    def temperatures(
        self,
        values: NDArray[np.generic],
        vox_c: float,
        distance_m: FloatArray,
        radiometry: Radiometry | None = None,
    ) -> tuple[FloatArray, NDArray[np.uint8]]:
        """Temperature (C) and flags of thermal pixel values (``radiometry``'s kind; None:
        the calibration's), at per-pixel distances (m): the compensation model's
        (:meth:`~thermodepth.compensation.CompensationModel.from_counts`), with invalid values
        NaN and flagged ``BAD_COUNTS``. A NaN ``vox_c`` (no sensor temperature) is
        compensated at the model's reference VOx temperature and flagged ``NO_VOX``."""
        radiometry = radiometry or self.radiometry
        extra = np.uint8(0)
        reference = self.model.vox_reference_c
        if not np.isfinite(vox_c) and reference is not None:
            vox_c, extra = reference, np.uint8(PixelFlag.NO_VOX)
        temp, flags = self.model.from_counts(values, vox_c, distance_m, radiometry)
        bad = radiometry.invalid(values)
        flags = flags | extra | np.where(bad, np.uint8(PixelFlag.BAD_COUNTS), np.uint8(0))
        out = np.where(bad, np.float32(np.nan), temp.astype(np.float32, copy=False))
        return out.astype(np.float32, copy=False), flags.astype(np.uint8, copy=False)

    def distances(self, range_m: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Each thermal pixel's distance (m) from its nearest surface's range (NaN where no
        depth pixel reaches it): those without one at the fallback distance (the settings',
        else the median of the known ranges, else 1 m); and where they are (mask)."""
        missing = np.isnan(range_m)
        if not missing.any():
            return range_m, missing
        # the median of every 4th pixel each way: robust, and 16x cheaper than all
        sample = range_m[::4, ::4]
        known = sample[np.isfinite(sample)]  # np.nanmedian's value, at a third of its cost
        s = self.settings
        fallback = s.fallback_distance_m or (float(np.median(known)) if known.size else 1.0)
        return np.where(missing, np.float32(fallback), range_m), missing

    def process(self, pair: FramePair) -> FusedFrame:
        """Fuse one frame pair (steps in the module docstring)."""
        self.check_sizes(pair)
        radiometry = self.radiometry_of(pair)
        s = self.settings
        near = self.registration.depth_to_thermal(pair.depth)
        distance, missing = self.distances(near.range_m)
        vox_c = pair.telemetry.fpa_temp_c
        if pair.telemetry.in_ffc or self.corrupt(pair, radiometry):
            # the shutter's image, or values mostly of no temperature: the few that look
            # like one are not trusted either (random values would make hotspots)
            why = PixelFlag.SHUTTER if pair.telemetry.in_ffc else PixelFlag.BAD_COUNTS
            temp = np.full(pair.thermal.shape, np.nan, np.float32)
            flags = np.full(pair.thermal.shape, why, np.uint8)
        else:
            temp, flags = self.temperatures(pair.thermal, vox_c, distance, radiometry)
        flags |= np.where(missing, np.uint8(PixelFlag.NO_DISTANCE), np.uint8(0))
        sample_depth = partial(
            self.registration.thermal_to_depth,
            pair.depth,
            temp,
            s.registration.interpolation,
            nearest=near,
        )
        frame = FusedFrame(
            pair.index,
            pair.depth_time_s,
            pair.thermal_time_s,
            vox_c,
            pair.telemetry.in_ffc,
            temp,
            flags,
            near.z_m,
            near.range_m,
            sample_depth,
            pair.depth,
            self.calibration,
            ir=pair.ir,
        )
        if frame.in_ffc:  # measurements never use the shutter's image
            return frame
        moments: list[Moments | None] = [None] * len(self.rois)
        for (emissivity, reflected_c, reflector), members, group in self._groups:
            if reflector is not None:  # the reflector's apparent temperature, read before
                read = moments[self._index[reflector]]
                reflected_c = read.mean if read is not None and read.n else None
            if emissivity is None and reflected_c is None and reflector is None:
                # summed while the frame is sampled
                sums = group.row_sums(flags)
                frame.on_depth = sample_depth(regions=sums)
            else:  # under their own conditions: their own temperatures, sampled for them
                own = radiometry.conditions.replace(
                    emissivity=radiometry.conditions.emissivity
                    if emissivity is None
                    else emissivity,
                    reflected_temp_c=(
                        radiometry.conditions.reflected_temp_c
                        if reflected_c is None
                        else reflected_c
                    ),
                )
                temp_g, flags_g = self.temperatures(
                    pair.thermal, vox_c, distance, replace(radiometry, conditions=own)
                )
                flags_g |= np.where(missing, np.uint8(PixelFlag.NO_DISTANCE), np.uint8(0))
                sums = group.row_sums(flags_g)
                self.registration.thermal_to_depth(
                    pair.depth, temp_g, s.registration.interpolation, nearest=near, regions=sums
                )
            for i, m in zip(members, Regions.moments(sums), strict=True):
                moments[i] = m
        self.measure(frame, [m for m in moments if m is not None])
        return frame

    # -- lines and isotherms (thermodepth.lines, thermodepth.isotherms) ---------------------

    def measure_lines(self, frame: FusedFrame) -> dict[str, RoiStats]:
        """Fill in the frame's line profiles and isotherms (none configured: nothing done,
        the depth grid not sampled for them); returns their temperatures' statistics by
        name, as the other ROIs' (flags not gathered: 0)."""
        if not self._lines and not self._isotherms:
            return {}
        cal = self.calibration
        t, z = frame.temp_depth_c, frame.depth_m
        frame.lines = [line_profile(line, z, t, cal.depth) for line in self._lines]
        by_name = {r.name: r for r in self.rois}
        frame.isotherms = [
            isotherm_area(
                iso,
                t,
                z,
                cal.depth,
                None if iso.within is None else by_name[iso.within].mask(z.shape, z),
            )
            for iso in self._isotherms
        ]
        stats = {p.name: RoiStats(p.name, *p.stats()) for p in frame.lines}
        for i in frame.isotherms:
            stats[i.name] = RoiStats(i.name, i.n, i.mean_c, i.max_c, i.min_c, i.sd_c)
        return stats

    def warm_up(self) -> None:
        """Run every numba kernel a frame of this pipeline runs once, so that numba compiles
        it now (or loads it from its cache): a monitor does so before its rigs' clocks start,
        so that a rig's first frames come on time and no rig's thread waits on another's
        compile (a compile holds Python's lock). On made-up frames (a wall at 30 C, 1 m away
        and nearer than the registration's view table reaches; in the calibration's kind of
        thermal values and in TLinear kelvin), through a copy of this pipeline: its alarms,
        trends and warnings are left as they were.

        Example:
            >>> from thermodepth.sim import default_calibration
            >>> Pipeline(Settings(), default_calibration()).warm_up()
        """
        cal = self.calibration
        copy = Pipeline(self.settings, cal, self.registration, self.model, warn=lambda _: None)
        planck = self.radiometry.planck
        signal = counts_from_kelvin(WARM_UP_TEMP_K, planck)
        tlinear = ThermalOutput.kelvin_per(WARM_UP_TLINEAR_K)
        for output in dict.fromkeys((cal.thermal_output, tlinear)):
            value = np.round(output.values(signal, planck)).astype(np.uint16)
            thermal = np.full(cal.thermal.shape, value, np.uint16)
            telemetry = Telemetry(
                0, WARM_UP_TEMP_K, WARM_UP_TEMP_K, tlinear=output.is_kelvin,
                tlinear_resolution_k=output.scale_k if output.is_kelvin else None,
            )  # fmt: skip
            for distance_m in WARM_UP_DISTANCES_M:
                depth = np.full(cal.depth.shape, round(distance_m / cal.depth_scale_m), np.uint16)
                frame = copy.process(FramePair(depth, thermal, 0.0, 0.0, telemetry))
                _ = frame.on_depth  # sampled when asked for, if no region asked for it

    def measure(self, frame: FusedFrame, roi_moments: list[Moments]) -> None:
        """Fill in the frame's hotspots, ROI statistics (from their sums, in the order of
        the settings' ROIs of area; lines and isotherms: :meth:`measure_lines`) and alarm
        events."""
        s = self.settings
        cal = self.calibration
        frame.hotspots = find_hotspots(
            frame.temp_thermal_c,
            frame.z_thermal_m,
            s.hotspots.threshold_c,
            cal.thermal,
            cal.thermal_from_depth,
            float(self.radiometry.conditions.ambient_temp_c),
            float(self.radiometry.conditions.emissivity),
            frame.flags_thermal,
            s.hotspots.min_thermal_px,
        )
        measured = self.measure_lines(frame)
        summed = iter(roi_moments)
        frame.rois = [
            measured[roi.name] if roi.name in measured else RoiStats.of(roi.name, next(summed))
            for roi in self.rois
        ]
        classes = self.severity.judge({r.name: r for r in frame.rois})
        if classes:  # each ROI's severity class goes with its reading
            frame.rois = [
                r if r.name not in classes else replace(r, severity=classes[r.name].as_dict())
                for r in frame.rois
            ]
        frame.events = self.alarms.update(
            frame.thermal_time_s,
            frame.index,
            frame.hotspots,
            frame.rois,
            {i.name: i.area_cm2 for i in frame.isotherms},
        )
