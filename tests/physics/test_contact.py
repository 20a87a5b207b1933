"""Tests of trackenv.physics.contact: the Hertz and linear wheel/rail contact laws."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackenv.physics.contact import HertzContact, LinearContact, zhai_contact_constant

LAWS = [HertzContact(), HertzContact(G=4.22e-8), LinearContact(), LinearContact(k=5e8)]
PROPERTY = settings(max_examples=50, deadline=None)


def test_hertz_linearised_stiffness_at_117kN():
    # dF/dδ = 1.5 F^{1/3} / G for F = (δ/G)^{3/2}: the paper's 1.43e9 N/m at 117 kN
    assert float(HertzContact().stiffness(117e3)) == pytest.approx(1.43e9, rel=0.005)


def test_hertz_stiffness_is_the_derivative():
    law = HertzContact()
    for f0 in (1e3, 50e3, 117e3, 300e3):
        d0 = float(law.compression(f0))
        h = 1e-6 * d0
        fd = (float(law.force(d0 + h)) - float(law.force(d0 - h))) / (2 * h)
        assert float(law.stiffness(f0)) == pytest.approx(fd, rel=1e-6)


def test_zhai_constants_for_a_046m_wheel():
    # Zhai's fits: conical 4.57 R^-0.149 1e-8, worn 3.86 R^-0.115 1e-8 (the published 5.13e-8 and 4.22e-8)
    assert zhai_contact_constant(0.46, "conical") == pytest.approx(5.13e-8, rel=0.01)
    assert zhai_contact_constant(0.46, "worn") == pytest.approx(4.22e-8, rel=0.01)
    assert HertzContact().G == pytest.approx(zhai_contact_constant(0.46, "conical"), rel=0.01)


def test_from_linear_stiffness_round_trip():
    law = HertzContact.from_linear_stiffness(2e9, reference_load=80e3)
    assert float(law.stiffness(80e3)) == pytest.approx(2e9, rel=1e-12)
    assert HertzContact.from_linear_stiffness().G == pytest.approx(HertzContact().G, rel=1e-12)


@pytest.mark.parametrize("law", LAWS, ids=lambda law: type(law).__name__)
def test_no_force_without_compression(law):
    d = np.array([-1e-3, -1e-9, 0.0])
    np.testing.assert_array_equal(law.force(d), 0.0)
    assert float(law.force(1e-6)) > 0.0


@pytest.mark.parametrize("law", LAWS, ids=lambda law: type(law).__name__)
def test_force_monotone(law):
    d = np.linspace(-1e-4, 5e-4, 101)
    assert np.all(np.diff(law.force(d)) >= 0.0)
    assert np.all(np.diff(law.force(d[d > 0])) > 0.0)


@PROPERTY
@given(f=st.floats(min_value=0.0, max_value=1e6, allow_nan=False))
def test_compression_inverts_force(f):
    for law in LAWS:
        assert float(law.force(law.compression(f))) == pytest.approx(f, rel=1e-12, abs=1e-9)


@PROPERTY
@given(d=st.floats(min_value=1e-9, max_value=1e-3, allow_nan=False))
def test_force_inverts_compression(d):
    for law in LAWS:
        assert float(law.compression(law.force(d))) == pytest.approx(d, rel=1e-12)


def test_hertz_closed_form():
    g = 5e-8
    law = HertzContact(G=g)
    d = 1e-4
    assert float(law.force(d)) == pytest.approx((d / g) ** 1.5, rel=1e-14)
    assert float(law.compression(117e3)) == pytest.approx(g * 117e3 ** (2 / 3), rel=1e-14)


def test_linear_closed_form():
    law = LinearContact(1.43e9)
    assert float(law.force(1e-4)) == pytest.approx(1.43e5, rel=1e-14)
    np.testing.assert_array_equal(law.stiffness(np.array([1.0, 2.0])), 1.43e9)


def test_vectorised():
    law = HertzContact()
    d = np.array([[0.0, 1e-5], [5e-5, -1e-5]])
    assert law.force(d).shape == (2, 2)
    assert law.compression(np.ones(3)).shape == (3,)


def test_bad_input_names_the_parameter():
    with pytest.raises(ValueError, match="G"):
        HertzContact(G=-1.0)
    with pytest.raises(ValueError, match="G"):
        HertzContact(G=float("nan"))
    with pytest.raises(ValueError, match="k"):
        LinearContact(k=0.0)
    with pytest.raises(ValueError, match="wheel_radius"):
        zhai_contact_constant(-0.46)
    with pytest.raises(ValueError, match="tread"):
        zhai_contact_constant(0.46, "new")
    with pytest.raises(ValueError, match="stiffness"):
        HertzContact.from_linear_stiffness(-1.0)
