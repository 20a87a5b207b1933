"""The line's rules on a network of lines that share one tamping machine (``trackenv/TampingNetwork-v0``).

:class:`NetworkRule` runs a line rule (:mod:`.line`; default :class:`~.line.SectionThreshold`) on every line of
the network, as if each had its own machine, then sends the one machine where the requests are: it keeps the
requests of the machine's line while that line has any, and otherwise asks for every line's, which moves the
machine to the line with the most (the env's rule) without asking it to leave a line with work left.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .base import Heuristic, as_batch
from .line import LineHeuristic, SectionThreshold

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
    """A line rule on every line, the machine kept on its line while the rule asks for work there (see the
    module docstring). ``line_rule``: a line heuristic (default: :class:`~.line.SectionThreshold` at its default
    threshold); bind it to the network's config (:meth:`bind`) for the line's calendar and capacity."""

    name = "network"

    def __init__(self, line_rule: LineHeuristic | None = None) -> None:
        self.line_rule = line_rule if line_rule is not None else SectionThreshold()
        super().__init__(line_rule=self.line_rule.name, **self.line_rule.params)
        # one name per line rule, e.g. "network(grouped-threshold)", where results are keyed by policy name (the
        # base class's name is a class attribute; this one is the instance's)
        self.__dict__["name"] = f"network({self.line_rule.name})"

    def bind(self, config: Any) -> NetworkRule:
        """A copy whose line rule knows the calendar and capacity of the network's line config."""
        return type(self)(self.line_rule.bind(config.line_config))

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
