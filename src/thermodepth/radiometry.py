"""Radiometry: Planck's law, the RBFO count model, emissivity, atmosphere and window.

Temperatures are kelvin and lengths metres inside; ``raw_to_celsius``/``celsius_to_raw`` are
the Celsius edge. A thermal camera's count S is modelled (Lin & Yao 2022, eqs 16-19, FLIR's
calibration form) as S = O + R / (exp(B / T) - F) for a blackbody at T. A real scene mixes
several sources in the signal S - O, which is linear in radiance:

    S = sum_k w_k S(T_k),   sum_k w_k = 1

with k over the object, reflected surroundings, atmosphere and an optional external window.
The weights w_k come from emissivity, atmospheric transmission tau(d) and the window's
transmission, and differ between methods (``RADIOMETRY_METHODS``):

- ``"flir"``: single pass over the full distance, as FLIR's own software does:
  S = IRT [tau E W(To) + tau (1-E) W(Tr) + (1-tau) W(Ta)] + (1-IRT) W(Twin).
- ``"thermimage"``: the Thermimage R package's model (window halfway, tau1 = tau2 = tau(d/2)),
  kept for compatibility with it and with its Python ports.

Because the weights sum to one, the offset O cancels and S can be mixed as it is.
``distance_m`` and ``emissivity`` may be per-pixel arrays: the depth camera measures a distance
for every pixel.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

# CODATA 2018 exact SI constants.
PLANCK_H = 6.62607015e-34  # J s
SPEED_OF_LIGHT = 299_792_458.0  # m / s
BOLTZMANN_K = 1.380649e-23  # J / K
# CODATA 2018 derived constants.
STEFAN_BOLTZMANN = 5.670374419e-8  # W m^-2 K^-4
WIEN_B = 2.897771955e-3  # m K (the paper's eq 15 uses 2.89776829e6 nm K, CODATA 1998)
C1L = 2.0 * PLANCK_H * SPEED_OF_LIGHT**2  # first radiation constant for radiance, W m^2 / sr
C2 = PLANCK_H * SPEED_OF_LIGHT / BOLTZMANN_K  # second radiation constant, m K

ZERO_C_IN_K = 273.15
#: Temperatures a file or a setting may give, C (open below, closed above): above absolute
#: zero, and up to well past what LWIR thermography measures (~2000 C).
TEMP_LIMITS_C = (-ZERO_C_IN_K, 5000.0)
#: The farthest distance a file or a setting may give, m: far beyond what a 160x120 thermal
#: camera resolves; the air's transmission underflows long before 1e300 m.
MAX_DISTANCE_M = 1000.0


def celsius_to_kelvin(temp_c: ArrayLike) -> FloatArray:
    return np.asarray(temp_c, dtype=np.float64) + ZERO_C_IN_K


def kelvin_to_celsius(temp_k: ArrayLike) -> FloatArray:
    return np.asarray(temp_k, dtype=np.float64) - ZERO_C_IN_K


# ---------------------------------------------------------------------------------------------
# Blackbody laws
# ---------------------------------------------------------------------------------------------


def planck_radiance(wavelength_m: ArrayLike, temp_k: ArrayLike) -> FloatArray:
    """Spectral radiance of a blackbody, W m^-2 sr^-1 m^-1 (Planck's law).

    L = 2 h c^2 / lambda^5 / (exp(h c / (lambda k T)) - 1). The paper's eq (16) integrates the
    hemispherical exitance, which is pi times this. Broadcasts wavelength against temperature;
    T <= 0 gives 0.
    """
    lam = np.asarray(wavelength_m, dtype=np.float64)
    t = np.asarray(temp_k, dtype=np.float64)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        x = C2 / (lam * t)
        out = C1L / lam**5 / np.expm1(x)
    return np.where(t > 0, out, 0.0)


@dataclass(frozen=True, eq=False)
class SpectralResponse:
    """Relative spectral response of a detector: wavelengths (m, increasing) and weights.

    ``flat(8e-6, 14e-6)`` is the Lepton's nominal 8-14 um band; a measured curve (the paper's
    Fig. 10) can be given as a table.
    """

    wavelengths_m: FloatArray
    weights: FloatArray
    #: weights x quadrature weights: band integral = planck_radiance(wavelengths) @ quadrature
    quadrature: FloatArray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        lam = np.asarray(self.wavelengths_m, dtype=np.float64)
        w = np.asarray(self.weights, dtype=np.float64)
        if lam.ndim != 1 or lam.shape != w.shape or lam.size < 2:
            raise ValueError("spectral response needs two 1-D arrays of equal length >= 2")
        if np.any(np.diff(lam) <= 0) or np.any(w < 0) or not np.all(np.isfinite(w)):
            raise ValueError("wavelengths must increase and weights be finite and >= 0")
        object.__setattr__(self, "wavelengths_m", lam)
        object.__setattr__(self, "weights", w)
        object.__setattr__(self, "quadrature", w * _quadrature_weights(lam))

    @classmethod
    def flat(cls, low_m: float = 8e-6, high_m: float = 14e-6, n: int = 241) -> SpectralResponse:
        lam = np.linspace(low_m, high_m, n)
        return cls(lam, np.ones(n))


def _quadrature_weights(x: FloatArray) -> FloatArray:
    """Composite Simpson weights on an odd uniform grid, trapezoid weights otherwise."""
    dx = np.diff(x)
    if x.size % 2 == 1 and np.allclose(dx, dx[0], rtol=1e-9):
        q = np.full(x.size, 2.0)
        q[1::2] = 4.0
        q[0] = q[-1] = 1.0
        return q * dx[0] / 3.0
    q = np.zeros(x.size)
    q[:-1] += dx / 2.0
    q[1:] += dx / 2.0
    return q


LWIR_8_14 = SpectralResponse.flat(8e-6, 14e-6)


def band_radiance(temp_k: ArrayLike, response: SpectralResponse = LWIR_8_14) -> FloatArray:
    """In-band radiance of a blackbody, W m^-2 sr^-1: integral of response x Planck radiance.

    Simpson's rule over the response's wavelength table when it is uniform with an odd
    number of points (241 over 8-14 um by default: relative error below 1e-9 against adaptive
    quadrature for 250-800 K), the trapezoid rule otherwise. Any shape of ``temp_k``.
    """
    t = np.asarray(temp_k, dtype=np.float64)
    return planck_radiance(response.wavelengths_m, t[..., None]) @ response.quadrature


def wien_peak_wavelength_m(temp_k: ArrayLike) -> FloatArray:
    """Wavelength of peak spectral radiance, metres: lambda = b / T (Wien; paper eq 15)."""
    return WIEN_B / np.asarray(temp_k, dtype=np.float64)


def stefan_boltzmann_power_w(
    area_m2: ArrayLike, emissivity: ArrayLike, surface_temp_k: ArrayLike, ambient_temp_k: ArrayLike
) -> FloatArray:
    """Net radiated power Q = A eps sigma (Ts^4 - Ta^4), watts (paper eq 14)."""
    ts = np.asarray(surface_temp_k, dtype=np.float64)
    ta = np.asarray(ambient_temp_k, dtype=np.float64)
    return np.asarray(area_m2) * np.asarray(emissivity) * STEFAN_BOLTZMANN * (ts**4 - ta**4)


# ---------------------------------------------------------------------------------------------
# The RBFO count model (paper eqs 17-19; FLIR's Planck constants)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PlanckConstants:
    """Calibration constants of a radiometric camera: S = O + R / (exp(B / T) - F).

    R: counts; B: kelvin; F: dimensionless; O: counts. FLIR metadata gives R1, R2 and
    PlanckO instead: R = R1 / R2 and O = -PlanckO (see :meth:`from_flir`).
    """

    R: float
    B: float
    F: float
    O: float  # noqa: E741 (the paper's and FLIR's name)

    @classmethod
    def from_flir(
        cls, r1: float, r2: float, b: float, f: float, planck_o: float
    ) -> PlanckConstants:
        """Constants from FLIR's metadata fields PlanckR1, PlanckR2, PlanckB, PlanckF, PlanckO."""
        return cls(R=r1 / r2, B=b, F=f, O=-planck_o)


