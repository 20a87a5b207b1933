"""The multi-agent entry point: :func:`line_parallel_env` poses a TampingLine env as a PettingZoo ``ParallelEnv``
with one agent per section (:class:`~trackenv.envs.parallel.LineParallelEnv` has the spec).

PettingZoo is an optional dependency (the ``multiagent`` extra): this module imports it only when it is called,
so ``import trackenv`` works without it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import gymnasium as gym

if TYPE_CHECKING:
    from .parallel import LineParallelEnv

__all__ = ["MISSING_PETTINGZOO", "line_parallel_env"]

MISSING_PETTINGZOO = 'line_parallel_env needs PettingZoo: pip install "trackenv[multiagent]"'


def line_parallel_env(env_id: str = "trackenv/TampingLine-v0", **kwargs: Any) -> LineParallelEnv:
    """A PettingZoo ``ParallelEnv`` over ``gym.make(env_id, **kwargs)``: one agent per section of the line
    (``"section_0"``, ...), each observing its section and the line context, acting wait (0) or tamp (1) (on the
    ids with the choices, its section's choice code, ``Discrete(7)``), and rewarded with its section's own costs
    plus an equal share of the possession of the steps it gets track work in
    (:class:`~trackenv.envs.parallel.LineParallelEnv`).

    ``env_id`` is any id whose env is a TampingLine (``trackenv/TampingLine-v0``, ``trackenv/TampingLineSmall-v0``,
    ``trackenv/TampingLine-v1``, ``trackenv/TampingLineWet-v0``, ...); ``kwargs`` go to ``gym.make`` (a config,
    a scenario name, ``LineConfig`` fields, ``render_mode``). ImportError naming the extra if PettingZoo is not
    installed; ValueError if the env is not a line env."""
    try:
        import pettingzoo  # noqa: F401  (the optional dependency, checked before the env is built)
    except ImportError:
        raise ImportError(MISSING_PETTINGZOO) from None
    from .parallel import LineParallelEnv

    env = gym.make(env_id, **kwargs)
    try:
        return LineParallelEnv(env)
    except ValueError:
        env.close()
        raise
