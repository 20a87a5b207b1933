"""Tests of trackenv.physics.track: parameters, closed forms, assembly, and the static and harmonic responses
of the finite-element track against the Winkler beam and the pinned-pinned rail mode."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackenv.physics.dynamics import receptance, static_deflection
from trackenv.physics.track import PER_SLEEPER_FIELDS, Track, hermite_element_matrices, hermite_shape

P = 100e3  # [N]


def winkler_closed_form(
    kp: float, kb: float, spacing: float, ei: float, load: float
) -> tuple[float, float, float]:
    """(k_f, β, w0) of a Winkler beam: supports of pad and ballast in series, smeared over the spacing."""
    k_support = 1.0 / (1.0 / kp + 1.0 / kb)
    k_f = k_support / spacing
    beta = (k_f / (4.0 * ei)) ** 0.25
    return k_f, beta, load * beta / (2.0 * k_f)


SEED_KF, SEED_BETA, SEED_W0 = winkler_closed_form(200e6, 160e6, 0.6, 6.11e6, P)
SEED_PINNED_PINNED = (math.pi / 0.6) ** 2 * math.sqrt(6.11e6 / 60.0) / (2.0 * math.pi)


# ------------------------------------------------------------------------------------------ parameters
def test_seed_is_table_3():
    t = Track.seed()
    assert t.n_sleepers == 51
    assert t.sleeper_spacing == 0.6
    assert t.length == pytest.approx(30.0)
    assert t.rail_bending_stiffness == 6.11e6
    assert t.rail_mass == 60.0
    expected = {
        "pad_stiffness": 200e6,
        "pad_damping": 30e3,
        "sleeper_mass": 157.4,
        "ballast_stiffness": 160e6,
        "ballast_damping": 500e3,
    }
    for name, value in expected.items():
        np.testing.assert_array_equal(getattr(t, name), np.full(51, value))
    np.testing.assert_allclose(t.sleeper_positions, 0.6 * np.arange(51))


def test_realistic_track_uic60():
    t = Track.realistic(120.0)
    assert t.n_sleepers == 201
    assert t.length == pytest.approx(120.0)
    assert t.rail_bending_stiffness == pytest.approx(210e9 * 3055e-8)
    np.testing.assert_array_equal(t.ballast_damping, 60e3)


def test_arrays_are_read_only():
    t = Track.seed()
    with pytest.raises(ValueError):
        t.pad_stiffness[0] = 1.0


def test_mesh_counts_and_layout():
    for epb in (2, 3, 4):
        t = Track.seed(elements_per_bay=epb)
        assert t.element_length == pytest.approx(0.6 / epb)
        assert t.n_nodes == 50 * epb + 1
        assert t.n_dof == 2 * t.n_nodes + 51
        lay = t.dof_layout
        all_dofs = np.concatenate([lay.node_w, lay.node_theta, lay.sleeper])
        np.testing.assert_array_equal(np.sort(all_dofs), np.arange(t.n_dof))
        np.testing.assert_array_equal(lay.sleeper_node, epb * np.arange(51))
        # the sleeper DOF follows the (w, θ) of the rail node above it: half-bandwidth 4
        np.testing.assert_array_equal(lay.sleeper, lay.node_w[lay.sleeper_node] + 2)
        # a bay is 2·epb + 1 DOFs, the same for every bay: the kernel indexes a window's sleepers from its start
        np.testing.assert_array_equal(lay.node_w[lay.sleeper_node], (2 * epb + 1) * np.arange(51))


# ------------------------------------------------------------------------------------------ modifiers
def test_scaled_is_scenario_b():
    t = Track.seed().scaled(ballast_stiffness=1.10, from_sleeper=40)
    np.testing.assert_array_equal(t.ballast_stiffness[:40], 160e6)
    np.testing.assert_allclose(t.ballast_stiffness[40:], 176e6)
    np.testing.assert_array_equal(t.pad_stiffness, 200e6)
    part = Track.seed().scaled(pad_stiffness=0.5, from_sleeper=10, to_sleeper=12)
    np.testing.assert_allclose(part.pad_stiffness[10:12], 100e6)
    assert np.count_nonzero(part.pad_stiffness != 200e6) == 2


def test_voided_sleeper():
    t = Track.seed().with_voided_sleeper(25, residual_support=0.1)
    assert t.ballast_stiffness[25] == pytest.approx(16e6)
    assert t.ballast_damping[25] == pytest.approx(50e3)
    assert np.count_nonzero(t.ballast_stiffness != 160e6) == 1
    # the rail over a hanging sleeper deflects more
    assert static_deflection(t, P, 15.0) > 1.05 * static_deflection(Track.seed(), P, 15.0)


def test_extended():
    base = Track.seed().scaled(ballast_stiffness=2.0, from_sleeper=50)
    t = base.extended(3, 5)
    assert t.n_sleepers == 59
    np.testing.assert_array_equal(t.ballast_stiffness[:3], 160e6)
    np.testing.assert_array_equal(t.ballast_stiffness[-5:], 320e6)
    np.testing.assert_array_equal(t.ballast_stiffness[3:-5], base.ballast_stiffness)


def test_modifier_errors():
    t = Track.seed()
    with pytest.raises(ValueError, match="unknown"):
        t.replace(ballast_modulus=1.0)
    with pytest.raises(ValueError, match="unknown per-sleeper"):
        t.scaled(rail_mass=2.0)
    with pytest.raises(ValueError, match="from_sleeper"):
        t.scaled(ballast_stiffness=1.1, from_sleeper=51)
    with pytest.raises(ValueError, match="ballast_stiffness"):
        t.scaled(ballast_stiffness=-1.0)
    with pytest.raises(ValueError, match="n_before"):
        t.extended(-1, 0)


# ------------------------------------------------------------------------------------------ bad input
@pytest.mark.parametrize("name", PER_SLEEPER_FIELDS)
@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf")])
def test_bad_per_sleeper_value_names_the_field(name, bad):
    values = np.array(getattr(Track.seed(), name))
    values[7] = bad
    with pytest.raises(ValueError, match=name):
        Track.seed().replace(**{name: values})


@pytest.mark.parametrize("name", ["pad_stiffness", "ballast_stiffness", "sleeper_mass"])
def test_zero_stiffness_or_mass_rejected(name):
    with pytest.raises(ValueError, match=name):
        Track.seed().replace(**{name: np.zeros(51)})


def test_supports_too_soft_to_hold_the_rail_are_refused():
    """Positive supports summing to less than 1e-9 of a rail element's stiffness (the rail floats; the matrix is
    singular in floating point, and a Cholesky factorisation failed inside scipy) are refused naming both fields,
    and the floor follows the rail and its mesh; a soft track far above it builds and deflects."""
    kw = dict(pad_damping=0.0, sleeper_mass=1.0, ballast_damping=0.0)
    with pytest.raises(ValueError, match="pad_stiffness and ballast_stiffness.*below 2.72 N/m"):
        Track.uniform(3, pad_stiffness=1.0, ballast_stiffness=1e-277, **kw)
    with pytest.raises(ValueError, match="rail would float"):
        Track.uniform(30, pad_stiffness=200e6, ballast_stiffness=1e-2, **kw)
    Track.uniform(30, pad_stiffness=200e6, ballast_stiffness=1.0, **kw)  # 30 N/m > 2.72: built
    with pytest.raises(ValueError, match="rail would float"):  # a finer mesh: a stiffer element, a higher floor
        Track.uniform(30, pad_stiffness=200e6, ballast_stiffness=1.0, elements_per_bay=8, **kw)
    soft = Track.uniform(51, pad_stiffness=1e6, ballast_stiffness=1e6, **kw)
    assert np.isfinite(static_deflection(soft)) and static_deflection(soft) > static_deflection(Track.seed())


@pytest.mark.parametrize(
    "name,bad",
    [
        ("rail_bending_stiffness", -6.11e6),
        ("rail_bending_stiffness", np.nan),
        ("rail_mass", 0.0),
        ("sleeper_spacing", -0.6),
        ("sleeper_spacing", np.nan),
    ],
)
def test_bad_scalar_names_the_field(name, bad):
    with pytest.raises(ValueError, match=name):
        Track.seed().replace(**{name: bad})


def test_bad_shapes_and_mesh():
    with pytest.raises(ValueError, match="ballast_damping"):
        Track.seed().replace(ballast_damping=np.ones(50))
    with pytest.raises(ValueError, match="elements_per_bay"):
        Track.seed(elements_per_bay=1)
    with pytest.raises(ValueError, match="n_sleepers"):
        Track.uniform(
            2,
            pad_stiffness=1.0,
            pad_damping=0.0,
            sleeper_mass=1.0,
            ballast_stiffness=1.0,
            ballast_damping=0.0,
        )


# ------------------------------------------------------------------------------------------ closed forms
def test_winkler_closed_forms():
    t = Track.seed()
    assert t.foundation_modulus == pytest.approx(SEED_KF, rel=1e-12)
    assert t.winkler_beta == pytest.approx(SEED_BETA, rel=1e-12)
    assert t.winkler_deflection(P) == pytest.approx(SEED_W0, rel=1e-12)
    assert t.pinned_pinned_frequency == pytest.approx(SEED_PINNED_PINNED, rel=1e-12)
    assert SEED_PINNED_PINNED == pytest.approx(1392.0, abs=1.0)


def test_hermite_shape_functions():
    L = 0.3
    np.testing.assert_allclose(hermite_shape(0.0, L), [1, 0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(hermite_shape(1.0, L), [0, 0, 1, 0], atol=1e-15)
    for xi in np.linspace(0, 1, 7):
        n = hermite_shape(xi, L)
        # a rigid translation and a rigid rotation about node 1 are reproduced exactly
        assert n[0] + n[2] == pytest.approx(1.0, abs=1e-15)
        assert n[1] + n[2] * L + n[3] == pytest.approx(xi * L, abs=1e-15)
    # a cubic is reproduced exactly: w = x^3 has w(0)=0, θ(0)=0, w(L)=L^3, θ(L)=3L^2
    xi = 0.37
    assert hermite_shape(xi, L) @ [0.0, 0.0, L**3, 3 * L**2] == pytest.approx((xi * L) ** 3, rel=1e-13)


def test_matrices_symmetric_definite_and_banded():
    t = Track.seed()
    m, c, k = (a.toarray() for a in t.matrices())
    for a in (m, c, k):
        np.testing.assert_allclose(a, a.T, rtol=0, atol=1e-9 * np.abs(a).max())
        i, j = np.nonzero(a)
        assert np.max(np.abs(i - j)) <= 4
    assert np.linalg.eigvalsh(m).min() > 0
    assert np.linalg.eigvalsh(k).min() > 0
    assert np.linalg.eigvalsh(c).min() > -1e-9 * np.abs(c).max()
    mb, _, kb = t.banded_matrices()
    assert mb.shape == (t.n_dof, 5)
    # band[i, k] = A[i, i - k]
    for i, kk in [(10, 0), (10, 3), (57, 4), (t.n_dof - 1, 1)]:
        assert kb[i, kk] == k[i, i - kk]


def dense_element_by_element(t: Track) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """M, C, K of ``t`` as full matrices, assembled the plain way: one element at a time into every entry of its
    4x4 block, then one support at a time."""
    n, lay = t.n_dof, t.dof_layout
    m, c, k = (np.zeros((n, n)) for _ in range(3))
    ke, me = hermite_element_matrices(t.element_length, t.rail_bending_stiffness, t.rail_mass)
    for e in range(t.n_nodes - 1):
        dofs = [lay.node_w[e], lay.node_theta[e], lay.node_w[e + 1], lay.node_theta[e + 1]]
        for a in range(4):
            for b in range(4):
                k[dofs[a], dofs[b]] += ke[a, b]
                m[dofs[a], dofs[b]] += me[a, b]
    for s in range(t.n_sleepers):
        w, d = lay.node_w[lay.sleeper_node[s]], lay.sleeper[s]
        supports = ((k, t.pad_stiffness[s], t.ballast_stiffness[s]), (c, t.pad_damping[s], t.ballast_damping[s]))
        for mat, pad, bal in supports:
            mat[w, w] += pad
            mat[d, d] += pad + bal
            mat[d, w] -= pad
            mat[w, d] -= pad
        m[d, d] += t.sleeper_mass[s]
    return m, c, k


@pytest.mark.parametrize(
    "track",
    [Track.seed(), Track.realistic(30.0).with_voided_sleeper(12, residual_support=0.05),
     Track.seed().scaled(ballast_stiffness=1.3, pad_stiffness=0.7, from_sleeper=20)],
    ids=["seed", "voided", "transition"],
)
def test_banded_assembly_is_the_element_by_element_sum(track):
    """The band storage, assembled for all elements at once, holds exactly (bit for bit) the entries of the
    plain element-by-element assembly, and nothing outside the band."""
    dense = dense_element_by_element(track)
    n = track.n_dof
    for band, full in zip(track.banded_matrices(), dense, strict=True):
        assert band.shape == (n, 5)
        for kk in range(5):
            i = np.arange(kk, n)
            np.testing.assert_array_equal(band[kk:, kk], full[i, i - kk])
            np.testing.assert_array_equal(band[:kk, kk], 0.0)
        i, j = np.nonzero(full)
        assert np.max(np.abs(i - j)) <= 4


def test_rigid_translation_and_total_mass():
    """Moving everything down by 1 m loads only the ballast springs; the kinetic energy of that motion is
    (rail mass + sleeper masses)/2."""
    t = Track.seed().scaled(ballast_stiffness=1.3, from_sleeper=20)
    m, _, k = t.matrices()
    lay = t.dof_layout
    u = np.zeros(t.n_dof)
    u[lay.node_w] = 1.0
    u[lay.sleeper] = 1.0
    f = k @ u
    np.testing.assert_allclose(f[lay.sleeper], t.ballast_stiffness, rtol=1e-12)
    rail = np.concatenate([f[lay.node_w], f[lay.node_theta]])
    np.testing.assert_allclose(rail, 0.0, atol=1e-6)
    assert u @ (m @ u) == pytest.approx(t.rail_mass * t.length + t.sleeper_mass.sum(), rel=1e-12)


# ------------------------------------------------------------------------------------------ statics
@pytest.mark.parametrize("x", [15.0, 15.3], ids=["over-sleeper", "mid-span"])
def test_static_deflection_vs_winkler(x):
    w = static_deflection(Track.seed(), P, x)
    assert w == pytest.approx(SEED_W0, rel=0.05)


def test_static_deflection_over_sleeper_below_mid_span():
    t = Track.seed()
    assert static_deflection(t, P, 15.0) < static_deflection(t, P, 15.3)


def test_static_deflection_linear_in_load():
    t = Track.seed()
    assert static_deflection(t, 2 * P, 15.1) == pytest.approx(2 * static_deflection(t, P, 15.1), rel=1e-12)


@pytest.mark.parametrize("x", [15.0, 15.3, 15.1])
def test_static_deflection_converges_with_mesh(x):
    """Hermite cubic elements are nodally exact for static point loads on a beam whose only foundation is at
    the nodes (the sleepers): between sleepers the exact deflection is a cubic. So at x = 15.0 and 15.3, which
    are nodes of every mesh here, the deflection does not change with the mesh (beyond round-off); at 15.1,
    which is inside an element for every mesh, the changes shrink as the element length halves."""
    w = [static_deflection(Track.seed(elements_per_bay=n), P, x) for n in (2, 4, 8, 16)]
    changes = np.abs(np.diff(w)) / abs(w[-1])
    for prev, nxt in zip(changes[:-1], changes[1:], strict=True):
        assert nxt < prev or max(prev, nxt) < 1e-9
    assert changes[-1] < 1e-3
    assert w[-1] == pytest.approx(SEED_W0, rel=0.05)


def test_static_deflection_bad_input():
    with pytest.raises(ValueError, match="x"):
        static_deflection(Track.seed(), P, 31.0)
    with pytest.raises(ValueError, match="load"):
        static_deflection(Track.seed(), -1.0, 15.0)


# ------------------------------------------------------------------------------------------ receptance
@pytest.mark.parametrize("x", [15.0, 15.3])
def test_receptance_static_limit(x):
    t = Track.seed()
    r = receptance(t, x, np.array([0.1, 1.0]))
    w1 = static_deflection(t, 1.0, x)
    np.testing.assert_allclose(np.abs(r), w1, rtol=0.01)
    assert abs(r[0].imag) < 0.01 * w1


def test_receptance_pinned_pinned_peak():
    t = Track.seed(elements_per_bay=4)
    f = np.arange(800.0, 2000.0 + 1e-9, 2.0)
    r_mid = np.abs(receptance(t, 15.3, f))
    f_peak = f[np.argmax(r_mid)]
    assert f_peak == pytest.approx(SEED_PINNED_PINNED, rel=0.10)
    # over a sleeper the rail is held at that frequency: the mid-span peak stands above it
    r_sleeper = np.abs(receptance(t, 15.0, np.array([f_peak])))[0]
    assert r_mid.max() > 2.0 * r_sleeper


def test_receptance_falls_at_high_frequency():
    t = Track.seed()
    r = np.abs(receptance(t, 15.0, np.array([20.0, 3000.0])))
    assert r[1] < 0.2 * r[0]


def test_receptance_bad_frequencies():
    with pytest.raises(ValueError, match="frequencies"):
        receptance(Track.seed(), 15.0, np.array([-1.0, 10.0]))
