"""Shared test fixtures."""

from __future__ import annotations

import pytest

from trackenv.envs.config import TampingEnvConfig


# --- numba: compile (or load) the kernel once, before the first test ---
@pytest.fixture(scope="session", autouse=True)
def warm_dynamics_kernel():
    """Load (or, on a fresh machine, compile) the dynamics kernel once per session, before the first test, so
    its compile cost lands here once instead of inside whichever test happens to run first. Each batch width is
    its own compiled entry (see trackenv.physics._kernel), so a batch of one and a batch of two (one row per
    thread) are warmed; wider batches load their entries from numba's on-disk cache when first used."""
    import numpy as np

    from trackenv.physics.dynamics import simulate_passes
    from trackenv.physics.track import Track
    from trackenv.physics.vehicle import Wheelset

    track, wheel = Track.seed(), Wheelset.seed()
    for rows in (1, 2):
        simulate_passes(track, wheel, 20.0, np.zeros((rows, track.n_sleepers)), x_start=10.0, x_end=10.5)
    # the compiled inverse of the root-solved settlement laws (trackenv.physics._newton), one entry
    from trackenv.physics.settlement import SatoLaw

    SatoLaw().equivalent_cycles(5e4, 1e-3)


# --- the small problem most tests of the env and the agents run on ---
@pytest.fixture(scope="session")
def small_config() -> TampingEnvConfig:
    """30 m of track (51 sleepers) in 3 sections over 2 years of quarters (8 steps), default physics."""
    return TampingEnvConfig(track_length_m=30.0, n_sections=3, horizon_years=2.0)


@pytest.fixture(scope="session")
def small_coarse_config(small_config: TampingEnvConfig) -> TampingEnvConfig:
    """:func:`small_config` with a time step of 2e-4 s (twice the default): half the cost of each pass, for
    tests of the agents rather than of the physics."""
    return small_config.replace(dt=2e-4)
