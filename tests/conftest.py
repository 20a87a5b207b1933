"""Fixtures shared across the test suite."""

from __future__ import annotations

import pytest

from trackenv.envs.config import TampingEnvConfig


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
