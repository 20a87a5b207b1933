"""OpenMP threads that sleep, not spin, while they wait for work: ``OMP_WAIT_POLICY=PASSIVE`` unless the user set it.

numba's parallel kernels (the batched pass, the implicit settlement step) and torch run their threads on GNU
OpenMP, whose idle threads spin by default between parallel regions. On a machine whose cores are busy with
other work (a second process, a test run, Ray workers) the spinning threads take the cores the working threads
need, and each parallel region waits for a thread the scheduler has put aside. Measured on the 2-core
development machine with another process busy on both cores: a `TampingLine-v0` step took 67 ms with spinning
threads and 46 ms with sleeping ones (the implicit settlement step alone 12 ms against 1.2), and a small torch
training step 12-14 ms against 1.1. On an idle machine a region wakes its sleeping threads in microseconds, a
few per step. The setting is read when an OpenMP runtime loads, so it is made before numba or torch start one;
a value already in the environment is kept.
"""

from __future__ import annotations

import os

WAIT_POLICY = "PASSIVE"


def prefer_passive_wait() -> None:
    """Set ``OMP_WAIT_POLICY`` to :data:`WAIT_POLICY` unless the environment already sets it."""
    os.environ.setdefault("OMP_WAIT_POLICY", WAIT_POLICY)
