"""Seeding of the native vector envs: one generator per env, from one seed, a list of seeds, or none."""

from __future__ import annotations

import numpy as np

from ..physics._checks import check_int


def vector_seeds(seed: int | list[int] | np.ndarray | None, num_envs: int) -> list[int | None]:
    """One seed per env for ``reset(seed=...)``: None gives None for every env (fresh entropy); an int ``s``
    seeds env ``i`` with ``s + i`` (Gymnasium's convention); a list (tuple, 1-d array) of ``num_envs`` seeds,
    each non-negative or None, seeds each env with its own."""
    if seed is None:
        return [None] * num_envs
    if isinstance(seed, (list, tuple)) or (isinstance(seed, np.ndarray) and seed.ndim == 1):
        if len(seed) != num_envs:
            raise ValueError(f"seed must be an int or a list of {num_envs} seeds, got {len(seed)}")
        return [None if s is None else check_int("seed", s, low=0) for s in seed]
    return [check_int("seed", seed, low=0) + i for i in range(num_envs)]


def vector_rngs(seed: int | list[int] | np.ndarray | None, num_envs: int,
                current: list[np.random.Generator] | None = None) -> list[np.random.Generator]:
    """One generator per env for ``reset(seed=...)``, from :func:`vector_seeds`; an env whose seed is None keeps
    its generator in ``current`` where it has one (as a single env's ``reset()`` continues its generator), else
    draws fresh entropy."""
    current = current or []
    return [current[i] if s is None and i < len(current) else np.random.default_rng(s)
            for i, s in enumerate(vector_seeds(seed, num_envs))]
