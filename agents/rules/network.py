"""The line's rules on a network of lines that share one tamping machine (``trackenv/TampingNetwork-v0``).

:class:`NetworkRule` runs a line policy on every line of the network, as if each had its own machine, then sends
the one machine where the requests are: it keeps the requests of the machine's line while that line has any, and
otherwise asks for every line's, which moves the machine to the line with the most (the env's rule) without
asking it to leave a line with work left. The line policy is a line rule (:mod:`.line`; default
:class:`~.line.SectionThreshold`) or any policy of the line with SB3's ``predict`` on batched line observations:
the shipped line agent (:class:`~trackenv_agents.learning.line_policy.LineAgent`) plays the network this way.

With ``dispatch="value"`` (or a :class:`~.dispatch.ValueDispatch` of other parameters) the machine goes where the
requested work is worth most instead: the quality cost per step of each line's requested sections in their
projected state, with a margin before it leaves a line that still asks for work (:mod:`.dispatch`); only the
chosen line's requests are passed on, so the env's count of requests takes the machine there.

The line policy is asked without a recurrent state: it cannot know which of its requests the machine worked (a
line the machine is not on has its requests dropped), so a memory of the work it asked for would be wrong there.
The policies played here keep none that matters on the network's tamping-only lines (the rules are stateless;
a choice agent's memory of its track work only repeats the ``years_since_tamping`` gap that it reads from the
observation anyway).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from trackenv.envs.line_episode import line_observation_space
from trackenv.envs.network import line_groups
from trackenv.physics._checks import check_scalar

from .base import Heuristic, as_batch, policy_params
from .dispatch import ValueDispatch
from .line import SectionThreshold

__all__ = ["DISPATCHES", "NETWORK_DISPATCH", "NETWORK_EAGER_PROBABILITY", "NetworkRule", "eager_for", "line_view",
           "network_label", "network_play"]

#: the dispatches of :class:`NetworkRule`: by the count of requests (the env's own rule), or by their value
DISPATCHES = ("requests", "value")
#: the dispatch the comparisons play the network with (the leaderboard's network rows, ``trackenv evaluate --env
#: trackenv/TampingNetwork-v0``): by value, cheaper than by requests for the tuned rules and the shipped agent
#: alike on 200 held-out episodes (the documentation's network page)
NETWORK_DISPATCH = "value"
#: the probability from which a trained line agent is asked for work on the line the machine stays on, in the
#: comparisons (:func:`eager_for`): chosen on training episodes 1000-1047 among 0.05-0.35 (the documentation's
#: network page)
NETWORK_EAGER_PROBABILITY = 0.15


def eager_for(line_policy: Any) -> float | None:
    """The ``eager_probability`` the comparisons play ``line_policy`` with on the network:
    :data:`NETWORK_EAGER_PROBABILITY` for a policy that can be asked from a probability (a trained line agent's
    ``requests``) and whose advisor keeps no state, None for the rules."""
    if not callable(getattr(line_policy, "requests", None)) or getattr(line_policy, "observation_state", False):
        return None
    return NETWORK_EAGER_PROBABILITY


def network_play(line_policy: Any, dispatch: str | ValueDispatch = NETWORK_DISPATCH) -> NetworkRule:
    """``line_policy`` as the comparisons play it on the network: on every line, the machine sent by ``dispatch``,
    a trained line agent eager where the machine stays (:func:`eager_for`)."""
    return NetworkRule(line_policy, dispatch, eager_probability=eager_for(line_policy))


def network_label(line_name: str, dispatch: str | ValueDispatch = "requests",
                  eager_probability: float | None = None) -> str:
    """The name of a :class:`NetworkRule` over the line policy ``line_name``: ``network(<line_name>)`` by
    requests, ``network-by-value(<line_name>)`` by value, ``, eager <p>`` added inside the brackets with an
    ``eager_probability`` (one name per policy where results are keyed by it)."""
    by_value = isinstance(dispatch, ValueDispatch) or dispatch == "value"
    inner = line_name if eager_probability is None else f"{line_name}, eager {eager_probability:g}"
    return f"network-by-value({inner})" if by_value else f"network({inner})"


def line_view(obs: dict[str, np.ndarray], n_lines: int, lines: Sequence[int] | None = None,
              network: Any = None) -> dict[str, np.ndarray]:
    """A batched network observation (batch, ...) as the batched observation of its lines ``lines`` (default
    all; batch · len(lines), ...): per-section keys (batch, Σ sections) -> (batch · len(lines), S), per-line keys
    -> (batch · len(lines), 1), ``time`` repeated; ``machine_line`` left out. The lines' sections (and profile
    segments) are those of ``network`` (a :class:`~trackenv.envs.network.NetworkConfig`; None: every line has an
    equal share); ``lines`` must have equally many."""
    chosen = list(range(n_lines)) if lines is None else list(lines)
    out = {}
    for key, value in obs.items():
        if key == "machine_line":
            continue
        if key == "time":
            out[key] = np.repeat(value, len(chosen), axis=0)
        elif _per_line(key, value, n_lines, network):
            out[key] = value[:, chosen].reshape(-1, 1)
        else:
            rows = _line_rows(network, n_lines, value.shape[1], profile=value.ndim > 2)
            parts = [value[:, rows[line]:rows[line + 1]] for line in chosen]
            out[key] = np.stack(parts, axis=1).reshape(-1, *parts[0].shape[1:])
    return out


def _per_line(key: str, value: np.ndarray, n_lines: int, network: Any) -> bool:
    """Whether ``key`` holds one value per line: per the line's observation space, or without ``network`` by its
    shape (batch, n_lines)."""
    if network is None:
        return value.ndim == 2 and value.shape[1] == n_lines
    return key in _per_line_keys(network.line_configs[0])


@functools.lru_cache(maxsize=64)
def _per_line_keys(line_config: Any) -> frozenset[str]:
    """The keys of the line's observation that hold one value per line (shape (1,))."""
    return frozenset(k for k, space in line_observation_space(line_config).spaces.items() if space.shape == (1,))


