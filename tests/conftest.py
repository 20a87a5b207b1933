"""Shared test fixtures."""

from __future__ import annotations

import pytest

from trackenv.envs.line_config import LineConfig, scenario


# --- numba: compile (or load) the kernel once, before the first test ---
@pytest.fixture(scope="session", autouse=True)
def warm_dynamics_kernel():
    """Load (or, on a fresh machine, compile) every entry of the dynamics kernel once per session, before the
    first test, so that its compile cost lands here once instead of inside whichever test happens to run first.
    Each (serial/parallel, batch width) pair is its own compiled entry (see trackenv.physics._kernel) and the
    suite uses them all; cold, their compilation is most of the suite's time, so the widths compile in worker
    processes at once, one per usable core (as ``trackenv compile`` does), and this one then loads them from
    numba's cache."""
    from trackenv.physics.kernels import compile_kernels, usable_cores

    compile_kernels(load=True, jobs=usable_cores())
    # the compiled inverse of the root-solved settlement laws (trackenv.physics._implicit), one entry
    from trackenv.physics.settlement import SatoLaw

    SatoLaw().equivalent_cycles(5e4, 1e-3)


# --- the small problem most tests of the env and the agents run on ---
@pytest.fixture(scope="session")
def small_config() -> LineConfig:
    """The 60 m track's preset cut to 30 m (51 sleepers) in 3 sections of 10 m over 2 years of quarters
    (8 steps), default physics."""
    return scenario("track60", n_sections=3, segment_length_m=30.0, sections_per_segment=3, capacity=3,
                    horizon_years=2.0)


@pytest.fixture(scope="session")
def small_coarse_config(small_config: LineConfig) -> LineConfig:
    """:func:`small_config` with a time step of 2e-4 s (twice the default): half the cost of each pass, for
    tests of the agents rather than of the physics."""
    return small_config.replace(dt=2e-4)
