"""Tests of trackenv.physics.tamping."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackenv.physics.tamping import TampingModel, TampingResult, sd_after_tamping, tamp, tamped_runs

N = 100  # sleepers (60 m at 0.6 m)


def _level(seed: int, sd: float = 4e-3) -> np.ndarray:
    """A settled, irregular level: 10 mm mean settlement plus smooth-ish random shape of SD about ``sd``."""
    rng = np.random.default_rng(seed)
    shape = np.convolve(rng.standard_normal(N + 6), np.ones(7) / 7.0, mode="valid")
    return 10e-3 + sd * shape / shape.std()


def _mask(start: int = 30, stop: int = 70) -> np.ndarray:
    m = np.zeros(N, dtype=bool)
    m[start:stop] = True
    return m


def test_tamping_lowers_sd_and_restores_design_line():
    z = _level(1)
    m = _mask()
    res = tamp(z, m, TampingModel(reference="design"), np.random.default_rng(0), np.zeros(N, int))
    assert isinstance(res, TampingResult)
    inner = slice(34, 66)  # tamped run without its run-outs
    assert np.std(res.level[inner]) < 0.5 * np.std(z[inner])
    # mean settlement of the tamped run is lifted back to (close to) the design line, except the run-outs
    assert abs(np.mean(res.level[34:66])) < 1e-3 < np.mean(z[34:66])
    assert np.all(res.lift[34:66] > 0)  # settled track: every fully tamped sleeper is raised


def test_smoothing_mode_keeps_level_of_neighbours():
    model = TampingModel(reference="smoothing")
    z = _level(1)
    m = _mask()
    res = tamp(z, m, model, np.random.default_rng(0), np.zeros(N, int))
    assert np.std(res.level[m]) < 0.5 * np.std(z[m])
    assert np.mean(res.level[m]) > 5e-3  # stays near the settled ~10 mm: no lift to the design line
    # a uniformly settled track is left where it is (no step), only the residual is added
    flat = tamp(
        np.full(N, 12e-3),
        m,
        TampingModel(reference="smoothing", residual_sd_m=0.0),
        np.random.default_rng(0),
        np.zeros(N, int),
    )
    np.testing.assert_allclose(flat.level, 12e-3, atol=1e-15)
    # kept shape is beta times the shape about the chord through the untamped neighbours
    exact = tamp(
        z,
        m,
        TampingModel(reference="smoothing", residual_sd_m=0.0, runout_sleepers=0),
        np.random.default_rng(0),
        np.zeros(N, int),
    )
    chord = z[29] + (z[70] - z[29]) * (np.arange(30, 70) - 29) / 41.0
    np.testing.assert_allclose(exact.level[m] - chord, 0.3 * (z[m] - chord), atol=1e-15)
    with pytest.raises(ValueError, match="reference"):
        TampingModel(reference="absolute")
    assert TampingModel().reference == "smoothing"  # the default (spot tamping of short sections)


@pytest.mark.parametrize("reference", ["design", "smoothing"])
def test_untamped_sleepers_unchanged(reference):
    z = _level(2)
    m = _mask(10, 40) | _mask(60, 80) | _mask(95, 100)
    t0 = np.arange(N) % 3
    res = tamp(z, m, TampingModel(reference=reference), np.random.default_rng(0), t0)
    np.testing.assert_array_equal(res.level[~m], z[~m])
    np.testing.assert_array_equal(res.tampings[~m], t0[~m])
    np.testing.assert_array_equal(res.tampings[m], t0[m] + 1)
    np.testing.assert_array_equal(res.lift[~m], 0.0)
    np.testing.assert_array_equal(res.restarted_mask, m)
    assert not res.renewed_mask.any()


def test_no_mask_changes_nothing():
    z = _level(3)
    res = tamp(z, np.zeros(N, bool), TampingModel(), np.random.default_rng(0), np.ones(N, int))
    np.testing.assert_array_equal(res.level, z)
    np.testing.assert_allclose(res.rate_factor, 1.15)


def test_rate_factor_grows_and_resets_at_renewal():
    model = TampingModel(damage_per_tamping=0.15, max_tampings_before_renewal=3)
    z = _level(4)
    m = np.ones(N, dtype=bool)
    count = np.zeros(N, dtype=int)
    rng = np.random.default_rng(5)
    factors = []
    for _ in range(4):
        res = tamp(z, m, model, rng, count)
        count, z = res.tampings, res.level
        factors.append(res.rate_factor[0])
        assert res.renewed_mask.any() == (len(factors) == 4)
    np.testing.assert_allclose(factors, [1.15, 1.15**2, 1.15**3, 1.0])
    np.testing.assert_array_equal(count, 0)
    # without renewal the count and the factor keep growing
    res = tamp(z, m, TampingModel(max_tampings_before_renewal=3, renewal_resets=False), rng, np.full(N, 3))
    np.testing.assert_allclose(res.rate_factor, 1.15**4)
    assert not res.renewed_mask.any()


def test_renewal_removes_memory():
    z = _level(6)
    m = np.ones(N, dtype=bool)
    model = TampingModel(reference="design", residual_sd_m=0.0, max_tampings_before_renewal=2)
    res = tamp(z, m, model, np.random.default_rng(0), np.full(N, 2))
    assert res.renewed_mask.all()
    np.testing.assert_allclose(res.level, 0.0, atol=1e-15)


def test_runout_keeps_edge_step_small():
    z = np.full(N, 12e-3)  # uniformly settled 12 mm
    m = _mask()
    model = TampingModel(reference="design", residual_fraction=0.3, residual_sd_m=0.0, runout_sleepers=3)
    res = tamp(z, m, model, np.random.default_rng(0), np.zeros(N, int))
    steps = np.abs(np.diff(res.level))
    assert steps.max() <= 12e-3 / 4 + 1e-12  # lift ramps over runout + 1 sleeper spacings
    np.testing.assert_allclose(res.level[30:34], 12e-3 * np.array([0.75, 0.5, 0.25, 0.0]), atol=1e-15)
    no_ramp = tamp(
        z,
        m,
        TampingModel(reference="design", residual_sd_m=0.0, runout_sleepers=0),
        np.random.default_rng(0),
        np.zeros(N, int),
    )
    assert np.abs(np.diff(no_ramp.level)).max() == pytest.approx(12e-3)


def test_run_touching_array_end_is_not_ramped():
    z = np.full(N, 12e-3)
    model = TampingModel(reference="design", residual_sd_m=0.0)
    res = tamp(z, _mask(0, 20), model, np.random.default_rng(0), np.zeros(N, int))
    assert res.level[0] == pytest.approx(0.0, abs=1e-15)
    assert res.level[19] == pytest.approx(12e-3 * 0.75)


def test_same_seed_same_result():
    z = _level(7)
    m = _mask(20, 50)
    t0 = np.zeros(N, int)
    a = tamp(z, m, TampingModel(), np.random.default_rng(11), t0)
    b = tamp(z, m, TampingModel(), np.random.default_rng(11), t0)
    c = tamp(z, m, TampingModel(), np.random.default_rng(12), t0)
    np.testing.assert_array_equal(a.level, b.level)
    assert not np.array_equal(a.level, c.level)
    np.testing.assert_array_equal(z, _level(7))  # input not modified


def test_beta_behaviour_on_average():
    # away from the run-outs, SD after / SD before (about the line fit) is residual_fraction without
    # residual noise, and matches sd_after_tamping on average with it
    model = TampingModel(reference="design", residual_fraction=0.3, residual_sd_m=0.5e-3)
    inner = slice(34, 66)
    m = _mask()
    ratios, sds_before, sds_after = [], [], []
    rng = np.random.default_rng(99)
    for seed in range(100):
        z = _level(seed)
        t = np.arange(32)
        fit = np.polyval(np.polyfit(np.arange(40), z[m], 1), t + 4)
        sd_b = np.std(z[inner] - fit)
        exact = tamp(
            z,
            m,
            TampingModel(reference="design", residual_fraction=0.3, residual_sd_m=0.0),
            rng,
            np.zeros(N, int),
        )
        ratios.append(np.std(exact.level[inner]) / sd_b)
        noisy = tamp(z, m, model, rng, np.zeros(N, int))
        sds_before.append(sd_b)
        sds_after.append(np.std(noisy.level[inner]))
    np.testing.assert_allclose(ratios, 0.3, rtol=1e-9)
    predicted = sd_after_tamping(np.array(sds_before), model)
    assert np.mean(sds_after) == pytest.approx(np.mean(predicted), rel=0.05)
    linear = sd_after_tamping(np.array(sds_before), model, linear=True)
    assert np.all(linear >= predicted)


def test_sd_after_tamping_forms():
    model = TampingModel(residual_fraction=0.4, residual_sd_m=1e-3)
    assert sd_after_tamping(0.0, model) == pytest.approx(1e-3)
    assert sd_after_tamping(3e-3, model, linear=True) == pytest.approx(1e-3 + 0.4 * 3e-3)
    assert sd_after_tamping(3e-3, model) == pytest.approx(np.hypot(1e-3, 1.2e-3))
    with pytest.raises(ValueError, match="sd_before"):
        sd_after_tamping(-1.0, model)


def test_tamped_runs():
    m = np.array([1, 1, 0, 0, 1, 0, 1, 1, 1], dtype=bool)
    np.testing.assert_array_equal(tamped_runs(m), [[0, 2], [4, 5], [6, 9]])
    assert tamped_runs(np.zeros(3, bool)).shape == (0, 2)


def test_bad_input_names_the_parameter():
    z = _level(8)
    rng = np.random.default_rng(0)
    t0 = np.zeros(N, int)
    with pytest.raises(ValueError, match="mask"):
        tamp(z, np.ones(N - 1, bool), TampingModel(), rng, t0)
    with pytest.raises(ValueError, match="mask"):
        tamp(z, np.ones(N), TampingModel(), rng, t0)
    bad = z.copy()
    bad[5] = np.nan
    with pytest.raises(ValueError, match="level"):
        tamp(bad, _mask(), TampingModel(), rng, t0)
    with pytest.raises(ValueError, match="tampings"):
        tamp(z, _mask(), TampingModel(), rng, np.full(N, -1))
    with pytest.raises(ValueError, match="tampings"):
        tamp(z, _mask(), TampingModel(), rng, np.zeros(N + 1, int))
    with pytest.raises(TypeError, match="rng"):
        tamp(z, _mask(), TampingModel(), 0, t0)
    with pytest.raises(ValueError, match="residual_fraction"):
        TampingModel(residual_fraction=1.5)
    with pytest.raises(ValueError, match="residual_fraction"):
        TampingModel(residual_fraction=-0.1)
    with pytest.raises(ValueError, match="max_tampings_before_renewal"):
        TampingModel(max_tampings_before_renewal=0)
    with pytest.raises(ValueError, match="runout_sleepers"):
        TampingModel(runout_sleepers=1.5)


def test_model_from_dict_and_helpers():
    model = TampingModel.from_dict({"residual_fraction": 0.4, "runout_sleepers": 5})
    assert model.residual_fraction == 0.4 and model.runout_sleepers == 5
    with pytest.raises(ValueError, match="lift_mm"):
        TampingModel.from_dict({"lift_mm": 3})
    with pytest.raises(ValueError, match="residual_sd_m"):
        TampingModel.from_dict({"residual_sd_m": -1e-3})
    np.testing.assert_allclose(model.rate_factor([0, 2]), [1.0, 1.15**2])
    assert TampingModel().duration_s(100.0) == pytest.approx(360.0)  # 100 m at 1 km/h
    with pytest.raises(dataclasses.FrozenInstanceError):
        model.residual_fraction = 0.1  # type: ignore[misc]


@settings(max_examples=40, deadline=None)
@given(
    mask=st.lists(st.booleans(), min_size=1, max_size=40),
    seed=st.integers(0, 2**32 - 1),
    runout=st.integers(0, 5),
    reference=st.sampled_from(["design", "smoothing"]),
)
def test_property_untamped_unchanged_and_finite(mask, seed, runout, reference):
    m = np.array(mask, dtype=bool)
    rng = np.random.default_rng(seed)
    z = rng.normal(5e-3, 3e-3, size=m.size)
    t0 = rng.integers(0, 10, size=m.size)
    res = tamp(z, m, TampingModel(runout_sleepers=runout, reference=reference), rng, t0)
    assert np.all(np.isfinite(res.level))
    np.testing.assert_array_equal(res.level[~m], z[~m])
    np.testing.assert_allclose(res.lift, z - res.level)
    assert np.all(res.rate_factor >= 1.0)
    assert np.all(res.tampings[m & ~res.renewed_mask] == t0[m & ~res.renewed_mask] + 1)


@pytest.mark.parametrize(("max_lift", "expected"), [(np.inf, 0.0), (0.05, 0.03), (0.02, 0.06), (0.1, 0.0)])
def test_design_lift_is_limited_per_pass(max_lift, expected):
    """A uniformly settled track (80 mm) tamped all along: lifted to the design line, by at most max_lift_m."""
    z = np.full(50, 0.08)
    model = TampingModel(reference="design", residual_sd_m=0.0, max_lift_m=max_lift)
    res = tamp(z, np.ones(50, bool), model, np.random.default_rng(0), np.zeros(50, int))
    np.testing.assert_allclose(res.level, expected, atol=1e-12)
    np.testing.assert_allclose(res.lift, 0.08 - expected, atol=1e-12)


def test_repeated_limited_lifts_reach_the_design_line():
    model = TampingModel(reference="design", residual_sd_m=0.0, residual_fraction=0.0, max_lift_m=0.03)
    z, n = np.full(30, 0.08), np.zeros(30, int)
    for expected in (0.05, 0.02, 0.0, 0.0):
        z = tamp(z, np.ones(30, bool), model, np.random.default_rng(0), n).level
        np.testing.assert_allclose(z, expected, atol=1e-12)


@pytest.mark.parametrize("bad", [0.0, -0.01, 2.0, "0.05", np.nan])
def test_max_lift_is_checked(bad):
    with pytest.raises(ValueError, match="^max_lift_m must"):
        TampingModel(max_lift_m=bad)


def test_restored_level_rows_match_the_model_row_by_row():
    """The engine's batched restoration: a row tamped whole is lifted to its least-squares line (numpy.polyfit
    here) keeping beta of its shape plus the given residual; a partly tamped row is the run-by-run model of
    :func:`tamp` (same noise), its untamped sleepers unchanged; a row of the batch does not depend on the others."""
    from trackenv.physics.tamping import restored_level

    rng = np.random.default_rng(7)
    n = 40
    level = rng.normal(0.0, 2e-3, (3, n)).cumsum(axis=1) * 0.2
    noise = rng.standard_normal((3, n))
    mask = np.ones((3, n), bool)
    mask[1, :] = False
    mask[1, 10:25] = True
    mask[2, :] = False
    model = TampingModel()
    renewed = np.zeros((3, n), bool)
    new = restored_level(level, mask, model, noise, renewed)
    x = np.arange(n)
    line = np.polyval(np.polyfit(x, level[0], 1), x)
    expected = line + model.residual_fraction * (level[0] - line) + model.residual_sd_m * noise[0]
    np.testing.assert_allclose(new[0], expected, rtol=0, atol=1e-15)

    class Given(np.random.Generator):  # tamp draws its residual from rng: give it the same one
        def standard_normal(self, size=None, dtype=np.float64, out=None):
            return noise[1].copy()

    given_noise = Given(np.random.PCG64(0))
    np.testing.assert_array_equal(new[1], tamp(level[1], mask[1], model, given_noise, np.zeros(n, int)).level)
    assert np.array_equal(new[1, ~mask[1]], level[1, ~mask[1]]) and np.array_equal(new[2], level[2])
    alone = restored_level(level[1:2], mask[1:2], model, noise[1:2], renewed[1:2])
    np.testing.assert_array_equal(alone[0], new[1])
