"""Tests of trackenv.physics.vehicle: wheelset, ten-DOF car and trains, their statics, and a car pass."""

from __future__ import annotations

import numpy as np
import pytest

from trackenv.physics.dynamics import simulate_pass
from trackenv.physics.track import Track
from trackenv.physics.vehicle import GRAVITY, Car, Train, Wheelset

CARS = [Car.manchester_coach(), Car.zhai_coach(), Car.freight_wagon()]
car_ids = [c.name for c in CARS]


def assert_symmetric_psd(a: np.ndarray, positive_definite: bool = False) -> None:
    np.testing.assert_allclose(a, a.T, rtol=0, atol=1e-12 * max(np.abs(a).max(), 1.0))
    eig = np.linalg.eigvalsh(a)
    scale = max(np.abs(eig).max(), 1.0)
    if positive_definite:
        assert eig.min() > 0
    else:
        assert eig.min() > -1e-10 * scale


# ------------------------------------------------------------------------------------------ wheelset
def test_wheelset_loads():
    assert Wheelset.seed().wheel_load == pytest.approx(1800 / 2 * 9.81)
    ws = Wheelset(mass=1800.0, static_load=100e3)
    assert ws.wheel_load == pytest.approx(900 * 9.81 + 100e3)
    s = ws.system()
    assert s.n_axles == 1 and s.n_dof == 1 and s.span == 0.0
    assert s.mass[0, 0] == 900.0
    np.testing.assert_allclose(s.static_wheel_loads, [ws.wheel_load])
    np.testing.assert_allclose(s.force, [ws.wheel_load])


def test_wheelset_carrying():
    ws = Wheelset.carrying(32_000.0, 2615.0)
    assert ws.static_load == pytest.approx((16_000.0 + 2615.0) * GRAVITY / 2)


def test_wheelset_bad_input():
    with pytest.raises(ValueError, match="mass"):
        Wheelset(mass=-1.0)
    with pytest.raises(ValueError, match="static_load"):
        Wheelset(static_load=float("nan"))


# ------------------------------------------------------------------------------------------ car
@pytest.mark.parametrize("car", CARS, ids=car_ids)
def test_car_static_wheel_loads(car):
    s = car.system()
    total = (car.body_mass + 2 * car.bogie_mass + 4 * car.wheelset_mass) * GRAVITY
    loads = s.static_wheel_loads
    assert loads.shape == (4,)
    assert loads.sum() == pytest.approx(total / 2, rel=1e-12)  # one rail carries half the car
    np.testing.assert_allclose(loads, total / 8, rtol=1e-12)  # a symmetric car loads its wheels equally
    assert car.wheel_load == pytest.approx(total / 8, rel=1e-12)


@pytest.mark.parametrize("car", CARS, ids=car_ids)
def test_car_matrices(car):
    s = car.system()
    assert s.mass.shape == s.damping.shape == s.stiffness.shape == (10, 10)
    assert_symmetric_psd(s.mass, positive_definite=True)
    assert_symmetric_psd(s.damping)
    assert_symmetric_psd(s.stiffness)
    # with the wheels held, the suspension holds the car: the free block is positive definite
    free = np.setdiff1d(np.arange(10), s.wheel_dofs)
    assert_symmetric_psd(s.stiffness[np.ix_(free, free)], positive_definite=True)
    # a rigid heave of the whole car stretches no spring
    np.testing.assert_allclose(s.stiffness @ np.array([1, 0, 1, 0, 1, 0, 1, 1, 1, 1.0]), 0.0, atol=1e-6)
    np.testing.assert_allclose(
        np.sum(s.force),
        (car.body_mass + 2 * car.bogie_mass + 4 * car.wheelset_mass) * GRAVITY / 2,
        rtol=1e-12,
    )


@pytest.mark.parametrize("car", CARS, ids=car_ids)
def test_car_axle_offsets(car):
    s = car.system()
    a, b = car.bogie_wheelbase, car.bogie_centre_distance
    np.testing.assert_allclose(s.axle_offsets, [0.0, a, b, a + b])
    assert s.span == pytest.approx(a + b)