def _line_rows(network: Any, n_lines: int, total: int, profile: bool) -> np.ndarray:
    """(n_lines + 1,) where each line's rows of a stacked key start: its sections, or with ``profile`` its
    segments, per ``network``'s lines; an equal share of ``total`` without one."""
    if network is None:
        return np.arange(n_lines + 1) * (total // n_lines)
    if not profile:
        return np.asarray(network.line_offsets)
    return np.concatenate([[0], np.cumsum([line.n_segments for line in network.line_configs])])


class NetworkRule(Heuristic):
    """A line policy on every line, the machine kept on its line while the policy asks for work there (see the
    module docstring). ``line_rule``: a line heuristic (default: :class:`~.line.SectionThreshold` at its default
    threshold) or any line policy with SB3's ``predict``, a ``name`` and a ``params`` dict (a trained line
    agent); bind it to the network's config (:meth:`bind`) for the line's calendar and capacity (on a network of
    lines of their own, always: unbound, it takes every line to have an equal share of the sections). ``dispatch``:
    ``"requests"`` (default: the machine stays while its line asks, else goes where most sections are asked
    for), ``"value"`` (:class:`~.dispatch.ValueDispatch` at its defaults) or a ValueDispatch; the value dispatch
    prices the sections with the line's limits and costs, so it plays once bound. ``eager_probability`` (in
    (0, 0.5]; None: off): the line the machine stays on asks for every section the line policy would tamp with
    at least that probability (a line policy with ``requests``, e.g. a trained line agent; ValueError
    otherwise). Its name is ``network(<line policy>)`` by requests, ``network-by-value(<line policy>)`` by value
    (:func:`network_label`)."""

    name = "network"

    def __init__(self, line_rule: Any = None, dispatch: str | ValueDispatch = "requests",
                 line_config: Any = None, eager_probability: float | None = None) -> None:
        self.line_rule = line_rule if line_rule is not None else SectionThreshold()
        if eager_probability is not None:
            eager_probability = check_scalar("eager_probability", eager_probability, low=0.0, high=0.5,
                                             low_inclusive=False)
            if not callable(getattr(self.line_rule, "requests", None)):
                raise ValueError(f"eager_probability needs a line policy that can be asked from a probability (a "
                                 f"trained line agent's requests); {type(self.line_rule).__name__} cannot")
        self.eager_probability = eager_probability
        if isinstance(dispatch, str):
            if dispatch not in DISPATCHES:
                raise ValueError(f"dispatch must be one of {list(DISPATCHES)} or a ValueDispatch, got {dispatch!r}")
            dispatch = ValueDispatch() if dispatch == "value" else dispatch
        elif not isinstance(dispatch, ValueDispatch):
            raise ValueError(f"dispatch must be one of {list(DISPATCHES)} or a ValueDispatch, got "
                             f"{type(dispatch).__name__}")
        self.dispatch = dispatch
        #: the network's line config (set by :meth:`bind`): the value dispatch's limits and costs
        self.line_config = line_config
        line_name = str(getattr(self.line_rule, "name", None) or type(self.line_rule).__name__)
        extra = {"dispatch": "value", **dispatch.params()} if isinstance(dispatch, ValueDispatch) else {}
        if eager_probability is not None:
            extra["eager_probability"] = eager_probability
        super().__init__(line_rule=line_name, **dict(getattr(self.line_rule, "params", None) or {}), **extra)
        # the base class's name is a class attribute; this one is the instance's
        self.__dict__["name"] = network_label(line_name, dispatch, eager_probability)

    def bind(self, config: Any, line_rules: Sequence[Any] | None = None) -> NetworkRule:
        """A copy whose line policy knows the calendar and capacity of the network's line config (a policy
        without ``bind`` is taken as it is), and whose dispatch knows that line's limits and costs. On a network
        of lines of their own (``config.mixed``) the line policy is bound to each distinct line config and plays
        the lines of that config. ``line_rules``: one line policy per line instead (a plan's rules tuned per
        line), of which the lines of one config play their first line's (ValueError where they differ in
        parameters)."""
        if line_rules is not None and len(line_rules) != config.n_lines:
            raise ValueError(f"line_rules must have one line policy per line ({config.n_lines}), got "
                             f"{len(line_rules)}")
        groups = []
        for line, members in line_groups(config):
            rule = self.line_rule if line_rules is None else line_rules[members[0]]
            if line_rules is not None and any(policy_params(line_rules[m]) != policy_params(rule) for m in members):
                raise ValueError(f"line_rules: lines {members} share one config but not their line policy's "
                                 f"parameters")
            bind = getattr(rule, "bind", None)
            groups.append((members, bind(line) if callable(bind) else rule, line))
        bound = type(self)(groups[0][1], self.dispatch, config.line_config, self.eager_probability)
        bound._network, bound._groups = config, groups
        return bound

    #: set by :meth:`bind`: the network's config, and per distinct line config (its lines, the line policy bound
    #: to it, the config)
    _network: Any = None
    _groups: list[tuple[list[int], Any, Any]] | None = None
    #: (n_envs, Σ sections) bool, set by :meth:`predict`: what each line's policy asked for on its line before the
    #: dispatch kept one line's (what a plan calls asked, wherever the machine is); None before the first predict
    last_requests: np.ndarray | None = None

    def reset(self) -> None:
        """The line policy's reset (each bound copy's), where it has one."""
        for _, line_rule, _ in self._groups or [([], self.line_rule, None)]:
            reset = getattr(line_rule, "reset", None)
            if callable(reset):
                reset()

    def _line_wants(self, b: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, list, list]:
        """The line policies' own requests on the batched network observation ``b``: (n_envs, n_lines, S) bool,
        padded with False where a line has fewer sections; each line's number of sections; the groups of lines
        of one line policy and each group's view of the observation (:func:`line_view`)."""
        n_envs, n_lines = b["machine_line"].shape
        groups = self._groups or [(list(range(n_lines)), self.line_rule, self.line_config)]
        if self._network is None and b["section_sd"].shape[1] % n_lines:
            raise ValueError(f"NetworkRule: {b['section_sd'].shape[1]} sections over {n_lines} lines are lines of "
                             f"their own: bind the rule to the network's config first (bind)")
        sections = np.diff(_line_rows(self._network, n_lines, b["section_sd"].shape[1], profile=False))
        views = [line_view(b, n_lines, members, self._network) for members, _, _ in groups]
        want = self._per_line(n_envs, groups, views, sections, lambda line_rule, view: line_rule.predict(view)[0])
        return want, sections, groups, views

    @staticmethod
    def _per_line(n_envs: int, groups: list, views: list[dict[str, np.ndarray]], sections: np.ndarray,
                  ask: Callable[[Any, dict[str, np.ndarray]], np.ndarray]) -> np.ndarray:
        """(n_envs, n_lines, S) bool: ``ask(line_rule, view)`` (batch · lines of the group, sections) of each
        group's line policy on its view, placed at its lines and padded with False where a line has fewer
        sections."""
        out = np.zeros((n_envs, len(sections), sections.max()), dtype=bool)
        for (members, line_rule, _), view in zip(groups, views, strict=True):
            asked = np.asarray(ask(line_rule, view), dtype=bool)
            out[:, members, :sections[members[0]]] = asked.reshape(n_envs, len(members), -1)
        return out

    @staticmethod
    def _flat(per_line: np.ndarray, sections: np.ndarray) -> np.ndarray:
        """(n_envs, n_lines, S) padded per-line values as the network's (n_envs, Σ sections), in the action's order."""
        return np.concatenate([per_line[:, line, :sections[line]] for line in range(len(sections))], axis=1)

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        b, batched = as_batch(obs)
        n_envs, n_lines = b["machine_line"].shape
        want, sections, groups, views = self._line_wants(b)
        self.last_requests = self._flat(want, sections)
        here = b["machine_line"].argmax(axis=1)
        rows = np.arange(n_envs)
        if isinstance(self.dispatch, ValueDispatch):
            target = self._value_target(self.dispatch, groups, views, want, here)
            keep = np.arange(n_lines)[None, :] == target[:, None]
            stay = target == here
        else:
            stay = want[rows, here].any(axis=1)  # its line asks: the machine stays and works there
            keep = np.where(stay[:, None], np.arange(n_lines)[None, :] == here[:, None], True)
        act = want & keep[:, :, None]
        if self.eager_probability is not None:  # where the machine stays, its line asks for what is due soon too
            p = self.eager_probability
            soon = self._per_line(n_envs, groups, views, sections, lambda rule, view: rule.requests(view, p))
            act[rows, here] |= soon[rows, here] & stay[:, None]
        flat = self._flat(act, sections).astype(np.int8)
        return (flat if batched else flat[0]), state

    def _value_target(self, dispatch: ValueDispatch, groups: list, views: list[dict[str, np.ndarray]],
                      want: np.ndarray, here: np.ndarray) -> np.ndarray:
        """(n_envs,) the line ``dispatch`` serves this step: each line's requests ``want`` (n_envs, n_lines, S)
        priced with its own config's limits and costs."""
        values = np.zeros(want.shape[:2])
        for (members, _, line_config), view in zip(groups, views, strict=True):
            if line_config is None:
                raise ValueError("NetworkRule(dispatch='value') prices the sections with the line's limits and "
                                 "costs: bind it to the network's config first (bind)")
            mine = want[:, members, :view["section_sd"].shape[1]]
            values[:, members] = dispatch.line_values(view, mine, line_config)
        move_cost = 0.0 if self._network is None else float(self._network.move_cost)
        return dispatch.target(values, np.asarray(want.any(axis=2)), here, move_cost)
