"""OpenMP threads that sleep, not spin, while they wait for work: ``OMP_WAIT_POLICY=PASSIVE`` unless the user set it.

numba's parallel kernels (the batched pass, the implicit settlement step) and torch run their threads on GNU
OpenMP, whose idle threads spin by default between parallel regions. On a machine whose cores are busy with
other work (a second process, a test run, Ray workers) the spinning threads take the cores the working threads
need, and each parallel region waits for a thread the scheduler has put aside: a line step then takes about 1.4
times as long, a small torch training step ten times. On an idle machine sleeping threads cost only their
wake-up at each parallel region, about 2 % of a step (the measurements: docs, Performance). The setting is read
when an OpenMP runtime loads, so it is made before numba or torch start one; a value already in the environment
is kept.
"""

from __future__ import annotations

import os

WAIT_POLICY = "PASSIVE"


def prefer_passive_wait() -> None:
    """Set ``OMP_WAIT_POLICY`` to :data:`WAIT_POLICY` unless the environment already sets it."""
    os.environ.setdefault("OMP_WAIT_POLICY", WAIT_POLICY)
