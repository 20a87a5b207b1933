"""The torch backend of the pass (trackenv.physics.torch_pass) against the numba kernel, on torch's CPU device.

Both run the same algorithm in float64; only the window's linear algebra is done differently (dense batched
Cholesky and inverse instead of banded sweeps), so results agree to rounding carried through the pass: measured
≤ 6e-12 of the largest value on these cases. The tolerance, 1e-9 of a row's largest peak, is two orders of
magnitude above that and five below the physics tolerances (0.5 % for dt, 1 % for the window)."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from trackenv.physics.dynamics import simulate_passes
from trackenv.physics.track import Track
from trackenv.physics.vehicle import Car, Wheelset

torch = pytest.importorskip("torch", reason="the torch backend needs torch (the 'rl' extra)")
from trackenv.physics import torch_pass  # noqa: E402  (after the skip: it imports torch)

RTOL = 1e-9
LOADED = Wheelset(mass=1800.0, static_load=100e3)
TRACK = Track.realistic(36.0)  # long enough for the windows to move (7 bays either side of the axle)


def dip(x, x0=15.0, depth=5e-3, length=1.0):
    """A 1 m cosine dip of ``depth`` [m] (downward positive): a loaded wheel leaves the rail at 120 km/h."""
    s = (np.asarray(x, dtype=float) - x0) / length
    return np.where((s >= 0) & (s <= 1), 0.5 * depth * (1 - np.cos(2 * np.pi * s)), 0.0)


ROUGH = 2e-4 * np.sin(np.arange(TRACK.n_sleepers) * 0.9)
# name: (tracks, vehicle, speed [m/s], irregularities, options)
CASES = {
    "plain_stiff_soft_pads": ([TRACK, TRACK.replace(pad_stiffness=np.full(TRACK.n_sleepers, 1e9)),
                               TRACK.replace(pad_stiffness=np.full(TRACK.n_sleepers, 6e7))], LOADED, 30.0, ROUGH,
                              dict(x_start=12.0, x_end=16.0, dt=2e-4)),
    "voided_sleeper": (TRACK.with_voided_sleeper(24), LOADED, 30.0, ROUGH, dict(x_start=12.0, x_end=16.0, dt=2e-4)),
    "loses_contact": (TRACK, LOADED, 120 / 3.6, dip, dict(x_start=13.0, x_end=17.0, on_overload="ignore")),
    "car_settled_supports": (Track.realistic(30.0), Car.freight_wagon(), 100 / 3.6, None,
                             dict(dt=4e-4, support_settlement=np.linspace(0.0, 2e-3, 51))),
    "steady_start": (TRACK, LOADED, 30.0, ROUGH, dict(start="steady", x_end=9.0, dt=2e-4)),
}


def assert_same_passes(got, want) -> None:
    """Per-sleeper peaks, contact force histories and lost-contact steps of each row alike."""
    for g, w in zip(got, want, strict=True):
        for field in ("ballast_force", "pad_plus_ballast_force", "contact_force", "rail_displacement",
                      "wheel_displacement", "irregularity"):
            a, b = getattr(g, field), getattr(w, field)
            np.testing.assert_allclose(a, b, rtol=0, atol=RTOL * np.abs(b).max(), err_msg=field)
        np.testing.assert_array_equal(g.contact_force == 0.0, w.contact_force == 0.0)
        assert g.max_contact_force == pytest.approx(w.max_contact_force, rel=RTOL)


@pytest.mark.parametrize("name", CASES)
def test_torch_backend_matches_the_kernel(name):
    tracks, vehicle, speed, irregularity, options = CASES[name]
    want = simulate_passes(tracks, vehicle, speed, irregularity, **options)
    got = simulate_passes(tracks, vehicle, speed, irregularity, backend="torch", device="cpu", **options)
    if name == "loses_contact":
        assert np.any(want[0].contact_force == 0.0)  # the case does what it is there for
    assert_same_passes(got, want)


def test_cholesky_solves_match_the_inverse(monkeypatch):
    tracks, vehicle, speed, irregularity, options = CASES["voided_sleeper"]
    want = simulate_passes(tracks, vehicle, speed, irregularity, backend="torch", **options)
    monkeypatch.setattr(torch_pass, "run", functools.partial(torch_pass.run, solver="cholesky"))
    got = simulate_passes(tracks, vehicle, speed, irregularity, backend="torch", **options)
    assert_same_passes(got, want)


def test_bad_backend_device_or_solver():
    with pytest.raises(ValueError, match="backend"):
        simulate_passes(TRACK, LOADED, 30.0, backend="cuda")
    with pytest.raises(ValueError, match="device"):
        simulate_passes(TRACK, LOADED, 30.0, backend="torch", device="no-such-device")
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="CUDA"):
            simulate_passes(TRACK, LOADED, 30.0, backend="torch", device="cuda")
    with pytest.raises(ValueError, match="solver"):
        torch_pass.integrate(None, None, {"u": torch.zeros(1)}, solver="lu")
