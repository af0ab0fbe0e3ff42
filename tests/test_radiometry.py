"""Radiometry: golden values (Thermimage, the paper), physical laws, round trips, bad counts."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.integrate import quad

from thermodepth.conditions import Conditions, Radiometry
from thermodepth.frame_radiometry import frame_celsius
from thermodepth.radiometry import (
    PAPER_2022,
    STEFAN_BOLTZMANN,
    ObjectParams,
    PlanckConstants,
    RadiometryParams,
    SpectralResponse,
    ThermalOutput,
    atmospheric_transmission,
    band_radiance,
    celsius_to_raw,
    counts_from_kelvin,
    invalid_counts,
    kelvin_from_counts,
    planck_radiance,
    raw_to_celsius,
    stefan_boltzmann_power_w,
    tlinear_to_celsius,
    water_vapour,
    wien_peak_wavelength_m,
)

K0 = 273.15
# FLIR SC660 constants as published in the Thermimage README (reference-values.md).
SC660 = PlanckConstants.from_flir(r1=21106.77, r2=0.012545258, b=1501, f=1, planck_o=-7340)


def sc660(**obj: float) -> RadiometryParams:
    base = {
        "reflected_temp_k": 20 + K0,
        "atmosphere_temp_k": 20 + K0,
        "window_temp_k": 20 + K0,
        "relative_humidity": 0.5,
    }
    return RadiometryParams(planck=SC660, obj=ObjectParams(**{**base, **obj}), max_counts=None)


# --- Golden values: Thermimage README (tolerance 1e-4 C: its printed precision is 1e-5) -----


def test_from_flir_constants() -> None:
    assert SC660.R == pytest.approx(21106.77 / 0.012545258)
    assert SC660.O == 7340


def test_thermimage_temp2raw() -> None:
    raw = celsius_to_raw(23.0, sc660(emissivity=1.0, distance_m=0.0), method="thermimage")
    assert raw == pytest.approx(17994.06, abs=0.005)  # published to 2 decimals


def test_thermimage_raw2temp_with_window() -> None:
    p = sc660(emissivity=0.95, distance_m=1.0, window_transmission=0.96)
    assert raw_to_celsius(17994.06, p, method="thermimage") == pytest.approx(23.31223, abs=1e-4)


@pytest.mark.parametrize(
    ("raw", "expected_c"),
    [
        (17171, 18.30355),
        (18272, 24.77367),
        (24931, 57.07398),
        (17870, 22.46279),
        (17833, 22.24723),
        (17808, 22.10131),
        (17829, 22.22390),
        (17861, 22.41040),
    ],
)
def test_thermimage_raw2temp(raw: float, expected_c: float) -> None:
    p = sc660(emissivity=0.95, distance_m=1.0)
    assert raw_to_celsius(raw, p, method="thermimage") == pytest.approx(expected_c, abs=1e-4)


def test_single_pass_differs_from_thermimage_by_a_few_hundredths() -> None:
    # FLIR's single pass attenuates over the full path once; Thermimage's halfway window
    # reads hot objects slightly warmer (+0.03 C on average against ThermaCAM).
    p = sc660(emissivity=0.95, distance_m=1.0, window_transmission=0.96)
    raws = np.array([17994.06, 18272, 24931])
    diff = raw_to_celsius(raws, p, "flir") - raw_to_celsius(raws, p, "thermimage")
    assert np.all(diff < -0.003)  # objects above the 20 C air: single pass reads cooler
    assert np.all(np.abs(diff) < 0.1)
    cold = raw_to_celsius(17171, p, "flir") - raw_to_celsius(17171, p, "thermimage")
    assert 0 < cold < 0.05  # below the air temperature the sign flips


def test_water_vapour_and_transmission() -> None:
    assert water_vapour(25 + K0, 0.5) == pytest.approx(11.44, abs=0.005)
    tau = atmospheric_transmission([0.5, 1.0, 2.0, 2.5, 3.0], 25 + K0, 0.5)
    np.testing.assert_allclose(tau, [0.99517, 0.99316, 0.99030, 0.98914, 0.98809], atol=6e-6)
    assert atmospheric_transmission(0.0, 25 + K0, 0.5) == 1.0
    assert np.isnan(atmospheric_transmission(-1.0, 25 + K0, 0.5))


def test_transmission_is_float64_whatever_the_distance_map() -> None:
    # the pipeline's distance maps are float32; the air is computed in float64 all the same
    # (it once took the root in float32: 1e-9 differences in the demo's calibration figures)
    d32 = np.linspace(0.3, 4.0, 50, dtype=np.float32)
    tau = atmospheric_transmission(d32, 25 + K0, 0.5)
    assert tau.dtype == np.float64
    assert np.array_equal(tau, atmospheric_transmission(d32.astype(np.float64), 25 + K0, 0.5))


def test_ignoring_atmosphere_biases_as_documented() -> None:
    # reference-values.md: ignoring tau biases a 35 C object by ~ -0.05 K at 0.5 m and
    # -0.10 K at 2.5 m, a 100 C object by -0.29 / -0.65 K (25 C air, RH 50 %).
    for temp_c, d, bias in [
        (35, 0.5, -0.05),
        (35, 2.5, -0.10),
        (100, 0.5, -0.29),
        (100, 2.5, -0.65),
    ]:
        p = RadiometryParams(obj=ObjectParams(1.0, d, 25 + K0, 25 + K0, 0.5))
        raw = celsius_to_raw(temp_c, p)
        naive = raw_to_celsius(raw, p.with_object(distance_m=0.0))
        assert naive - temp_c == pytest.approx(bias, abs=0.015)


# --- The paper --------------------------------------------------------------------------------


def test_paper_counts_at_39_and_25_c() -> None:
    s39, s25 = counts_from_kelvin([39 + K0, 25 + K0], PAPER_2022)
    assert s39 == pytest.approx(8502, abs=1)
    assert s25 == pytest.approx(8033, abs=1)
    assert (s39 - s25) / 14 == pytest.approx(33.5, abs=0.5)  # ~33 counts per kelvin
    assert s39 < 16383  # inside the 14-bit range


def test_paper_eq19_is_kelvin_minus_273_15() -> None:
    # the paper prints "+ 273.15"; only the subtraction gives back the 39 C plate
    s = counts_from_kelvin(39 + K0, PAPER_2022)
    assert kelvin_from_counts(s, PAPER_2022) - K0 == pytest.approx(39.0, abs=1e-9)


def test_wien_peak_eq15() -> None:
    assert wien_peak_wavelength_m(312.0) * 1e9 == pytest.approx(9288, abs=0.5)
    # and it is where Planck's law peaks
    lam = np.linspace(5e-6, 15e-6, 200001)
    assert lam[np.argmax(planck_radiance(lam, 312.0))] == pytest.approx(9287.7e-9, abs=0.2e-9)


def test_stefan_boltzmann_eq14() -> None:
    assert pytest.approx(5.67e-8, rel=1e-3) == STEFAN_BOLTZMANN  # paper's rounded value
    # 0.09 m^2 plate (30 x 30 cm), eps 0.95, 39 C in 25 C surroundings
    q = stefan_boltzmann_power_w(0.09, 0.95, 39 + K0, 25 + K0)
    assert q == pytest.approx(0.09 * 0.95 * 5.670374419e-8 * (312.15**4 - 298.15**4))
    assert 7.0 < q < 8.0
    # integrating Planck's law over all wavelengths gives sigma T^4 / pi
    wide = SpectralResponse(np.geomspace(0.3e-6, 2e-3, 20001), np.ones(20001))
    assert band_radiance(312.0, wide) == pytest.approx(
        STEFAN_BOLTZMANN * 312.0**4 / np.pi, rel=1e-4
    )


def test_band_radiance_matches_adaptive_quadrature() -> None:
    for t in (250.0, 312.0, 400.0, 800.0):
        exact, _ = quad(
            lambda lam, t=t: planck_radiance(lam, t), 8e-6, 14e-6, epsabs=0, epsrel=1e-12
        )
        assert band_radiance(t) == pytest.approx(exact, rel=1e-9)


# --- Round trips, per-pixel parameters, properties ---------------------------------------------


@pytest.mark.parametrize("method", ["flir", "thermimage"])
def test_round_trip_counts_temperature_counts(method: str) -> None:
    temps = np.linspace(0, 150, 151)
    p = RadiometryParams(
        obj=ObjectParams(0.9, 2.0, 22 + K0, 25 + K0, 0.4, 0.9, 28 + K0), max_counts=None
    )
    raw = celsius_to_raw(temps, p, method)
    back = celsius_to_raw(raw_to_celsius(raw, p, method), p, method)
    np.testing.assert_allclose(back, raw, rtol=1e-6)
    np.testing.assert_allclose(raw_to_celsius(raw, p, method), temps, atol=1e-8)


def test_per_pixel_distance_and_emissivity_broadcast() -> None:
    rng = np.random.default_rng(7)
    counts = rng.uniform(8000, 9000, (120, 160))
    dist = rng.uniform(0.3, 3.0, (120, 160))
    emis = rng.uniform(0.8, 1.0, (120, 160))
    base = RadiometryParams(obj=ObjectParams(reflected_temp_k=25 + K0, atmosphere_temp_k=25 + K0))
    out = raw_to_celsius(counts, base.with_object(distance_m=dist, emissivity=emis))
    assert out.shape == (120, 160)
    for i, j in [(0, 0), (60, 80), (119, 159)]:
        one = base.with_object(distance_m=dist[i, j], emissivity=emis[i, j])
        assert out[i, j] == pytest.approx(raw_to_celsius(counts[i, j], one), abs=1e-12)


def test_invalid_counts_give_nan_and_mask_without_warnings() -> None:
    # pytest turns RuntimeWarning into errors (pyproject), so no warning may escape here
    p = RadiometryParams(obj=ObjectParams(emissivity=0.95, distance_m=1.0))
    counts = np.array([8500.0, np.nan, -1.0, 16384.0, np.inf, 6000.0, 6094.0, 0.0, 16383.0])
    t = raw_to_celsius(counts, p)
    expect_nan = [False, True, True, True, True, True, True, True, False]
    np.testing.assert_array_equal(np.isnan(t), expect_nan)
    np.testing.assert_array_equal(
        invalid_counts(counts, p), [False, True, True, True, True, False, False, False, False]
    )
    assert np.isnan(kelvin_from_counts(PAPER_2022.O, PAPER_2022))
    frame = np.zeros((120, 160), np.uint16)  # an all-zero frame: all NaN, no crash
    assert np.isnan(raw_to_celsius(frame, p)).all()


def test_unknown_method_and_bad_params_raise() -> None:
    with pytest.raises(ValueError, match="unknown radiometry method"):
        raw_to_celsius(8500, RadiometryParams(), method="magic")
    with pytest.raises(ValueError, match="percent"):
        ObjectParams(relative_humidity=50.0)
    with pytest.raises(ValueError, match="emissivity"):
        ObjectParams(emissivity=0.0)


def test_air_conditions_per_row_broadcast() -> None:
    # one air temperature, humidity and reflected temperature per row, as sweep tables have
    amb_c = np.array([15.0, 25.0, 35.0])
    rh_pct = np.array([20.0, 50.0, 90.0])
    refl_c = np.array([10.0, 60.0, 25.0])
    obj = ObjectParams.from_celsius(0.9, [0.5, 2.0, 4.0], amb_c, rh_pct, refl_c)
    counts = np.array([8400.0, 8600.0, 9000.0])
    rows = raw_to_celsius(counts, RadiometryParams(obj=obj))
    for i in range(3):
        one = ObjectParams.from_celsius(0.9, obj.distance_m[i], amb_c[i], rh_pct[i], refl_c[i])
        assert isinstance(one.atmosphere_temp_k, float)  # scalars stay scalars
        assert one.atmosphere_temp_k == pytest.approx(amb_c[i] + K0)
        assert rows[i] == pytest.approx(raw_to_celsius(counts[i], RadiometryParams(obj=one)))
    # one bad element is enough to refuse
    with pytest.raises(ValueError, match="percent"):
        ObjectParams.from_celsius(0.9, 1.0, 25.0, [50.0, 150.0])
    with pytest.raises(ValueError, match="positive temperature in kelvin"):
        ObjectParams.from_celsius(0.9, 1.0, [25.0, -300.0], 50.0)


def test_tlinear() -> None:
    assert tlinear_to_celsius(31215) == pytest.approx(39.0)
    assert tlinear_to_celsius(3122, resolution_k=0.1) == pytest.approx(39.05)
    assert np.isnan(tlinear_to_celsius(0))


counts_st = st.floats(6200, 16383)
temp_st = st.floats(-20, 150)


@given(counts_st, counts_st, st.floats(0.3, 1.0), st.floats(0, 5))
def test_monotonic_in_counts(a: float, b: float, e: float, d: float) -> None:
    p = RadiometryParams(
        obj=ObjectParams(
            emissivity=e, distance_m=d, reflected_temp_k=298.15, atmosphere_temp_k=298.15
        )
    )
    lo, hi = sorted((a, b))
    tl, th = raw_to_celsius([lo, hi], p)
    if np.isfinite(tl) and np.isfinite(th):
        assert th >= tl


@given(st.floats(40, 150), st.floats(0.3, 0.99), st.floats(0.01, 0.3))
def test_hot_object_reads_cooler_with_higher_emissivity(temp_c: float, e: float, de: float) -> None:
    # The same counts from a hot object: assuming more emissivity means a cooler object.
    p = RadiometryParams(obj=ObjectParams(emissivity=e, reflected_temp_k=298.15))
    raw = celsius_to_raw(temp_c, p)
    higher = raw_to_celsius(raw, p.with_object(emissivity=min(1.0, e + de)))
    assert higher < temp_c


@given(temp_st, st.floats(0.5, 1.0), st.floats(0, 10), st.sampled_from(["flir", "thermimage"]))
def test_inverse_of_inverse(temp_c: float, e: float, d: float, method: str) -> None:
    p = RadiometryParams(
        obj=ObjectParams(
            emissivity=e, distance_m=d, reflected_temp_k=290.0, atmosphere_temp_k=295.0
        ),
        max_counts=None,
    )
    assert raw_to_celsius(celsius_to_raw(temp_c, p, method), p, method) == pytest.approx(
        temp_c, abs=1e-7
    )


# --- A camera's own temperature output (thermal.output kind: kelvin) ------------------------

LEPTON_TLINEAR = ThermalOutput.kelvin_per(0.01)
P2PRO = ThermalOutput.kelvin_per(1 / 64)


@given(
    st.floats(230.0, 1000.0),
    st.sampled_from([LEPTON_TLINEAR, P2PRO, ThermalOutput.kelvin_per(0.1, 50.0)]),
    st.sampled_from(["flir", "thermimage"]),
)
def test_kelvin_reading_passes_unchanged_with_emissivity_1_and_no_air(
    temp_k: float, output: ThermalOutput, method: str
) -> None:
    # The camera's reading is what it makes of a blackbody: with emissivity 1, no air and no
    # window our radiometry must give the reading back, whatever the Planck constants.
    values = (temp_k - output.offset_k) / output.scale_k
    for planck in (PAPER_2022, SC660):
        radiometry = Radiometry(Conditions(emissivity=1.0), planck, method, output)
        assert radiometry.celsius(values, 0.0) == pytest.approx(temp_k - K0, abs=1e-9)


@given(st.floats(-20, 400), st.floats(0.3, 1.0), st.floats(0, 10))
def test_kelvin_output_round_trip(temp_c: float, e: float, d: float) -> None:
    radiometry = Radiometry(Conditions(emissivity=e, ambient_temp_c=22.0), output=P2PRO)
    values = radiometry.counts(temp_c, d)  # the camera's values (float) of the object
    assert radiometry.celsius(values, d) == pytest.approx(temp_c, abs=1e-7)


def test_kelvin_reading_corrected_like_counts() -> None:
    # A camera reads the blackbody-equivalent of what reaches it: with emissivity 0.9 and
    # 3 m of air a 60 C object reads cooler; its reading, as counts would be, is corrected
    # back to 60 C, and both kinds give the same temperature to the reading's quantisation.
    conditions = Conditions(emissivity=0.9, ambient_temp_c=20.0, humidity_pct=70.0)
    counts = Radiometry(conditions).counts(60.0, 3.0)
    apparent_k = kelvin_from_counts(counts, PAPER_2022)
    assert apparent_k - K0 < 58.5  # what the camera itself says
    values = np.round(apparent_k / 0.01)
    got = Radiometry(conditions, output=LEPTON_TLINEAR).celsius(values, 3.0)
    assert got == pytest.approx(60.0, abs=0.02)  # 0.01 K steps, gain ~1.1 through e, tau
    assert got == pytest.approx(Radiometry(conditions).celsius(counts, 3.0), abs=0.02)


def test_values_that_are_no_reading() -> None:
    values = np.array([0.0, 1.0, 31215.0, 65535.0, np.nan, -5.0])
    bad = LEPTON_TLINEAR.invalid(values)  # 0: no data; 0.01 K: no temperature; 655 K: fine
    assert bad.tolist() == [True, True, False, False, True, True]
    blackbody = Radiometry(Conditions(emissivity=1.0), output=LEPTON_TLINEAR)
    assert blackbody.celsius(values)[2] == pytest.approx(39.0)
    counts16 = ThermalOutput(bits=16)
    assert counts16.invalid([16384.0, 65535.0, 65536.0]).tolist() == [False, False, True]
    assert ThermalOutput().invalid([16383.0, 16384.0]).tolist() == [False, True]
    with pytest.raises(ValueError, match="output kind 'celsius'"):
        ThermalOutput("celsius")
    with pytest.raises(ValueError, match="scale_k must be a finite number > 0"):
        ThermalOutput.kelvin_per(0.0)


def test_a_frame_of_another_kind_is_told() -> None:
    counts = np.full((120, 160), 8000, np.uint16)  # a Lepton's raw counts
    why = LEPTON_TLINEAR.problem(counts)
    assert why is not None and "median of 80.0 K, which is no temperature" in why
    assert ThermalOutput().problem(counts) is None
    tlinear = np.full((120, 160), 31215, np.uint16)
    assert LEPTON_TLINEAR.problem(tlinear) is None
    why = ThermalOutput().problem(tlinear)
    assert why is not None and "beyond the 14-bit range" in why
    tlinear[:50] = 0  # fewer than half of the pixels bad: NaN per pixel, no line
    assert LEPTON_TLINEAR.problem(tlinear) is None


# --- A whole frame in one pass (frame_radiometry) equals the numpy path -----------------------


@pytest.mark.parametrize("output", [ThermalOutput(), LEPTON_TLINEAR, P2PRO])
@pytest.mark.parametrize(("gain", "offset"), [(1.0, 0.0), (0.97, 35.0)])
def test_a_frame_in_one_pass_is_the_numpy_path(
    output: ThermalOutput, gain: float, offset: float
) -> None:
    rng = np.random.default_rng(4)
    lo, hi = (7000, 13000) if not output.is_kelvin else (26000, 45000)
    if output == P2PRO:
        lo, hi = 17000, 30000
    values = rng.integers(lo, hi, (48, 64)).astype(np.uint16)
    values[0, :5] = [0, 65535, 16384, 1, 6000]  # no data, beyond 14 bits, ...
    d = rng.uniform(0.2, 6.0, (48, 64)).astype(np.float32)
    d[1, :3] = [np.nan, 2000.0, 0.0]  # no distance, beyond the table, at the lens
    cond = Conditions(emissivity=0.9, ambient_temp_c=22.0, reflected_temp_c=30.0, humidity_pct=60.0)
    rad = Radiometry(cond, output=output)
    limits = (0.5, 4.0, 20.0, 60.0)
    fast = frame_celsius(values, d, rad.params(), output, gain, offset, limits, (1, 4, 8, 2))
    assert fast is not None
    temp, flags = fast
    signal = rad.signal(values)
    corrected = PAPER_2022.O + (signal - PAPER_2022.O - offset) / gain
    want = rad.with_output(ThermalOutput(bits=32)).celsius(corrected, d)  # the numpy path
    assert np.array_equal(np.isnan(temp), np.isnan(want))
    # float64 both, the sums reordered: 1e-6 C, or 2e-9 of the value at hundreds of C
    assert np.allclose(temp, want, rtol=2e-9, atol=1e-6, equal_nan=True)
    expected = (
        2
        | np.where((d < 0.5) | (d > 4.0), 1, 0)
        | np.where((want < 20.0) | (want > 60.0), 4, 0)
        | np.where(np.isnan(want), 8, 0)
    )
    assert np.array_equal(flags, expected)
    # a condition that is a map, another model or not a uint16 frame: the numpy path's
    emissivity_map = Radiometry(cond.replace(emissivity=np.full((48, 64), 0.9)), output=output)
    assert emissivity_map.frame(values, d) is None
    assert Radiometry(cond, method="thermimage", output=output).frame(values, d) is None
    assert rad.frame(values.astype(np.float64), d) is None
