"""TampingNetwork: several lines that share one tamping machine (``trackenv/TampingNetwork-v0``).

:class:`TampingNetwork` (one network) and :class:`TampingNetworkVectorEnv` (many, every segment of every line
of every network in one batched pass per vehicle type) are :class:`~trackenv.envs.env.TrackEnv` and
:class:`~trackenv.envs.env.TrackVectorEnv` over the network's engine
(:class:`~trackenv.envs.network.NetworkBatch`, whose lines are rows of the line's engine); the configuration and
the rules of the shared machine are in :mod:`trackenv.envs.network`.
"""

from __future__ import annotations

from functools import partial
from typing import Any

from gymnasium.vector import AutoresetMode, VectorEnv

from .env import TrackEnv, TrackVectorEnv
from .network import NetworkBatch, NetworkConfig
from .sharded import native_or_sharded

__all__ = ["TampingNetwork", "TampingNetworkVectorEnv", "network_vector_env"]


def network_config(config: NetworkConfig | dict | None, overrides: dict[str, Any]) -> NetworkConfig:
    """The config of a TampingNetwork env from its arguments (:meth:`NetworkConfig.coerce`; ``max_episode_steps``,
    which ``gym.make`` may pass, is dropped: the env truncates itself at its horizon)."""
    overrides.pop("max_episode_steps", None)
    for name, why in _LINE_ENV_ONLY.items():
        if name in overrides:
            raise ValueError(f"{name}: the network takes no {name} ({why}); its own arguments are config, n_lines, "
                             "line_config, capacity, move_cost and start_line, any other a field of the line config")
    return NetworkConfig.coerce(config, **overrides)


#: TampingLine's arguments that the network does not take, each with why (a line config would refuse them less
#: clearly: as unknown keys of its lines)
_LINE_ENV_ONLY = {
    "action_type": "its action is MultiBinary, one request per section of every line",
    "scenario": "its lines are given by line_config: a preset name, a dict, a line file, or a list of them",
}


class TampingNetwork(TrackEnv):
    """Plan tamping of a network of lines that share one tamping machine: which line the machine works on, and
    which of its sections it tamps, step by step.

    **Description.** ``n_lines`` lines (default 3), each a TampingLine of the same line config (default: the
    12-section default line; :class:`~trackenv.envs.line.TampingLine` has the physics) or of its own (a list of
    line configs: presets, dicts, line files), each with its own draws (traffic field, register, rates, hidden
    wet spots). One machine serves them all: it is on one line at
    a time, tamps at most ``capacity`` sections per step there (the line's capacity by default), and moving to
    another line takes a step and costs ``move_cost``. Every line carries its traffic and degrades every step.

    **Action space.** ``MultiBinary(n_lines · n_sections)``: line ``l``'s section ``j`` is entry
    ``l · n_sections + j`` (on lines of their own ``MultiBinary(Σ sections)``, line ``l``'s section ``j`` at
    ``config.line_offsets[l] + j``). The requests are counted per line (masked sections left out); the machine's
    destination is the line with the most requests (a tie with the machine's line keeps it there; between other
    lines, the lowest index). On its own line the machine works the requests as a TampingLine does (over
    ``capacity``, the worst measured SD kept and ``info["clipped"]`` True); requests on other lines are dropped.
    If the destination is another line the machine moves there: nothing is tamped this step, ``move_cost`` is
    paid, and it works there from the next step if asked again. ``info["dropped_requests"]`` counts per line
    the unmasked requests not tamped (moving, another line's, or clipped). **Masks** (:meth:`action_masks`,
    sb3-contrib's pairs): each line's own mask on every line (a section tamped within
    ``min_steps_between_tampings`` steps is masked). On the machine's line an unmasked section may be tamped;
    on another line, asking for it votes to move there (and it may be tamped once the machine is there).

    **Observation** (``Dict``, float32): every key of TampingLine's observation stacked over the lines, with the
    line's bounds (the widest of the lines'): per-section keys (``section_sd``, ``register``, ...) (Σ sections,) in
    the action's order; per-line keys (``measurement_age``, ``budget_left``) (n_lines,); ``time`` (1,), shared; and
    ``machine_line`` (n_lines,), the machine's line one-hot.

    **Reward.** −(Σ over the lines of their step costs + the move cost), k€. ``info["costs"]``: each of the
    line's cost parts summed over the lines, and ``move``; ``info["line_costs"]`` (n_lines,) each line's cost
    and ``info["line_cost_parts"]`` per part and line; ``info["machine_line"]`` (after the step) and
    ``info["moved"]``; the lines' per-section info keys concatenated (Σ sections,).

    **Episode end.** Truncation at the lines' horizon (default 10 years = 40 steps); ``step`` after it raises
    until ``reset``; the machine starts every episode on ``start_line``.

    **Vector env.** ``gym.make_vec("trackenv/TampingNetwork-v0", num_envs=n,
    vectorization_mode="vector_entry_point")`` builds :class:`TampingNetworkVectorEnv` (``workers=N`` for the
    same networks in N processes), with the conventions of every native vector env of trackenv
    (:mod:`trackenv.envs.batched`); network ``i`` gives bit for bit what this env gives for the same seed.

    **Arguments.** ``config`` (:class:`~trackenv.envs.network.NetworkConfig` or a dict), or its fields as keywords
    (``n_lines``, ``line_config``: a LineConfig, dict or preset name, or a list of them one per line,
    ``capacity``, ``move_cost``,
    ``start_line``); any other keyword is a field of the line config (``horizon_years=1.0``).
    ``render_mode="rgb_array"`` draws the machine's line. **Randomness**: each line is drawn at reset from a
    generator seeded from the env's (:func:`~trackenv.envs.network.line_seeds`); ``get_state``/``set_state``
    snapshot the network (every line and the machine).

    **Versions.** v0: first release.
    """

    def __init__(self, config: NetworkConfig | dict | None = None, *, render_mode: str | None = None,
                 **overrides: Any) -> None:
        super().__init__(network_config(config, overrides), action_type="multibinary", render_mode=render_mode)

    @property
    def batch(self) -> NetworkBatch | None:
        """The engine (:class:`~trackenv.envs.network.NetworkBatch` of this one network), or None before the first
        reset."""
        return self.engine


class TampingNetworkVectorEnv(TrackVectorEnv):
    """``num_envs`` TampingNetwork episodes (same config), stepped together: every line of every network a row
    of one line engine. See :class:`TampingNetwork` for the spec; the Gymnasium conventions are those of every
    native vector env of trackenv (:mod:`trackenv.envs.batched`)."""

    def __init__(self, num_envs: int = 2, config: NetworkConfig | dict | None = None, *,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP,
                 render_mode: str | None = None, **overrides: Any) -> None:
        super().__init__(num_envs, network_config(config, overrides), action_type="multibinary",
                         autoreset_mode=autoreset_mode, render_mode=render_mode)

    @property
    def batch(self) -> NetworkBatch | None:
        """The engine (:class:`~trackenv.envs.network.NetworkBatch`), or None before the first reset."""
        return self.engine


def network_vector_env(num_envs: int = 2, *, workers: int = 1, **kwargs: Any) -> VectorEnv:
    """The vector entry point of ``trackenv/TampingNetwork-v0``: :class:`TampingNetworkVectorEnv`, or with
    ``workers`` > 1 the same networks in that many processes
    (:class:`~trackenv.envs.sharded.ShardedVectorEnv`)."""
    return native_or_sharded(partial(TampingNetworkVectorEnv, **kwargs), num_envs, workers)