@pytest.mark.parametrize("car", CARS, ids=car_ids)
def test_car_static_displacements(car):
    """In static equilibrium on level wheels the body sags by the two spring deflections in series."""
    s = car.system()
    q = s.static_displacements(np.zeros(4))
    np.testing.assert_allclose(q[s.wheel_dofs], 0.0)
    m_body_half, m_bogie_half = car.body_mass / 2, car.bogie_mass / 2
    sec = m_body_half * GRAVITY / 2 / car.secondary_stiffness  # per bogie side spring
    prim = (m_body_half / 2 + m_bogie_half) * GRAVITY / 2 / car.primary_stiffness
    assert q[2] == pytest.approx(prim, rel=1e-10)
    assert q[4] == pytest.approx(prim, rel=1e-10)
    assert q[0] == pytest.approx(prim + sec, rel=1e-10)
    np.testing.assert_allclose(q[[1, 3, 5]], 0.0, atol=1e-12)
    # the reactions at the wheels are the static wheel loads
    reactions = s.force[s.wheel_dofs] - s.stiffness[s.wheel_dofs] @ q
    np.testing.assert_allclose(reactions, s.static_wheel_loads, rtol=1e-10)
    # lifting all wheels by 1 mm lifts the whole car rigidly
    q1 = s.static_displacements(np.full(4, -1e-3))
    np.testing.assert_allclose(
        q1 - q, np.array([-1e-3, 0, -1e-3, 0, -1e-3, 0, -1e-3, -1e-3, -1e-3, -1e-3]), atol=1e-12
    )


def test_car_bad_input():
    with pytest.raises(ValueError, match="bogie_centre_distance"):
        Car(32_000.0, 1.97e6, 2615.0, 1476.0, 1813.0, 1.2e6, 4e3, 0.43e6, 20e3, 2.56, 2.0, 24.5)
    with pytest.raises(ValueError, match="body_mass"):
        Car(-1.0, 1.97e6, 2615.0, 1476.0, 1813.0, 1.2e6, 4e3, 0.43e6, 20e3, 2.56, 19.0, 24.5)
    with pytest.raises(ValueError, match="primary_stiffness"):
        Car(32_000.0, 1.97e6, 2615.0, 1476.0, 1813.0, float("nan"), 4e3, 0.43e6, 20e3, 2.56, 19.0, 24.5)


# ------------------------------------------------------------------------------------------ train
def test_train_axle_offsets_increase():
    car = Car.manchester_coach()
    s = Train.of(car, 3).system()
    assert s.n_axles == 12 and s.n_dof == 30
    assert s.axle_offsets[0] == 0.0
    assert np.all(np.diff(s.axle_offsets) > 0)
    # cars follow each other at their length over buffers
    np.testing.assert_allclose(s.axle_offsets[4:8] - s.axle_offsets[:4], car.length_over_buffers)
    np.testing.assert_allclose(s.axle_offsets[8:] - s.axle_offsets[4:8], car.length_over_buffers)
    np.testing.assert_allclose(s.static_wheel_loads, car.wheel_load, rtol=1e-12)


def test_mixed_train():
    s = Train((Car.manchester_coach(), Car.freight_wagon())).system()
    assert np.all(np.diff(s.axle_offsets) > 0)
    np.testing.assert_allclose(s.static_wheel_loads[:4], Car.manchester_coach().wheel_load, rtol=1e-12)
    np.testing.assert_allclose(s.static_wheel_loads[4:], Car.freight_wagon().wheel_load, rtol=1e-12)
    assert_symmetric_psd(s.stiffness)


def test_train_bad_input():
    with pytest.raises(ValueError, match="n_cars"):
        Train.of(Car.manchester_coach(), 0)
    with pytest.raises(ValueError, match="cars"):
        Train(())


# ------------------------------------------------------------------------------------------ car pass
def test_car_pass_on_realistic_track():
    car = Car.manchester_coach()
    res = simulate_pass(Track.realistic(120.0), car, 100 / 3.6)
    n = res.time.size
    central = res.contact_force[n // 4 : 3 * n // 4]
    assert np.all(np.isfinite(res.contact_force))
    assert res.contact_force.shape == (n, 4)
    np.testing.assert_allclose(central.mean(axis=0), car.wheel_load, rtol=0.02)
    np.testing.assert_allclose(res.contact_force[0], res.static_wheel_load, rtol=1e-9)
    # axles run one behind the other at the car's offsets
    np.testing.assert_allclose(
        res.wheel_position[:, 0, None] - res.wheel_position,
        car.system().axle_offsets[None, :] * np.ones((n, 1)),
        atol=1e-9,
    )
