"""PettingZoo's parallel API over a TampingLine env: one agent per section (:class:`LineParallelEnv`).

Needs the ``multiagent`` extra (PettingZoo); build it with :func:`trackenv.envs.multiagent.line_parallel_env`,
which says so when PettingZoo is missing. The class is built only on the line env's public API (``reset``,
``step``, its spaces, its ``info`` and ``action_masks()``), so it follows the env through changes of its engine.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .choices import CHOICES, IS_TRACK_WORK
from .line import TampingLine
from .multiagent import MISSING_PETTINGZOO

try:
    from pettingzoo import ParallelEnv
except ImportError as err:  # reached only when this module is imported directly
    raise ImportError(MISSING_PETTINGZOO) from err

__all__ = ["SHARED_COST_KEYS", "LineParallelEnv", "agent_name", "possession_shares"]

#: The cost parts of the line env's ``info["costs"]`` that belong to the line, not to one section: split among
#: the agents by :func:`possession_shares`; every other part is in ``info["section_costs"]``, section by section.
SHARED_COST_KEYS = ("possession",)


def agent_name(section: int) -> str:
    """The agent of section ``section`` (counted from 0 along the line): ``"section_<i>"``."""
    return f"section_{section}"


def possession_shares(shared_cost: float, worked: np.ndarray) -> np.ndarray:
    """(n_sections,) each section's share of the step's ``shared_cost`` (k€): equal shares among the sections
    ``worked`` on in the step's possession (tamped; with the choices, any track work: tamp, spot tamp,
    drainage, renewal), nothing for the others (equal shares among all sections if none was, so that the shares
    always add up to ``shared_cost``; the line env has no possession then).

    Why equal shares: the possession is a fixed cost that any step with track work incurs in full whatever its
    size, and the Shapley value of such a cost among the sections that use it is an equal share. A section that
    waits (or is only inspected or surveyed, which needs no possession) pays none of it, and a section that joins
    a campaign pays less than one that goes alone."""
    worked = np.asarray(worked, dtype=bool)
    payers = worked if worked.any() else np.ones_like(worked)
    return np.where(payers, float(shared_cost) / int(payers.sum()), 0.0)


def _line_env_ids() -> list[str]:
    """The registered ids whose entry point is a TampingLine class (the lines and the 60 m track) acting in its own
    action space (no discrete actions, no wrapper in the registration), for messages."""
    from gymnasium.envs.registration import load_env_creator

    def is_line(spec: Any) -> bool:
        creator = load_env_creator(spec.entry_point) if isinstance(spec.entry_point, str) else spec.entry_point
        own_actions = spec.kwargs.get("action_type") in (None, "multibinary", "choices")
        return isinstance(creator, type) and issubclass(creator, TampingLine) and own_actions and \
            not spec.additional_wrappers

    return sorted(env_id for env_id, spec in gym.registry.items() if env_id.startswith("trackenv/") and is_line(spec))


def _check_line_env(env: gym.Env) -> tuple[int, int]:
    """The number of sections of ``env``, a TampingLine (possibly wrapped) with MultiBinary section actions or the
    choices (``MultiDiscrete([7] * n_sections)``) and a Dict observation, and the number of codes a section's
    action has (2 or 7); ValueError naming what it is otherwise."""
    name = env.spec.id if env.spec is not None else type(env).__name__
    if not isinstance(env.unwrapped, TampingLine):
        raise ValueError(f"env_id must name a TampingLine env (one of {_line_env_ids()}), got {name!r} "
                         f"({type(env.unwrapped).__name__})")
    space = env.action_space
    n = int(space.shape[0]) if space.shape is not None and len(space.shape) == 1 else 0
    if n and space == spaces.MultiBinary(n):
        codes = 2
    elif n and space == spaces.MultiDiscrete([len(CHOICES)] * n):
        codes = len(CHOICES)
    else:
        raise ValueError(f"{name!r} acts in {space}: one agent per section needs the line env's own actions, "
                         f"MultiBinary(n_sections) or the choices MultiDiscrete([{len(CHOICES)}] * n_sections), as on "
                         f"{', '.join(_line_env_ids())} (without a wrapper that changes them)")
    if not isinstance(env.observation_space, spaces.Dict):
        raise ValueError(f"{name!r}: the line env's observation space must be a Dict, got {env.observation_space}")
    return n, codes


class LineParallelEnv(ParallelEnv):
    """A TampingLine env as a PettingZoo ``ParallelEnv``: one agent per section, all acting at once.

    **Agents.** ``"section_0"``, ..., ``"section_<n-1>"`` along the line (``possible_agents``); all of them live
    from ``reset`` to the horizon, when all are truncated together and ``agents`` becomes empty.

    **Action space** (per agent): ``Discrete(2)``: 0 = wait, 1 = tamp this section in this step's campaign; on
    a line with the choices (``action_type="choices"``: ``trackenv/TampingLine-v1``, ``TampingLineWet-v0``,
    ``TampingLineDefects-v0``), ``Discrete(7)``: the section's choice code
    (:data:`~trackenv.envs.choices.CHOICES`: 0 nothing, 1 tamp, 2 spot tamp, 3 drainage, 4 renew, 5 inspect,
    6 survey). The joint action is the line env's action, with its rules: a masked choice becomes nothing, and
    over the possession's capacity (or the annual budget) the line env keeps the sections with the worst measured
    SD (``over_capacity="clip"``, the default) or raises. ``info["tamped_sections"]`` says whether the agent's
    section was tamped (or renewed), ``info["section_choices"]`` which choice it got.

    **Observation** (per agent): ``Dict`` with

    * ``"observation"``: float32 ``Box``, first the agent's section's entries of the line env's observation,
      then the line context that every agent shares, each part in the order of the line env's observation space
      (its keys' alphabetical order): on the default line ``register``, ``section_peak`` and ``section_sd``
      [mm], ``tampings``, ``tampings_since_renewal``, ``years_since_tamping`` [year], then ``budget_left``,
      ``measurement_age`` [year], ``time`` (the keys of ``profiles`` or the choices take their places in that
      order). ``feature_names`` names the entries in order; units and bounds are the line env's (its table:
      :class:`~trackenv.envs.line.TampingLine`).
    * ``"action_mask"``: int8 ``(2,)`` [may wait, may tamp]: 0 for tamp while the section is within
      ``min_steps_between_tampings`` of its last tamping, or where its tamping alone would not fit the possession
      or what is left of an annual budget; with the choices ``(7,)``, one entry per code (the
      line env's ``action_masks()``, section by section: a choice not enabled, track work too soon after the
      last, work larger than the possession, a cost over what is left of the budget). The mask is in the
      observation only (PettingZoo's convention, which its API test samples with); what the sections' choices
      need together (capacity, budget) is not masked: the line env resolves it.

    Every agent has the same observation and action spaces, so one policy can serve them all (parameter
    sharing).

    **Reward** (per agent, −k€): −(the section's own costs of the step, ``info["section_costs"]`` of the line
    env: its tamping or renewal, geometry, speed restriction and immediate action, + its share of the step's
    possession). The possession of a campaign is split **equally among the sections tamped in it** (with the
    choices: among the sections with track work, i.e. tamp, spot tamp, drainage or renewal; an inspection or a
    survey needs no possession) (:func:`possession_shares`: the Shapley value of a fixed cost); sections that wait
    pay none. So the agents' rewards add up to the line env's reward (up to floating-point rounding).

    **Infos** (per agent): every per-section entry of the line env's info at the agent's section
    (``tamped_sections``, ``section_costs``, ``section_sd_mm``, ``section_class``, ``wet_spot_active``, ...),
    plus ``possession_share`` and ``cost`` (own + share, = −reward) in k€, ``dropped`` (the agent asked for a
    choice and its section got nothing: masked, too soon after its last track work, or cut for the possession's
    capacity or the budget) and ``clipped`` (the line env's: the line's requests were cut for the capacity or the
    budget). The line env's whole info is :attr:`line_info`.

    **Episode end.** No terminal state; every agent is truncated at the line env's horizon. ``step`` with no live
    agent raises RuntimeError until ``reset``.

    **Seeding.** ``reset(seed=s)`` seeds the line env; the same seed and joint actions give the line env's
    rollout. ``options`` is accepted (PettingZoo's API passes it) and not used: the line env takes none.

    **State.** :meth:`state` is the line env's whole observation flattened (``state_space``), for centralised
    critics. :meth:`get_state` and :meth:`set_state` copy and restore the episode (the line env's snapshot,
    :mod:`~trackenv.envs.state`), e.g. for a tree search over joint actions: the restored moment's observations,
    infos and live agents, as after the step that led there.

    **Rendering.** ``render_mode="rgb_array"`` (an argument of the line env): :meth:`render` is the line env's
    picture of the line.

    **Arguments.** ``env``: a TampingLine env (``gym.make`` of a line id, possibly wrapped, with its
    ``MultiBinary`` actions or the choices and its Dict observation); ValueError otherwise. Usually built by
    :func:`~trackenv.envs.multiagent.line_parallel_env`.
    """

    metadata = {"name": "trackenv_line_parallel_v0", "render_modes": ["rgb_array"], "render_fps": 4,
                "is_parallelizable": True}

    def __init__(self, env: gym.Env) -> None:
        n_sections, self._codes = _check_line_env(env)
        self.env = env
        self.render_mode = env.render_mode
        self.possible_agents: list[str] = [agent_name(j) for j in range(n_sections)]
        self.agents: list[str] = []
        space = env.observation_space
        assert isinstance(space, spaces.Dict)  # checked above
        # per-section keys lead with the sections (their first axis), the rest is the line's context
        self._section_keys = [k for k, s in space.items() if s.shape is not None and s.shape[:1] == (n_sections,)]
        self._line_keys = [k for k in space if k not in self._section_keys]
        self.feature_names: tuple[str, ...] = self._feature_names(space)
        """The names of the entries of every agent's ``"observation"`` vector, in order."""
        low = self.agent_features({k: s.low for k, s in space.items()})  # type: ignore[attr-defined]
        high = self.agent_features({k: s.high for k, s in space.items()})  # type: ignore[attr-defined]
        mask_space = spaces.Box(0, 1, (self._codes,), np.int8)
        self.observation_spaces: dict[str, spaces.Space] = {
            agent: spaces.Dict({"observation": spaces.Box(low[j], high[j], dtype=np.float32),
                                "action_mask": mask_space})
            for j, agent in enumerate(self.possible_agents)}
        self.action_spaces: dict[str, spaces.Space] = {agent: spaces.Discrete(self._codes)
                                                       for agent in self.possible_agents}
        self.state_space = spaces.flatten_space(space)
        self._obs: dict[str, np.ndarray] | None = None
        self._info: dict[str, Any] = {}

    # ------------------------------------------------------------------ spaces
    def observation_space(self, agent: str) -> spaces.Space:
        """The observation space of ``agent`` (the same object at every call)."""
        return self.observation_spaces[self._known(agent)]

    def action_space(self, agent: str) -> spaces.Space:
        """The action space of ``agent``, ``Discrete(2)`` or with the choices ``Discrete(7)`` (the same object
        at every call)."""
        return self.action_spaces[self._known(agent)]

    def _known(self, agent: str) -> str:
        if agent not in self.observation_spaces:
            raise ValueError(f"agent must be one of {self.possible_agents}, got {agent!r}")
        return agent

    def _feature_names(self, space: spaces.Dict) -> tuple[str, ...]:
        names = []
        for key in self._section_keys + self._line_keys:
            shape = space[key].shape or ()
            width = int(np.prod(shape[1:] if key in self._section_keys else shape))
            names += [key] if width == 1 else [f"{key}[{i}]" for i in range(width)]
        return tuple(names)

    def agent_features(self, arrays: Mapping[str, np.ndarray]) -> np.ndarray:
        """(n_sections, n_features) float32: row j is agent j's ``"observation"`` from the line env's
        observation (or its space's bounds) ``arrays``; a policy trained here reads a line observation with it."""
        n = len(self.possible_agents)
        columns = [np.asarray(arrays[k]).reshape(n, -1) for k in self._section_keys]
        columns += [np.broadcast_to(np.asarray(arrays[k]).reshape(1, -1), (n, np.size(arrays[k])))
                    for k in self._line_keys]
        return np.concatenate(columns, axis=1).astype(np.float32)

    # ------------------------------------------------------------------ the API
    def reset(self, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[dict[str, dict], dict[str, dict]]:
        """A new episode of the line env (seeded with ``seed``); every agent live. ``options`` is not used."""
        if options is not None and not isinstance(options, Mapping):
            raise ValueError(f"options must be a dict or None, got {type(options).__name__}")
        self._obs, self._info = self.env.reset(seed=seed)
        self.agents = list(self.possible_agents)
        return self._observations(), self._infos(self._info)

    def step(self, actions: Mapping[str, Any]) -> tuple[dict[str, dict], dict[str, float], dict[str, bool],
                                                       dict[str, bool], dict[str, dict]]:
        """One step of the line env with the joint action of ``actions`` (one 0/1, or one choice code, per live
        agent)."""
        if not self.agents:
            raise RuntimeError("call reset() before step()" if self._obs is None else
                               "the episode has ended (every agent truncated at the horizon): call reset()")
        live = self.agents
        want = self._joint_action(actions)
        self._obs, _, terminated, truncated, self._info = self.env.step(want)
        infos = self._infos(self._info, want)
        rewards = {agent: -infos[agent]["cost"] for agent in self.possible_agents}
        terminations = dict.fromkeys(live, bool(terminated))
        truncations = dict.fromkeys(live, bool(truncated))
        observations = self._observations()
        if terminated or truncated:
            self.agents = []
        return observations, rewards, terminations, truncations, infos

    def get_state(self) -> Any:
        """A snapshot of the episode: the line env's :class:`~trackenv.envs.state.EnvState`, which
        :meth:`set_state` of this or another PettingZoo env of the same line config (or the line env's own
        ``set_state``) continues bit for bit."""
        if self._obs is None:
            raise RuntimeError("call reset() before get_state()")
        return self.env.unwrapped.get_state()  # type: ignore[attr-defined]

    def set_state(self, state: Any) -> tuple[dict[str, dict], dict[str, dict]]:
        """Continue from ``state`` (from :meth:`get_state`, or a line env's of the same config), after a
        ``reset`` of this env as the line env needs: the line env restored, every agent live unless that moment is
        the horizon, and :meth:`state`, :attr:`line_info` and the returned observations and infos (as ``reset``
        returns them) those of the restored moment, as after the step that led there. The snapshot is not
        changed, so it can be restored again."""
        line = self.env.unwrapped
        line.set_state(state)  # type: ignore[attr-defined]
        self._obs = line.current_observation()  # type: ignore[attr-defined]
        self._info = copy.deepcopy(state.last_info)  # the info of the step that led there, as the line env keeps
        ended = line.engine.step_count(0) >= line.config.horizon_steps  # type: ignore[attr-defined]
        self.agents = [] if ended else list(self.possible_agents)
        return self._observations(), self._infos(self._info)

    def _joint_action(self, actions: Mapping[str, Any]) -> np.ndarray:
        """The line env's action from one 0/1 (or one choice code) per live agent; ValueError naming what is
        wrong."""
        allowed = "0 (wait) or 1 (tamp)" if self._codes == 2 else f"a choice code in [0, {self._codes - 1}]"
        if not isinstance(actions, Mapping):
            raise ValueError(f"actions must be a dict of agent -> {allowed}, got {type(actions).__name__}")
        missing = [agent for agent in self.agents if agent not in actions]
        unknown = [agent for agent in actions if agent not in self.agents]
        if missing or unknown:
            raise ValueError(f"actions must have one entry per live agent {self.agents}; missing {missing}, "
                             f"unknown {unknown}")
        want = np.zeros(len(self.possible_agents), dtype=np.int8 if self._codes == 2 else np.int64)
        for j, agent in enumerate(self.possible_agents):
            value = actions[agent]  # what the agent's Discrete space contains: an integer, not 1.0 nor [1]
            if isinstance(value, bool) or not self.action_spaces[agent].contains(value):
                raise ValueError(f"actions[{agent!r}] must be {allowed} (an integer), got {value!r}")
            want[j] = int(value)
        return want

    def _observations(self) -> dict[str, dict[str, np.ndarray]]:
        assert self._obs is not None
        features = self.agent_features(self._obs)
        masks = np.asarray(self.env.get_wrapper_attr("action_masks")(), dtype=np.int8).reshape(-1, self._codes)
        return {agent: {"observation": features[j], "action_mask": masks[j]}
                for j, agent in enumerate(self.possible_agents)}

    def _infos(self, info: Mapping[str, Any], want: np.ndarray | None = None) -> dict[str, dict[str, Any]]:
        """Each agent's info from the line env's ``info`` of a step (or a reset: no costs) and the joint action
        ``want`` that led to it (None: unknown, nothing dropped)."""
        n = len(self.possible_agents)
        per_section = {k: v for k, v in info.items() if isinstance(v, np.ndarray) and v.shape == (n,)}
        shares, costs = np.zeros(n), np.zeros(n)
        if "section_costs" in info:  # a step's info
            worked = IS_TRACK_WORK[np.asarray(info["section_choices"], dtype=np.int64)]
            shares = possession_shares(sum(info["costs"][k] for k in SHARED_COST_KEYS), worked)
            costs = np.asarray(info["section_costs"], dtype=float) + shares
        applied = np.asarray(info.get("section_choices", np.zeros(n)), dtype=np.int64)
        dropped = (np.zeros(n, bool) if want is None
                   else (np.asarray(want, dtype=np.int64) != 0) & (applied == 0))
        clipped = bool(info.get("clipped", False))
        return {agent: {**{k: v[j].item() for k, v in per_section.items()},
                        "possession_share": float(shares[j]), "cost": float(costs[j]),
                        "dropped": bool(dropped[j]), "clipped": clipped}
                for j, agent in enumerate(self.possible_agents)}

    @property
    def line_info(self) -> dict[str, Any]:
        """The line env's info of the last ``reset`` or ``step`` (its cost parts, the sections tamped, the true
        quality, ...)."""
        return self._info

    def state(self) -> np.ndarray:
        """The global state for centralised training: the line env's last observation, flattened
        (``state_space``)."""
        if self._obs is None:
            raise RuntimeError("call reset() before state()")
        return np.asarray(spaces.flatten(self.env.observation_space, self._obs))

    def render(self) -> np.ndarray | None:
        """The line env's picture of the line (``render_mode="rgb_array"``), else None."""
        return self.env.render()  # type: ignore[return-value]

    def close(self) -> None:
        """Close the line env."""
        self.env.close()
