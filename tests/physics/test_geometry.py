"""Tests of trackenv.physics.geometry: spectra, synthesis, D1 filter, sections, limits, isolated defects."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from trackenv.physics.geometry import (
    FRA_PROFILE_LIMITS_62FT_M,
    BandLimits,
    QualityLimits,
    classify,
    d1_filter,
    fra_psd,
    german_psd,
    isolated_defect,
    psd_variance,
    section_edges,
    section_index,
    section_peak,
    section_sd,
    synthesize_profile,
)

# ------------------------------------------------------------------------------------------------ spectra


def test_german_psd_hand_values():
    # Omega = 0.1: A*Oc^2 = 4.032e-7 * 0.67996516 = 2.7416195e-7;
    # (0.01 + 0.00042436) * (0.01 + 0.67996516) = 0.00719243  ->  3.81180e-5 m^2/(rad/m)
    # Omega = 1.0: (1.00042436) * (1.67996516) = 1.68067795  ->  1.63126e-7
    s = german_psd(np.array([0.1, 1.0]))
    np.testing.assert_allclose(s, [3.81180e-5, 1.63126e-7], rtol=1e-5)
    # high disturbance scales with A_v: 1.080e-6 / 4.032e-7
    np.testing.assert_allclose(german_psd([0.1, 1.0], "high"), s * 1.080e-6 / 4.032e-7, rtol=1e-12)


def test_fra_psd_hand_values():
    # class 4, Omega = 1: 0.25 * 0.5376e-4 * 0.8245^2 / (1 * (1 + 0.8245^2))
    #                   = 9.13651e-6 / 1.67980 = 5.43905e-6
    # Omega = 0.1: 9.13651e-6 / (0.01 * 0.68980025) = 1.32452e-3
    np.testing.assert_allclose(fra_psd([0.1, 1.0], 4), [1.32452e-3, 5.43905e-6], rtol=1e-5)
    # classes scale with A_v, and class 1 is the roughest
    np.testing.assert_allclose(fra_psd(0.5, 6) / fra_psd(0.5, 1), 0.0339 / 1.2107, rtol=1e-12)


def test_psd_errors_name_the_argument():
    with pytest.raises(ValueError, match="quality"):
        german_psd(0.1, "medium")
    with pytest.raises(ValueError, match="track_class"):
        fra_psd(0.1, 7)
    with pytest.raises(ValueError, match="wavenumber"):
        fra_psd(0.0, 4)
    with pytest.raises(ValueError, match="wavenumber"):
        german_psd([0.1, np.nan])


def test_psd_variance_matches_closed_form():
    # A*Oc^2 / ((W^2 + a^2)(W^2 + b^2)) = A*Oc^2/(b^2 - a^2) * (1/(W^2 + a^2) - 1/(W^2 + b^2))
    a_v, wc, wr = 4.032e-7, 0.8246, 0.0206
    w1, w2 = 2 * math.pi / 50.0, 2 * math.pi / 1.0

    def prim(w):
        return a_v * wc**2 / (wc**2 - wr**2) * (math.atan(w / wr) / wr - math.atan(w / wc) / wc)

    assert psd_variance(german_psd, 1.0, 50.0) == pytest.approx(prim(w2) - prim(w1), rel=1e-8)


# ---------------------------------------------------------------------------------------------- synthesis


def test_synthesis_variance_matches_psd_integral():
    psd = functools.partial(german_psd, quality="high")
    expected = psd_variance(psd, 1.0, 50.0)
    rng = np.random.default_rng(20240601)
    x = np.arange(0.0, 120.0, 0.6)
    var = np.mean([synthesize_profile(x, psd, rng).var() for _ in range(200)])
    assert var == pytest.approx(expected, rel=0.10)


def test_synthesis_narrow_band_long_track_and_uneven_positions():
    psd = functools.partial(fra_psd, track_class=5)
    expected = psd_variance(psd, 2.0, 10.0)
    rng = np.random.default_rng(7)
    x = np.sort(rng.uniform(0.0, 400.0, size=1500))  # not equally spaced
    draws = [synthesize_profile(x, psd, rng, min_wavelength=2.0, max_wavelength=10.0) for _ in range(5)]
    var = np.mean([d.var() for d in draws])
    assert var == pytest.approx(expected, rel=0.10)


def test_synthesis_zero_mean_and_reproducible():
    x = np.arange(0.0, 60.0, 0.6)
    a = synthesize_profile(x, german_psd, np.random.default_rng(3))
    b = synthesize_profile(x, german_psd, np.random.default_rng(3))
    c = synthesize_profile(x, german_psd, np.random.default_rng(4))
    assert a.shape == x.shape
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)
    assert abs(a.mean()) < 1e-15


def test_synthesis_band_limited():
    # only 5-10 m waves requested: the D1 band-pass at 20-40 m must see almost nothing of it
    x = np.arange(0.0, 600.0, 0.25)
    z = synthesize_profile(x, german_psd, np.random.default_rng(5), min_wavelength=5.0, max_wavelength=10.0)
    long_waves = d1_filter(z, 0.25, band=(20.0, 40.0))
    assert np.std(long_waves[400:-400]) < 0.02 * np.std(z)


def test_synthesis_bad_input():
    x = np.arange(10.0)
    with pytest.raises(ValueError, match="max_wavelength"):
        synthesize_profile(x, german_psd, np.random.default_rng(0), min_wavelength=5.0, max_wavelength=2.0)
    with pytest.raises(ValueError, match="synthesis_length"):
        synthesize_profile(x, german_psd, np.random.default_rng(0), synthesis_length=3.0)
    with pytest.raises(ValueError, match="x"):
        synthesize_profile([0.0, np.nan], german_psd, np.random.default_rng(0))
    with pytest.raises(TypeError, match="rng"):
        synthesize_profile(x, german_psd, 42)


# ---------------------------------------------------------------------------------------------- D1 filter


def _amplitude(y):
    return math.sqrt(2.0) * np.std(y)


@pytest.mark.parametrize("wavelength, low, high", [(10.0, 0.95, 1.05), (1.0, 0.0, 0.10), (100.0, 0.0, 0.10)])
def test_d1_passband_and_stopband(wavelength, low, high):
    dx = 0.25
    x = np.arange(0.0, 800.0, dx)
    z = 1e-3 * np.sin(2 * math.pi * x / wavelength)
    d1 = d1_filter(z, dx)
    interior = slice(int(150 / dx), -int(150 / dx))
    ratio = _amplitude(d1[interior]) / _amplitude(z[interior])
    assert low <= ratio <= high


def test_d1_short_track_passband_everywhere():
    # the env's tracks are short (60 m at 0.6 m): a 10 m sine still comes through at the ends
    dx = 0.6
    x = np.arange(0.0, 60.0, dx)
    z = 2e-3 * np.sin(2 * math.pi * x / 10.0 + 0.3)
    d1 = d1_filter(z, dx)
    assert np.max(np.abs(d1 - z)) < 0.15 * 2e-3
    assert np.max(np.abs(d1[17:-17] - z[17:-17])) < 0.05 * 2e-3


def test_d1_removes_offset_and_slope_including_edges():
    dx = 0.6
    x = np.arange(0.0, 60.0, dx)
    d1 = d1_filter(5e-3 + 1e-4 * x, dx)
    assert np.max(np.abs(d1)) < 1e-6  # < 1 micrometre for a 5-11 mm ramp


def test_d1_batched_last_axis():
    dx = 0.6
    x = np.arange(0.0, 90.0, dx)
    zz = np.stack([np.sin(2 * math.pi * x / 8.0), np.cos(2 * math.pi * x / 15.0)]) * 1e-3
    out = d1_filter(zz, dx)
    np.testing.assert_allclose(out[1], d1_filter(zz[1], dx), atol=1e-15)


@pytest.mark.parametrize("quality", ["low", "high"])
def test_compiled_d1_matches_the_scipy_reference(quality):
    """The compiled D1 core (trackenv.physics._d1) runs the method of the scipy implementation it replaced
    (tests/physics/d1_reference.py): Levinson's recursion instead of solve_toeplitz, the AR prediction as a plain
    recursion instead of lfilter, the same second-order sections. On env-like tracks (PSD level of low and high
    disturbance, 60-600 m at 0.6 m, offsets and slopes; levels of 3-20 mm) it agrees to 3.3e-16 m measured;
    bound 1e-15 m; also without the end extension and for a record too short for an AR model."""
    from d1_reference import d1_reference

    rng = np.random.default_rng(11)
    for length in (60.0, 120.0, 240.0):
        x = np.arange(0.0, length, 0.6)
        z = np.stack([synthesize_profile(x, functools.partial(german_psd, quality=quality), rng) for _ in range(4)])
        z += rng.uniform(-5e-3, 5e-3, (4, 1)) + rng.uniform(-1e-4, 1e-4, (4, 1)) * x
        np.testing.assert_allclose(d1_filter(z, 0.6), d1_reference(z, 0.6), rtol=0.0, atol=1e-15)
        np.testing.assert_allclose(d1_filter(z, 0.6, pad_wavelengths=0.0), d1_reference(z, 0.6, pad_wavelengths=0.0),
                                   rtol=0.0, atol=1e-15)
    short = np.array([1e-3, -2e-3, 0.5e-3])
    np.testing.assert_allclose(d1_filter(short, 0.6), d1_reference(short, 0.6), rtol=0.0, atol=1e-15)


def test_d1_bad_input():
    z = np.zeros(100)
    with pytest.raises(ValueError, match="spacing"):
        d1_filter(z, -0.6)
    with pytest.raises(ValueError, match="z"):
        d1_filter(np.array([0.0, np.nan, 1.0]), 0.6)
    with pytest.raises(ValueError, match="band"):
        d1_filter(z, 2.0)  # 3 m is below the Nyquist wavelength of 4 m
    with pytest.raises(ValueError, match="band"):
        d1_filter(z, 0.6, band=(25.0, 3.0))


# ----------------------------------------------------------------------------------------------- sections


def test_section_edges_and_index():
    np.testing.assert_array_equal(section_edges(10, 3), [0, 3, 6, 10])
    np.testing.assert_array_equal(section_index(10, 3), [0, 0, 0, 1, 1, 1, 2, 2, 2, 2])
    with pytest.raises(ValueError, match="n_sections"):
        section_edges(3, 4)


def test_section_sd_and_peak_by_hand():
    z = np.array([1.0, -1.0, 1.0, -1.0, 0.0, 0.0, 2.0, -4.0])
    idx = np.array([0, 0, 0, 0, 1, 1, 2, 2])
    np.testing.assert_allclose(section_sd(z, idx, 3), [1.0, 0.0, 3.0])
    np.testing.assert_allclose(section_peak(z, idx, 3), [1.0, 0.0, 4.0])
    # non-contiguous sections are fine
    np.testing.assert_allclose(section_peak(z, np.array([0, 1, 0, 1, 0, 1, 0, 1]), 2), [2.0, 4.0])


def test_section_statistics_of_a_batch_are_those_of_each_row():
    """A batch of records (rows, n) gives each row's SD and peak exactly as the row alone (one call of the vector
    env for all its envs)."""
    rng = np.random.default_rng(3)
    z = rng.standard_normal((5, 2, 23))
    idx = section_index(23, 4)
    sd, peak = section_sd(z, idx, 4), section_peak(z, idx, 4)
    assert sd.shape == peak.shape == (5, 2, 4)
    for r in np.ndindex(5, 2):
        np.testing.assert_array_equal(sd[r], section_sd(z[r], idx, 4))
        np.testing.assert_array_equal(peak[r], section_peak(z[r], idx, 4))
    with pytest.raises(ValueError, match="section_index"):
        section_sd(z, section_index(22, 4), 4)


def test_section_bad_input():
    z = np.zeros(4)
    with pytest.raises(ValueError, match="section_index"):
        section_sd(z, np.array([0, 1, 2, 3]), 3)
    with pytest.raises(ValueError, match="section_index"):
        section_sd(z, np.array([0, 0, 0, 0]), 2)  # section 1 empty
    with pytest.raises(ValueError, match="z"):
        section_peak(np.array([0.0, np.nan]), np.array([0, 0]), 1)


# ------------------------------------------------------------------------------------------------- limits


def test_limits_lookup_by_speed():
    q = QualityLimits.en13848()
    assert q.for_speed(100 / 3.6).immediate_action_m == pytest.approx(26e-3)
    assert q.for_speed(80 / 3.6).immediate_action_m == pytest.approx(28e-3)  # upper bound inclusive
    assert q.for_speed(0.0).immediate_action_m == pytest.approx(28e-3)
    band = q.for_speed(250 / 3.6)
    assert (band.speed_low_kmh, band.speed_high_kmh) == (230.0, 300.0)
    assert band.immediate_action_m == pytest.approx(16e-3)
    for v in (10, 25, 40, 60, 80):
        b = q.for_speed(v)
        assert 0 < b.alert_m < b.intervention_m < b.immediate_action_m
        assert b.sd_alert_m > 0
    # 80-120 km/h alert and intervention lie in the ranges given by EN 13848-5
    b = q.for_speed(30.0)
    assert 8e-3 <= b.alert_m <= 16e-3 and 11e-3 <= b.intervention_m <= 20e-3
    assert 1.8e-3 <= b.sd_alert_m <= 2.7e-3
    with pytest.raises(ValueError, match="speed_m_per_s"):
        q.for_speed(301 / 3.6)
    with pytest.raises(ValueError, match="speed_m_per_s"):
        q.for_speed(-1.0)


def test_limits_tables_stricter_at_higher_speed():
    q = QualityLimits.en13848()
    for col in (q.alert_m, q.intervention_m, q.immediate_action_m, q.sd_alert_m):
        assert np.all(np.diff(col) < 0)
    assert "13848" in q.source


def test_classify():
    lim = BandLimits(
        alert_m=0.01,
        intervention_m=0.015,
        immediate_action_m=0.026,
        sd_alert_m=0.002,
        speed_low_kmh=80.0,
        speed_high_kmh=120.0,
    )
    peaks = np.array([0.0, 0.0099, 0.01, 0.0151, 0.026, 0.05])
    np.testing.assert_array_equal(classify(peaks, lim), [0, 0, 1, 2, 3, 3])
    sd = np.array([0.0025, 0.0, 0.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(classify(peaks, lim, sd), [1, 0, 1, 2, 3, 3])
    with pytest.raises(ValueError, match="peaks"):
        classify([np.nan], lim)
    with pytest.raises(ValueError, match="limits"):
        classify(peaks, QualityLimits.en13848())


def test_limits_from_dict_and_validation():
    d = {
        "speed_upper_kmh": [100, 200],
        "alert_m": [0.01, 0.008],
        "intervention_m": [0.015, 0.012],
        "immediate_action_m": [0.025, 0.02],
        "sd_alert_m": [0.002, 0.0015],
    }
    q = QualityLimits.from_dict(d)
    assert q.speed_upper_kmh == (100.0, 200.0)
    assert q.for_speed(150 / 3.6).alert_m == pytest.approx(0.008)
    with pytest.raises(ValueError, match="colour"):
        QualityLimits.from_dict({**d, "colour": "red"})
    with pytest.raises(ValueError, match="speed_upper_kmh"):
        QualityLimits.from_dict({**d, "speed_upper_kmh": [200, 100]})
    with pytest.raises(ValueError, match="intervention_m"):
        QualityLimits.from_dict({**d, "intervention_m": [0.005, 0.012]})
    with pytest.raises(ValueError, match="sd_alert_m"):
        QualityLimits.from_dict({**d, "sd_alert_m": [0.002]})


def test_fra_profile_table():
    assert FRA_PROFILE_LIMITS_62FT_M[1] == pytest.approx(0.0762)
    assert FRA_PROFILE_LIMITS_62FT_M[5] == pytest.approx(1.25 * 0.0254)


# ------------------------------------------------------------------------------------------ isolated defect


def test_isolated_defect_shape():
    x = np.linspace(0.0, 20.0, 201)
    z = isolated_defect(0.01, 4.0, x, 10.0)
    assert z.max() == pytest.approx(0.01)
    assert z[100] == pytest.approx(0.01)  # deepest at the centre, positive = downward
    assert np.all(z[x < 8.0] == 0.0) and np.all(z[x > 12.0] == 0.0)
    assert z[np.argmin(np.abs(x - 9.0))] == pytest.approx(0.005)  # half depth at a quarter length
    assert np.max(np.abs(np.diff(z))) < 0.01 * 0.1 * math.pi / 4.0 * 1.01  # smooth: slope <= pi*d/(2*L)
    with pytest.raises(ValueError, match="length"):
        isolated_defect(0.01, 0.0, x, 10.0)
    with pytest.raises(ValueError, match="depth"):
        isolated_defect(np.nan, 1.0, x, 10.0)
