"""The line's rules on a network of lines that share one tamping machine (``trackenv/TampingNetwork-v0``).

:class:`NetworkRule` runs a line policy on every line of the network, as if each had its own machine, then sends
the one machine where the requests are: it keeps the requests of the machine's line while that line has any, and
otherwise asks for every line's, which moves the machine to the line with the most (the env's rule) without
asking it to leave a line with work left. The line policy is a line rule (:mod:`.line`; default
:class:`~.line.SectionThreshold`) or any policy of the line with SB3's ``predict`` on batched line observations:
the shipped line agent (:class:`~trackenv_agents.learning.line_policy.LineAgent`) plays the network this way.

The line policy is asked without a recurrent state: it cannot know which of its requests the machine worked (a
line the machine is not on has its requests dropped), so a memory of the work it asked for would be wrong there.
The policies played here keep none that matters on the network's tamping-only lines (the rules are stateless;
a choice agent's memory of its track work only repeats the ``years_since_tamping`` gap that it reads from the
observation anyway).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .base import Heuristic, as_batch
from .line import SectionThreshold

__all__ = ["NetworkRule", "line_view"]


def line_view(obs: dict[str, np.ndarray], n_lines: int) -> dict[str, np.ndarray]:
    """A batched network observation (batch, ...) as the batched observation of its lines (batch · n_lines,
    ...): per-section keys (batch, n_lines · S) -> (batch · n_lines, S), per-line keys -> (batch · n_lines, 1),
    ``time`` repeated; ``machine_line`` left out."""
    out = {}
    for key, value in obs.items():
        if key == "machine_line":
            continue
        if key == "time":
            out[key] = np.repeat(value, n_lines, axis=0)
        else:
            out[key] = value.reshape(value.shape[0] * n_lines, value.shape[1] // n_lines, *value.shape[2:])
    return out


class NetworkRule(Heuristic):
    """A line policy on every line, the machine kept on its line while the policy asks for work there (see the
    module docstring). ``line_rule``: a line heuristic (default: :class:`~.line.SectionThreshold` at its default
    threshold) or any line policy with SB3's ``predict``, a ``name`` and a ``params`` dict (a trained line
    agent); bind it to the network's config (:meth:`bind`) for the line's calendar and capacity."""

    name = "network"

    def __init__(self, line_rule: Any = None) -> None:
        self.line_rule = line_rule if line_rule is not None else SectionThreshold()
        line_name = str(getattr(self.line_rule, "name", None) or type(self.line_rule).__name__)
        super().__init__(line_rule=line_name, **dict(getattr(self.line_rule, "params", None) or {}))
        # one name per line policy, e.g. "network(grouped-threshold)", where results are keyed by policy name (the
        # base class's name is a class attribute; this one is the instance's)
        self.__dict__["name"] = f"network({line_name})"

    def bind(self, config: Any) -> NetworkRule:
        """A copy whose line policy knows the calendar and capacity of the network's line config (a policy
        without ``bind`` is taken as it is)."""
        bind = getattr(self.line_rule, "bind", None)
        return type(self)(bind(config.line_config) if callable(bind) else self.line_rule)

    def reset(self) -> None:
        """The line policy's reset, where it has one."""
        reset = getattr(self.line_rule, "reset", None)
        if callable(reset):
            reset()

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        b, batched = as_batch(obs)
        n_envs, n_lines = b["machine_line"].shape
        want, _ = self.line_rule.predict(line_view(b, n_lines))
        want = np.asarray(want, dtype=bool).reshape(n_envs, n_lines, -1)
        here = b["machine_line"].argmax(axis=1)
        busy = want[np.arange(n_envs), here].any(axis=1)
        keep = np.where(busy[:, None], np.arange(n_lines)[None, :] == here[:, None], True)
        act = (want & keep[:, :, None]).reshape(n_envs, -1).astype(np.int8)
        return (act if batched else act[0]), state
