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
    suite uses them all; cold, their compilation is most of the suite's time, so a second process compiles the
    entries of the chunks of 6 to 16 rows while this one compiles those of one and four rows (they share numba's
    on-disk cache; the two entries of a width share their chunk integrator, so a width is compiled in one
    process), then this one loads them."""
    import subprocess
    import sys

    from trackenv.physics.dynamics import KERNEL_ENTRIES, warm_kernel

    wide = [e for e in KERNEL_ENTRIES if e[1] >= 6]  # cold: 99 s in all, against 116 s with the 6 rows here
    helper = subprocess.Popen(
        [sys.executable, "-c", f"from trackenv.physics.dynamics import warm_kernel; warm_kernel({wide!r})"]
    )
    try:
        warm_kernel([e for e in KERNEL_ENTRIES if e not in wide])
    finally:
        helper.wait()
    warm_kernel(wide)  # compiled by the helper: loaded from the cache (or compiled here if it failed)
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
