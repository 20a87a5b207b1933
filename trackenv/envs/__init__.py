"""Gymnasium environments of trackenv, registered on import (safe to import twice).

No ``max_episode_steps``: the env truncates itself at its configured horizon, so a registered TimeLimit could
only cut a longer configured horizon short (``gym.make(..., horizon_years=20)`` runs its 80 steps).

Every id is the one environment (:class:`~trackenv.envs.line.TampingLine` over the one engine) with a preset of
:class:`~trackenv.envs.line_config.LineConfig`: the line problem (:mod:`trackenv.envs.line`),
``trackenv/TampingLine-v0`` (the default line), ``trackenv/TampingLineSmall-v0`` (tests, quick studies),
``trackenv/TampingLineHard-v0`` and ``trackenv/TampingLineLong-v0`` (50 km); with every choice of a track
manager (``action_type="choices"``: :mod:`trackenv.envs.choices`), ``trackenv/TampingLine-v1`` (the default
line), ``trackenv/TampingLineWet-v0`` (a wet, poorly drained line) and ``trackenv/TampingLineDefects-v0`` (many
short defects); the 60 m track
(:mod:`trackenv.envs.tamping`), ``trackenv/Tamping-v1`` (MultiBinary actions), ``trackenv/TampingDiscrete-v1``
(one section or none per step), and for learners
(:mod:`trackenv.envs.wrappers`) ``trackenv/TampingRanked-v1`` (``Discrete(n_sections + 1)`` ranked actions,
section-level Dict observation) and ``trackenv/TampingRankedFlat-v1`` (the same with one flat ``Box``
observation: RLlib's and CleanRL's default encoders). Each has a native vector entry point
(``gym.make_vec(..., vectorization_mode="vector_entry_point")``; add ``workers=N`` for the same envs in N
processes, :class:`~trackenv.envs.sharded.ShardedVectorEnv`).
``trackenv/TampingNetwork-v0`` (:mod:`trackenv.envs.network_env`) is a network of lines that share one tamping
machine, its lines rows of the same engine (:mod:`trackenv.envs.network`).
The line ids take a line file (``line="my_line.yaml"``: :mod:`trackenv.envs.line_file`; the example in
:mod:`trackenv.lines`).
:func:`~trackenv.envs.multiagent.line_parallel_env` poses any of them as a PettingZoo ``ParallelEnv`` with one
agent per section (the ``multiagent`` extra).

Every env has the planning state API (:mod:`trackenv.envs.state`): ``get_state()`` / ``set_state(state)``, and
per row on the native vector envs.
"""

import warnings

from gymnasium.envs.registration import register, registry

from .line import TampingLine, TampingLineVectorEnv
from .line_config import SCENARIOS, LineConfig, scenario
from .line_file import LineDescription, LineFileError, load_line
from .line_fit import history_fit
from .multiagent import line_parallel_env
from .network import NetworkConfig
from .network_env import TampingNetwork, TampingNetworkVectorEnv
from .network_file import NetworkDescription, load_network
from .problems import make_vector_env, problem_config
from .state import EnvState
from .tamping import TampingEnv
from .vector import TampingVectorEnv

_ENVS: tuple[tuple[str, str, str, dict], ...] = (
    ("trackenv/TampingLine-v0", "trackenv.envs.line:TampingLine", "trackenv.envs.sharded:line_vector_env",
     {"scenario": "default"}),
    ("trackenv/TampingLineSmall-v0", "trackenv.envs.line:TampingLine", "trackenv.envs.sharded:line_vector_env",
     {"scenario": "small"}),
    ("trackenv/TampingLineLong-v0", "trackenv.envs.line:TampingLine", "trackenv.envs.sharded:line_vector_env",
     {"scenario": "long"}),
    ("trackenv/TampingLineHard-v0", "trackenv.envs.line:TampingLine", "trackenv.envs.sharded:line_vector_env",
     {"scenario": "hard"}),
    ("trackenv/TampingLine-v1", "trackenv.envs.line:TampingLine", "trackenv.envs.sharded:line_vector_env",
     {"scenario": "choices", "action_type": "choices"}),
    ("trackenv/TampingLineWet-v0", "trackenv.envs.line:TampingLine", "trackenv.envs.sharded:line_vector_env",
     {"scenario": "wet", "action_type": "choices"}),
    ("trackenv/TampingLineDefects-v0", "trackenv.envs.line:TampingLine", "trackenv.envs.sharded:line_vector_env",
     {"scenario": "defects", "action_type": "choices"}),
    ("trackenv/TampingNetwork-v0", "trackenv.envs.network_env:TampingNetwork",
     "trackenv.envs.network_env:network_vector_env", {}),
    ("trackenv/Tamping-v1", "trackenv.envs.tamping:TampingEnv", "trackenv.envs.sharded:tamping_vector_env",
     {"action_type": "multibinary"}),
    ("trackenv/TampingDiscrete-v1", "trackenv.envs.tamping:TampingEnv", "trackenv.envs.sharded:tamping_vector_env",
     {"action_type": "discrete"}),
    ("trackenv/TampingRanked-v1", "trackenv.envs.wrappers:make_ranked", "trackenv.envs.wrappers:make_ranked_vector",
     {"env_id": "trackenv/Tamping-v1"}),
    ("trackenv/TampingRankedFlat-v1", "trackenv.envs.wrappers:make_ranked",
     "trackenv.envs.wrappers:make_ranked_vector", {"env_id": "trackenv/Tamping-v1", "flat": True}),
)
for _id, _entry, _vector_entry, _kwargs in _ENVS:
    if _id not in registry:
        register(id=_id, entry_point=_entry, kwargs=_kwargs, vector_entry_point=_vector_entry)

#: ids whose name has a higher version registered that is another problem, not a replacement: the default line
#: with tamping only (v0, the benchmark's) and with every choice of a track manager (v1). Gymnasium's ``make``
#: tells the user of any id with a higher version to "upgrade"; for these that advice is wrong, so that one
#: deprecation message, and only for these ids, is not shown (every other warning, and Gymnasium's message about
#: any other id, is left as it is).
CURRENT_LOWER_VERSIONS = ("trackenv/TampingLine-v0",)
for _id in CURRENT_LOWER_VERSIONS:
    warnings.filterwarnings("ignore", message=rf".*The environment {_id} is out of date\.", category=DeprecationWarning)

__all__ = ["SCENARIOS", "EnvState", "LineConfig", "LineDescription", "LineFileError", "NetworkConfig",
           "NetworkDescription", "TampingEnv", "TampingLine", "TampingLineVectorEnv", "TampingNetwork",
           "TampingNetworkVectorEnv", "TampingVectorEnv", "history_fit", "line_parallel_env", "load_line",
           "load_network", "make_vector_env", "problem_config", "scenario"]