#: The Lepton 3 calibration of Lin & Yao 2022, eq (19). The paper prints "+ 273.15" there;
#: eq (17) gives kelvin, so Celsius is T - 273.15 (with "+" a 39 C plate would read 585 C).
PAPER_2022 = PlanckConstants(R=231160.0, B=1428.0, F=1.0, O=6094.211)

PLANCK_PRESETS: dict[str, PlanckConstants] = {"paper2022": PAPER_2022}


def counts_from_kelvin(temp_k: ArrayLike, planck: PlanckConstants) -> FloatArray:
    """Counts S = O + R / (exp(B / T) - F) of a blackbody at ``temp_k`` (inverse of eq 19)."""
    t = np.asarray(temp_k, dtype=np.float64)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        return planck.O + planck.R / (np.exp(planck.B / t) - planck.F)


def kelvin_from_counts(counts: ArrayLike, planck: PlanckConstants) -> FloatArray:
    """Blackbody temperature T = B / ln(R / (S - O) + F), kelvin (paper eqs 17 and 19).

    NaN where S <= O (no finite temperature gives such a count), without numpy warnings.
    """
    s = np.asarray(counts, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = planck.B / np.log(planck.R / (s - planck.O) + planck.F)
    return np.where(s > planck.O, t, np.nan)


def tlinear_to_celsius(values: ArrayLike, resolution_k: float = 0.01) -> FloatArray:
    """Celsius from Lepton TLinear output (kelvin x 100, or x 10 with ``resolution_k=0.1``).

    Lepton 3.5 / 2.5 radiometric output; telemetry row C word 49 says which resolution.
    Zero (no data) gives NaN.
    """
    v = np.asarray(values, dtype=np.float64)
    return np.where(v > 0, v * resolution_k - ZERO_C_IN_K, np.nan)


# ---------------------------------------------------------------------------------------------
# What a thermal camera's pixel values are
# ---------------------------------------------------------------------------------------------

OUTPUT_KINDS = ("counts", "kelvin")

#: Kelvin a camera's own temperature output may read (-100 .. 2000 C): beyond, a value is not
#: a temperature (no data, or the output is not what the calibration says).
KELVIN_LIMITS = (ZERO_C_IN_K - 100.0, ZERO_C_IN_K + 2000.0)


@dataclass(frozen=True)
class ThermalOutput:
    """What a thermal camera's pixel values are (the calibration file's ``thermal.output``).

    ``"counts"``: raw counts of the RBFO model (paper eqs 17-19), valid from 0 to
    2^bits - 1 (a Lepton's 14 bits, a Boson's 16). ``"kelvin"``: the camera's own
    blackbody-equivalent (apparent) temperature, kelvin = value x scale_k + offset_k
    (Lepton TLinear: scale 0.01 or 0.1; InfiRay P2 Pro / Topdon TC001: 1/64; Boson TLinear:
    0.01), read as the camera reads a blackbody: emissivity 1, no air.

    Either becomes the signal S (counts of the RBFO form, linear in in-band radiance) by
    :meth:`signal`: counts as they are, a kelvin reading T through S(T) = O + R / (exp(B / T)
    - F) of the Planck constants in use; so emissivity, reflections, the air and the window
    mix in it exactly as they do in counts, and with emissivity 1 and no air a kelvin reading
    comes back unchanged.
    """

    kind: str = "counts"
    scale_k: float = 1.0
    offset_k: float = 0.0
    bits: int = 14

    def __post_init__(self) -> None:
        if self.kind not in OUTPUT_KINDS:
            raise ValueError(f"output kind {self.kind!r}: expected one of {OUTPUT_KINDS}")
        if not (np.isfinite(self.scale_k) and self.scale_k > 0 and np.isfinite(self.offset_k)):
            raise ValueError("scale_k must be a finite number > 0 and offset_k finite")
        if not 1 <= self.bits <= 32:
            raise ValueError(f"bits must be 1-32, got {self.bits}")

    @classmethod
    def kelvin_per(cls, scale_k: float, offset_k: float = 0.0) -> ThermalOutput:
        """A kelvin output of ``scale_k`` kelvin per unit (and ``offset_k``)."""
        return cls("kelvin", float(scale_k), float(offset_k))

    @property
    def is_kelvin(self) -> bool:
        return self.kind == "kelvin"

    @property
    def max_counts(self) -> float:
        """The largest valid count (counts kind)."""
        return float(2**self.bits - 1)

    def invalid(self, values: ArrayLike) -> NDArray[np.bool_]:
        """Values no temperature can come from: NaN or infinite, and for counts negative or
        above 2^bits - 1, for kelvin a reading outside :data:`KELVIN_LIMITS` (0: no data)."""
        v = np.asarray(values, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            if self.is_kelvin:
                k = v * self.scale_k + self.offset_k
                return ~((k >= KELVIN_LIMITS[0]) & (k <= KELVIN_LIMITS[1]))
            return ~((v >= 0) & (v <= self.max_counts))

    def problem(self, values: ArrayLike) -> str | None:
        """Why a frame's values cannot be of this kind, or None: more than half of them (every
        4th pixel each way) invalid (:meth:`invalid`): the camera sends another kind, or
        another scale, than the calibration says. A few bad pixels are not this."""
        sample = np.asarray(values)[::4, ::4]
        if np.count_nonzero(self.invalid(sample)) * 2 <= sample.size:
            return None
        median = float(np.median(sample))
        if self.is_kelvin:
            return (
                f"the thermal values read as kelvin x {1 / self.scale_k:g} give a median of "
                f"{median * self.scale_k + self.offset_k:.1f} K, which is no temperature: does "
                "the camera send raw counts (thermal.output kind: counts), or another scale?"
            )
        return (
            f"the thermal values (median {median:g}) are beyond the {self.bits}-bit range of "
            "raw counts: does the camera send its own temperature (thermal.output kind: "
            "kelvin, with its scale_k), or more bits (bits: 16)?"
        )

    def kelvin(self, values: ArrayLike) -> FloatArray:
        """The camera's own reading in kelvin (kelvin kind), NaN where :meth:`invalid`."""
        v = np.asarray(values, dtype=np.float64)
        return np.where(self.invalid(v), np.nan, v * self.scale_k + self.offset_k)

    def signal(self, values: ArrayLike, planck: PlanckConstants) -> FloatArray:
        """The signal S (float counts of the RBFO form) of pixel values; NaN where
        :meth:`invalid`."""
        if self.is_kelvin:
            return counts_from_kelvin(self.kelvin(values), planck)
        v = np.asarray(values, dtype=np.float64)
        return np.where(self.invalid(v), np.nan, v)

    def values(self, signal: ArrayLike, planck: PlanckConstants) -> FloatArray:
        """Pixel values (float, unrounded) of a signal: the inverse of :meth:`signal`."""
        s = np.asarray(signal, dtype=np.float64)
        if self.is_kelvin:
            return (kelvin_from_counts(s, planck) - self.offset_k) / self.scale_k
        return s

    def as_dict(self) -> dict[str, float | int | str]:
        """The mapping a calibration file holds (``thermal.output``)."""
        if self.is_kelvin:
            return {"kind": "kelvin", "scale_k": self.scale_k, "offset_k": self.offset_k}
        return {"kind": "counts"} if self.bits == 14 else {"kind": "counts", "bits": self.bits}


RAW_COUNTS = ThermalOutput()
"""A Lepton 3's raw 14-bit counts: what a calibration file without ``thermal.output`` means."""


# ---------------------------------------------------------------------------------------------
# Directional emissivity of a smooth surface (Fresnel)
# ---------------------------------------------------------------------------------------------


def fresnel_index(normal_emissivity: ArrayLike) -> FloatArray:
    """The real refractive index n whose normal-incidence Fresnel reflectance is
    1 - ``normal_emissivity``: R0 = ((n - 1) / (n + 1))^2, so n = (1 + sqrt R0) / (1 - sqrt R0)
    (dimensionless, >= 1; any shape, emissivity in (0, 1]). Glass's n = 1.5 has R0 = 0.04."""
    root = np.sqrt(1.0 - np.asarray(normal_emissivity, dtype=np.float64))
    return (1.0 + root) / (1.0 - root)


def fresnel_emissivity(cos_theta: ArrayLike, normal_emissivity: ArrayLike) -> FloatArray:
    """Directional emissivity eps(theta) = 1 - R(theta) of a smooth, opaque surface whose
    normal emissivity is ``normal_emissivity``, seen at ``theta`` from its normal.

    R is the Fresnel reflectance for unpolarised light from air (n = 1) onto a medium of real
    index n (:func:`fresnel_index`: the one with R(0) = 1 - eps_n), the mean of the s and p
    polarisations: r_s = (c - n c_t) / (c + n c_t), r_p = (n c - c_t) / (n c + c_t),
    c = cos theta, c_t = sqrt(1 - (1 - c^2) / n^2) (Snell), R = (r_s^2 + r_p^2) / 2 (the
    Fresnel equations for a non-absorbing medium: Modest, Radiative Heat Transfer, 3rd ed.
    2013, chapters 2-3; Born & Wolf, Principles of Optics, section 1.5). Emissivity is eps_n
    up to ~40 degrees and falls beyond ~60 (to 0 at grazing); glass (n = 1.5): 0.96 at
    normal, 0.911 at 60 and 0.612 at 80 degrees, R_p = 0 at Brewster's 56.3 degrees.
    ``cos_theta`` (any shape, |cos| used: surfaces are seen from both sides) broadcasts
    with ``normal_emissivity`` (in (0, 1]); dimensionless.
    """
    c = np.clip(np.abs(np.asarray(cos_theta, dtype=np.float64)), 1e-12, 1.0)
    n2 = np.square(fresnel_index(normal_emissivity))
    g = np.sqrt(n2 - 1.0 + c * c)  # n c_t, written so that n = 1 gives R = 0 at any angle
    rs = (c - g) / (c + g)
    rp = (n2 * c - g) / (n2 * c + g)
    return 1.0 - 0.5 * (rs * rs + rp * rp)


# ---------------------------------------------------------------------------------------------
# Atmosphere (FLIR's model, as published with Thermimage)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class AtmosphereConstants:
    """FLIR atmospheric transmission constants (metadata AtmosphericTransAlpha1 ... X)."""

    alpha1: float = 0.006569
    alpha2: float = 0.01262
    beta1: float = -0.002276
    beta2: float = -0.00667
    x: float = 1.9


FLIR_ATMOSPHERE = AtmosphereConstants()


def water_vapour(temp_k: ArrayLike, relative_humidity: ArrayLike) -> FloatArray:
    """FLIR's water-vapour term H = RH exp(1.5587 + 0.06939 T - 0.00027816 T^2 + 6.8455e-7 T^3).

    T in Celsius inside the polynomial (as FLIR defines it); ``relative_humidity`` is a
    fraction in [0, 1] (not percent). At 25 C and 0.5: H = 11.44.
    """
    t = kelvin_to_celsius(temp_k)
    rh = np.asarray(relative_humidity, dtype=np.float64)
    return rh * np.exp(1.5587 + 0.06939 * t - 0.00027816 * t**2 + 0.00000068455 * t**3)


def atmospheric_transmission(
    distance_m: ArrayLike,
    temp_k: ArrayLike,
    relative_humidity: ArrayLike,
    constants: AtmosphereConstants = FLIR_ATMOSPHERE,
) -> FloatArray:
    """Transmission tau of an air path (FLIR's two-term model), dimensionless in (0, 1].

    tau = X exp(-sqrt(d)(a1 + b1 sqrt(H))) + (1 - X) exp(-sqrt(d)(a2 + b2 sqrt(H))),
    d in metres, H from :func:`water_vapour`. At 25 C, RH 0.5: 0.99517 at 0.5 m, 0.98914 at
    2.5 m. Negative or NaN distances give NaN.
    """
    c = constants
    with np.errstate(invalid="ignore"):  # the root of a negative distance is NaN
        sd = np.sqrt(np.asarray(distance_m, dtype=np.float64))
    sh = np.sqrt(water_vapour(temp_k, relative_humidity))
    # the coefficients negated first: with one air (scalars) each term is one pass per pixel
    return c.x * np.exp(sd * -(c.alpha1 + c.beta1 * sh)) + (1 - c.x) * np.exp(
        sd * -(c.alpha2 + c.beta2 * sh)
    )


# ---------------------------------------------------------------------------------------------
# Object temperature through emissivity, atmosphere and window
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ObjectParams:
    """What lies between the object and the detector, SI units; every field a scalar or an
    array that broadcasts with the counts (a per-pixel map, or one value per table row).

    emissivity: object emissivity in (0, 1];
    distance_m: object distance in metres (>= 0; the range, i.e. the length of the air path);
    reflected_temp_k: apparent temperature of the surroundings the object reflects;
    atmosphere_temp_k: air temperature; relative_humidity: fraction in [0, 1];
    window_transmission: external window (IRT) in (0, 1], 1 = no window; window_temp_k.
    """

    emissivity: float | FloatArray = 1.0
    distance_m: float | FloatArray = 0.0
    reflected_temp_k: float | FloatArray = 293.15
    atmosphere_temp_k: float | FloatArray = 293.15
    relative_humidity: float | FloatArray = 0.5
    window_transmission: float = 1.0
    window_temp_k: float | FloatArray = 293.15

    def __post_init__(self) -> None:
        def outside(value: float | FloatArray, lo: float, hi: float, lo_open: bool) -> bool:
            if isinstance(value, float | int):  # most are: numpy costs 10x more
                return bool((value <= lo if lo_open else value < lo) or value > hi)
            v = np.asarray(value, dtype=np.float64)
            return bool(np.any(((v <= lo) if lo_open else (v < lo)) | (v > hi)))

        if outside(self.emissivity, 0.0, 1.0, True):
            raise ValueError("emissivity must be in (0, 1]")
        if outside(self.relative_humidity, 0.0, 1.0, False):
            raise ValueError(
                f"relative_humidity is a fraction in [0, 1], got {self.relative_humidity} "
                "(percent? divide by 100)"
            )
        if outside(self.window_transmission, 0.0, 1.0, True):
            raise ValueError("window_transmission must be in (0, 1]")
        for name in ("reflected_temp_k", "atmosphere_temp_k", "window_temp_k"):
            if outside(getattr(self, name), 0.0, np.inf, True):
                raise ValueError(f"{name} must be a positive temperature in kelvin")

    @classmethod
    def from_celsius(
        cls,
        emissivity: ArrayLike,
        distance_m: ArrayLike,
        ambient_c: ArrayLike,
        humidity_pct: ArrayLike,
        reflected_c: ArrayLike | None = None,
    ) -> ObjectParams:
        """Object parameters in the units people give them: air temperature (C), relative
        humidity (%) and the reflected surroundings' temperature (C; the air's unless given).
        Arrays broadcast as in the constructor."""

        def value(a: ArrayLike) -> float | FloatArray:  # plain floats stay floats
            a = np.asarray(a, dtype=np.float64)
            return float(a) if a.ndim == 0 else a

        return cls(
            emissivity=value(emissivity),
            distance_m=value(distance_m),
            reflected_temp_k=value(
                celsius_to_kelvin(ambient_c if reflected_c is None else reflected_c)
            ),
            atmosphere_temp_k=value(celsius_to_kelvin(ambient_c)),
            relative_humidity=value(np.asarray(humidity_pct, dtype=np.float64) / 100.0),
        )


@dataclass(frozen=True, eq=False)
class RadiometryParams:
    """Planck constants, object parameters and atmosphere constants for one camera.

    max_counts: largest valid count (16383 for 14-bit Lepton data; None for no limit).
    """

    planck: PlanckConstants = PAPER_2022
    obj: ObjectParams = field(default_factory=ObjectParams)
    atmosphere: AtmosphereConstants = FLIR_ATMOSPHERE
    max_counts: float | None = 16383.0

    def with_object(self, **changes: object) -> RadiometryParams:
        """A copy with some :class:`ObjectParams` fields replaced (e.g. a distance map)."""
        return replace(self, obj=replace(self.obj, **changes))  # type: ignore[arg-type]


class SourceWeights(NamedTuple):
    """Weights of each source in the detected signal (they sum to one)."""

    object: FloatArray
    reflected: FloatArray
    atmosphere: FloatArray
    window: FloatArray


def _weights_single_pass(p: RadiometryParams) -> SourceWeights:
    o = p.obj
    tau = atmospheric_transmission(
        o.distance_m, o.atmosphere_temp_k, o.relative_humidity, p.atmosphere
    )
    e = np.asarray(o.emissivity, dtype=np.float64)
    irt = o.window_transmission
    return SourceWeights(
        object=irt * tau * e,
        reflected=irt * tau * (1.0 - e),
        atmosphere=irt * (1.0 - tau),
        window=np.asarray(1.0 - irt),
    )


def _weights_halfway_window(p: RadiometryParams) -> SourceWeights:
    o = p.obj
    tau = atmospheric_transmission(
        np.asarray(o.distance_m) / 2.0, o.atmosphere_temp_k, o.relative_humidity, p.atmosphere
    )
    e = np.asarray(o.emissivity, dtype=np.float64)
    irt = o.window_transmission
    # object -> air (tau1) -> window (irt) -> air (tau2) -> camera, with tau1 = tau2 = tau
    return SourceWeights(
        object=e * tau * irt * tau,
        reflected=(1.0 - e) * tau * irt * tau,
        atmosphere=(1.0 - tau) * irt * tau + (1.0 - tau),
        window=(1.0 - irt) * tau,
    )


#: Radiometric models by name: each gives the source weights for a set of parameters.
RADIOMETRY_METHODS: dict[str, Callable[[RadiometryParams], SourceWeights]] = {
    "flir": _weights_single_pass,
    "thermimage": _weights_halfway_window,
}


def source_weights(params: RadiometryParams, method: str = "flir") -> SourceWeights:
    """Weights of object, reflected, atmosphere and window in the signal for ``method``."""
    try:
        return RADIOMETRY_METHODS[method](params)
    except KeyError:
        raise ValueError(
            f"unknown radiometry method {method!r}; choose from {sorted(RADIOMETRY_METHODS)}"
        ) from None


def _background_counts(params: RadiometryParams, w: SourceWeights) -> FloatArray:
    """Counts contributed by everything but the object: sum over k != object of w_k S(T_k)."""
    o, pl = params.obj, params.planck
    return (
        w.reflected * counts_from_kelvin(o.reflected_temp_k, pl)
        + w.atmosphere * counts_from_kelvin(o.atmosphere_temp_k, pl)
        + w.window * counts_from_kelvin(o.window_temp_k, pl)
    )


def invalid_counts(counts: ArrayLike, params: RadiometryParams) -> NDArray[np.bool_]:
    """Mask of counts no temperature can come from: NaN/inf, negative, above ``max_counts``."""
    s = np.asarray(counts, dtype=np.float64)
    bad = ~np.isfinite(s) | (s < 0)
    if params.max_counts is not None:
        bad |= s > params.max_counts
    return bad


def raw_to_kelvin(counts: ArrayLike, params: RadiometryParams, method: str = "flir") -> FloatArray:
    """Object temperature in kelvin from raw counts (any shape), through ``method``'s model.

    Inverts S = w_obj S(T_obj) + sum_k w_k S(T_k) for T_obj. NaN (never an exception, never
    a numpy warning) where the counts are invalid (:func:`invalid_counts`) or imply an object
    signal at or below the offset O. Per-pixel ``distance_m``/``emissivity`` broadcast.
    """
    s = np.asarray(counts, dtype=np.float64)
    w = source_weights(params, method)
    with np.errstate(divide="ignore", invalid="ignore"):
        obj_counts = (s - _background_counts(params, w)) / w.object
    t = kelvin_from_counts(obj_counts, params.planck)
    return np.where(invalid_counts(s, params), np.nan, t)


def kelvin_to_raw(temp_k: ArrayLike, params: RadiometryParams, method: str = "flir") -> FloatArray:
    """Raw counts (float) of an object at ``temp_k`` seen through ``method``'s model."""
    w = source_weights(params, method)
    return w.object * counts_from_kelvin(temp_k, params.planck) + _background_counts(params, w)


def raw_to_celsius(counts: ArrayLike, params: RadiometryParams, method: str = "flir") -> FloatArray:
    """Object temperature in Celsius from raw counts; see :func:`raw_to_kelvin`."""
    return kelvin_to_celsius(raw_to_kelvin(counts, params, method))


def celsius_to_raw(temp_c: ArrayLike, params: RadiometryParams, method: str = "flir") -> FloatArray:
    """Raw counts (float) of an object at ``temp_c`` Celsius; inverse of raw_to_celsius."""
    return kelvin_to_raw(celsius_to_kelvin(temp_c), params, method)
