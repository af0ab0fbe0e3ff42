"""The virtual thermal camera (a Lepton 3 by default): scene radiance -> optics -> VOx sensor ->
14-bit counts (or the camera's own kelvin) + telemetry.

Chain, per frame (docs/simulator.md has every equation, default and source):

1. Aperture radiance of each sub-pixel ray (band radiance, 8-14 um), through the air path of
   its true range: L_ap = tau(r) [eps L(T) + (1 - eps) L(T_amb)] + (1 - tau(r)) L(T_air)
   (:mod:`.shading`).
2. Pixel footprint (mean of supersample x supersample rays) and optics blur (Gaussian PSF)
   (:func:`.shading.render_aperture`).
3. The VOx focal-plane effect the paper compensates: residual responsivity
   g(T_fpa) = (T_ref / T_fpa)^2 (1 + c (T_fpa - T_ref)) (VOx TCR ~ 1/T^2 under a linear gain
   compensation) and interior emission the camera over-subtracts,
   L_meas = g(T_fpa) L_ap - kappa [L(T_fpa) - L(T_ref)].
4. Calibration map to counts: S = O + R / (exp(B / T_eq) - F) with T_eq the blackbody
   temperature of L_meas (the paper's RBFO constants), plus fixed-pattern offsets (reset by
   each FFC, drifting with the FPA temperature since), temporal noise (NETD), rounding to
   14-bit integers.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
from numpy.typing import NDArray

from ..frames import FfcState, Telemetry
from ..radiometry import (
    LWIR_8_14,
    PAPER_2022,
    RAW_COUNTS,
    PlanckConstants,
    SpectralResponse,
    ThermalOutput,
    band_radiance,
    counts_from_kelvin,
    kelvin_from_counts,
)

FloatArray = NDArray[np.float64]

FpaProfile = Callable[[float], float]
"""FPA (VOx) temperature in kelvin as a function of time in seconds."""


def constant_fpa(temp_k: float) -> FpaProfile:
    """FPA held at ``temp_k``."""
    return lambda t: temp_k


def warmup_fpa(start_k: float, end_k: float, tau_s: float = 300.0) -> FpaProfile:
    """Warm-up after power-on: exponential approach from ``start_k`` to ``end_k``."""
    return lambda t: end_k + (start_k - end_k) * float(np.exp(-max(t, 0.0) / tau_s))


def ramp_fpa(start_k: float, end_k: float, duration_s: float) -> FpaProfile:
    """Linear ramp from ``start_k`` to ``end_k`` over ``duration_s``, then held."""
    return lambda t: start_k + (end_k - start_k) * min(max(t / duration_s, 0.0), 1.0)


def steps_fpa(times_s: list[float], temps_k: list[float]) -> FpaProfile:
    """Piecewise constant: ``temps_k[i]`` from ``times_s[i]`` on (times increasing)."""
    ts, vs = np.asarray(times_s, float), np.asarray(temps_k, float)
    return lambda t: float(vs[max(int(np.searchsorted(ts, t, side="right")) - 1, 0)])


@dataclass(frozen=True)
class LeptonModel:
    """Parameters of the virtual Lepton 3 (defaults: datasheet, paper, or stated choices).

    planck: the counts calibration (paper's RBFO constants); response: spectral band;
    netd_k: temporal noise as NETD at 300 K (datasheet: < 50 mK); psf_sigma_px: optics blur;
    supersample: rays per pixel side (pixel footprint); fps: unique frame rate (8.7 Hz);
    vox_reference_temp_k: FPA temperature at which the camera reads true (T_ref);
    vox_gain_slope_per_k: c, the linear responsivity compensation; interior_emission: kappa;
    fpn_residual_counts: SD of pixel offsets left just after an FFC;
    fpn_drift_counts_per_k: SD over pixels of offset drift per kelvin of FPA change since FFC;
    ffc_interval_s / ffc_delta_k: FFC every so long or after so much FPA change;
    ffc_duration_s: shutter closed; ffc_imminent_s: warning before a timed FFC;
    housing_offset_k: housing temperature minus FPA temperature; bits: ADC depth;
    output: what the pixel values are (raw counts, or the camera's own kelvin at a scale);
    tells_output: the telemetry says a kelvin output (a Lepton's TLinear flag; the P2 Pro's
    source knows it), else only the calibration does (a Boson); reports_fpa: the frames carry
    the FPA temperature (NaN otherwise: an InfiRay P2 Pro); ffc_freeze: while the shutter is
    closed the camera repeats its last image (P2 Pro, Boson) instead of showing the shutter.
    """

    planck: PlanckConstants = PAPER_2022
    response: SpectralResponse = LWIR_8_14
    netd_k: float = 0.050
    psf_sigma_px: float = 0.6
    supersample: int = 4
    fps: float = 8.7
    vox_reference_temp_k: float = 308.15
    vox_gain_slope_per_k: float = 0.009
    interior_emission: float = 0.01
    fpn_residual_counts: float = 0.5
    fpn_drift_counts_per_k: float = 0.3
    ffc_interval_s: float = 180.0
    ffc_delta_k: float = 1.5
    ffc_duration_s: float = 0.25
    ffc_imminent_s: float = 2.0
    housing_offset_k: float = -1.0
    bits: int = 14
    output: ThermalOutput = RAW_COUNTS
    tells_output: bool = True
    reports_fpa: bool = True
    ffc_freeze: bool = False

    @property
    def max_counts(self) -> int:
        return 2**self.bits - 1

    def values(self, counts: FloatArray) -> NDArray[np.uint16]:
        """The camera's pixel values of float counts: rounded counts within the ADC's range,
        or its own temperature (kelvin of the counts, emissivity 1, no air) in units of its
        scale."""
        if self.output.is_kelvin:
            kelvin = kelvin_from_counts(counts, self.planck)
            counts = (np.nan_to_num(kelvin) - self.output.offset_k) / self.output.scale_k
            return np.clip(np.rint(counts), 0, 65535).astype(np.uint16)
        return np.clip(np.rint(counts), 0, self.max_counts).astype(np.uint16)

    @cached_property
    def noise_counts(self) -> float:
        """Temporal noise SD in counts: NETD times dS/dT at 300 K."""
        s = counts_from_kelvin([299.95, 300.05], self.planck)
        return float(self.netd_k * (s[1] - s[0]) / 0.1)

    def responsivity(self, fpa_temp_k: float | FloatArray) -> float | FloatArray:
        """Residual gain g(T_fpa) = (T_ref / T_fpa)^2 (1 + c (T_fpa - T_ref))."""
        t_ref = self.vox_reference_temp_k
        return (t_ref / fpa_temp_k) ** 2 * (1.0 + self.vox_gain_slope_per_k * (fpa_temp_k - t_ref))


@dataclass(frozen=True, eq=False)
class RadianceTable:
    """Band radiance L(T) on a fine grid, for fast L(T) and its inverse T(L) by interpolation.

    150-1000 K in 0.05 K steps: interpolation error below 1e-5 K in T(L).
    """

    temp_k: FloatArray
    radiance: FloatArray

    def to_radiance(self, temp_k: FloatArray | float) -> FloatArray:
        return np.asarray(np.interp(temp_k, self.temp_k, self.radiance))

    def to_kelvin(self, radiance: FloatArray | float) -> FloatArray:
        return np.asarray(np.interp(radiance, self.radiance, self.temp_k))


@lru_cache(maxsize=4)
def radiance_table(response: SpectralResponse = LWIR_8_14) -> RadianceTable:
    t = np.linspace(150.0, 1000.0, 17001)
    return RadianceTable(t, band_radiance(t, response))


def bolometer_memory(time_constant_s: float, renders: int = 4) -> tuple[FloatArray, FloatArray]:
    """Lags (s, (renders,)) before a frame's time and weights ((renders,), sum 1) that stand
    for a microbolometer's memory of the scene in a few renders.

    A pixel is a first-order thermal system: its signal is the scene radiance filtered by
    (1 / tau) exp(-s / tau), s >= 0 the lag (the Lepton's tau: about 12 ms, an assumption;
    FLIR gives 8-12 ms for modern microbolometers and no figure for the Lepton). The kernel
    is split into ``renders`` intervals one tau long (the last one open-ended), each rendered
    at its centroid with its share of the weight, so the mean and the mean lag (tau) are
    exact: lags (k + 0.418) tau with weights (1 - 1/e) e^-k, and the last at renders x tau
    with e^-(renders - 1). Four renders reach past 3 tau (95 % of the weight).
    """
    k = np.arange(renders, dtype=np.float64)
    e = np.exp(-1.0)
    weights = np.exp(-k) * (1.0 - e)
    lags = (k + 1.0 - e / (1.0 - e)) * time_constant_s
    weights[-1] = np.exp(-(renders - 1.0))
    lags[-1] = renders * time_constant_s
    return lags, weights


def measured_radiance(
    aperture: FloatArray, fpa_temp_k: float, model: LeptonModel, table: RadianceTable
) -> FloatArray:
    """L_meas = g(T_fpa) L_ap - kappa [L(T_fpa) - L(T_ref)] (the VOx effect)."""
    interior = table.to_radiance(fpa_temp_k) - table.to_radiance(model.vox_reference_temp_k)
    return model.responsivity(fpa_temp_k) * aperture - model.interior_emission * interior


def counts_from_radiance(
    radiance: FloatArray, model: LeptonModel, table: RadianceTable
) -> FloatArray:
    """Float counts of measured radiance through the camera's RBFO calibration."""
    return counts_from_kelvin(table.to_kelvin(radiance), model.planck)


class LeptonSensor:
    """The stateful part of the camera: FPA temperature, FFC (shutter) cycle, fixed-pattern
    offsets, temporal noise, the pixel values (14-bit counts, or the camera's own kelvin) and
    telemetry.

    ``read(time_s, aperture)`` turns an aperture radiance image into pixel values and
    telemetry. Call it with increasing times. ``noise=False`` gives exact float counts (no
    FPN, no noise, no rounding, whatever the output) for physics checks.
    """

    def __init__(
        self,
        model: LeptonModel,
        shape: tuple[int, int],
        fpa: FpaProfile,
        rng: np.random.Generator,
        noise: bool = True,
    ) -> None:
        self.model = model
        self.shape = shape
        self.fpa = fpa
        self.rng = rng
        self.noise = noise
        self.table = radiance_table(model.response)
        self.drift_pattern = rng.standard_normal(shape) * model.fpn_drift_counts_per_k
        self.frame_counter = 0
        self._ffc_start_s: float | None = None  # shutter closed since
        self._last_ffc_end_s: float | None = None
        self._ffc_fpa_k = float(fpa(0.0))  # offsets drift from the FPA temperature at FFC
        self._residual = np.zeros(shape)
        self._prev_s: float | None = None  # time of the previous read
        self._last: NDArray[np.uint16] | FloatArray | None = None  # the last image given

    def _ffc_due(self, time_s: float, fpa_k: float) -> bool:
        assert self._last_ffc_end_s is not None
        return (
            time_s - self._last_ffc_end_s >= self.model.ffc_interval_s
            or abs(fpa_k - self._ffc_fpa_k) >= self.model.ffc_delta_k
        )

    def _fell_due_s(self, time_s: float) -> float:
        """When the FFC due at ``time_s`` fell due, since the previous read: reads may be
        seconds apart (a session that keeps one frame in many), and the camera starts its
        FFC when it falls due, not at the next frame kept. The FPA's crossing of
        ``ffc_delta_k`` is found by bisection; the timed FFC at its time."""
        assert self._last_ffc_end_s is not None
        lo = time_s if self._prev_s is None else self._prev_s
        hi = min(time_s, max(lo, self._last_ffc_end_s + self.model.ffc_interval_s))

        def moved(t: float) -> bool:
            return abs(float(self.fpa(t)) - self._ffc_fpa_k) >= self.model.ffc_delta_k

        if not moved(hi):  # the timed FFC, at its time
            return hi
        for _ in range(40):  # to well below a microsecond over hours
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if moved(mid) else (mid, hi)
        return hi

    def _state(self, time_s: float, fpa_k: float) -> FfcState:
        m = self.model
        if self._last_ffc_end_s is None and self._ffc_start_s is None:
            self._ffc_start_s = 0.0  # the camera runs an FFC at power-on (t = 0)
        elif self._ffc_start_s is None and self._ffc_due(time_s, fpa_k):
            self._ffc_start_s = self._fell_due_s(time_s)
        if self._ffc_start_s is not None:
            end_s = self._ffc_start_s + m.ffc_duration_s
            if time_s < end_s:
                return FfcState.IN_PROGRESS
            # the shutter opened at end_s: new offsets were measured against it
            self._ffc_start_s = None
            self._last_ffc_end_s = end_s
            self._ffc_fpa_k = float(self.fpa(end_s))
            self._residual = self.rng.standard_normal(self.shape) * m.fpn_residual_counts
        assert self._last_ffc_end_s is not None
        if self._last_ffc_end_s + m.ffc_interval_s - time_s <= m.ffc_imminent_s:
            return FfcState.IMMINENT
        return FfcState.COMPLETE

    def read(
        self, time_s: float, aperture: FloatArray
    ) -> tuple[NDArray[np.uint16] | FloatArray, Telemetry]:
        m = self.model
        fpa_k = float(self.fpa(time_s))
        state = self._state(time_s, fpa_k)
        self._prev_s = time_s
        frozen = state == FfcState.IN_PROGRESS and m.ffc_freeze and self._last is not None
        if frozen:  # the camera repeats its last image while its shutter is closed
            assert self._last is not None
            values = self._last.copy()
        else:
            if state == FfcState.IN_PROGRESS:
                # the image shows the closed shutter, at the housing temperature
                shutter = self.table.to_radiance(fpa_k + m.housing_offset_k)
                aperture = np.full(self.shape, shutter)
            values = counts_from_radiance(
                measured_radiance(aperture, fpa_k, m, self.table), m, self.table
            )
            if self.noise:
                values = values + self._residual + self.drift_pattern * (fpa_k - self._ffc_fpa_k)
                values = m.values(values + self.rng.standard_normal(self.shape) * m.noise_counts)
            self._last = values
        since = None if self._last_ffc_end_s is None else time_s - self._last_ffc_end_s
        kelvin_told = m.output.is_kelvin and m.tells_output
        nan = float("nan")
        telemetry = Telemetry(
            frame_counter=self.frame_counter,
            # telemetry carries centikelvin
            fpa_temp_k=round(fpa_k, 2) if m.reports_fpa else nan,
            housing_temp_k=round(fpa_k + m.housing_offset_k, 2) if m.reports_fpa else nan,
            ffc_state=state,
            time_since_ffc_s=since,
            ffc_desired=state == FfcState.IMMINENT,
            tlinear=kelvin_told,
            tlinear_resolution_k=m.output.scale_k if kelvin_told else None,
        )
        self.frame_counter += 1
        return values, telemetry
