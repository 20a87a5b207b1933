"""What every tamping rule is: an SB3-style policy over the env's observation dict.

Every policy speaks stable-baselines3's ``predict(obs, state=None, episode_start=None, deterministic=True)
-> (action, state)``, as its models do, so one harness (:mod:`trackenv_agents.evaluation`) scores rules and
trained agents alike. ``obs`` is one observation dict (action shape ``(n_sections,)``) or a batched dict with a
leading env axis (``obs["time"].ndim == 2``; action shape ``(n_envs, n_sections)``). Actions are int8 0/1.

Each rule has a ``name``, a ``params`` dict (its constructor arguments, JSON-friendly) and a
:meth:`~Heuristic.param_grid` classmethod: the grid that :func:`trackenv_agents.evaluation.tuning.tune`
searches. The rules themselves are in :mod:`.line` (they serve every preset: the lines and the 60 m track);
:class:`RandomPolicy` is the untuned baseline.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

__all__ = ["Heuristic", "RandomPolicy", "as_batch", "policy_params"]


def policy_params(policy: Any) -> dict[str, Any]:
    """A copy of ``policy``'s ``params`` (a rule's, an agent's), {} where it has none."""
    params = getattr(policy, "params", None)
    return dict(params) if isinstance(params, Mapping) else {}


def as_batch(obs: dict[str, Any]) -> tuple[dict[str, np.ndarray], bool]:
    """The observation with a leading env axis, and whether it came batched."""
    batched = np.asarray(obs["time"]).ndim == 2
    if batched:
        return {k: np.asarray(v) for k, v in obs.items()}, True
    return {k: np.asarray(v)[None] for k, v in obs.items()}, False


class Heuristic:
    """Base class: subclasses implement :meth:`_act` on batched observations (bool (n_envs, n_sections))."""

    name: ClassVar[str] = "heuristic"

    def __init__(self, **params: Any) -> None:
        self.params: dict[str, Any] = dict(params)

    def _act(self, obs: dict[str, np.ndarray]) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def predict(self, obs: dict[str, Any], state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        """SB3-style: the action (int8 0/1 per section; batched if ``obs`` is) and the unchanged ``state``."""
        b, batched = as_batch(obs)
        act = np.asarray(self._act(b), dtype=np.int8)
        return (act if batched else act[0]), state

    def reset(self) -> None:
        """Nothing to forget: the heuristics are stateless."""

    def bind(self, config: Any) -> Heuristic:
        """A copy that knows the planning calendar of ``config`` (a no-op for calendar-free policies)."""
        return self

    @classmethod
    def param_grid(cls) -> list[dict[str, Any]]:
        """The parameter sets searched when tuning (a list of keyword dicts)."""
        return [{}]

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params.items())
        return f"{type(self).__name__}({args})"


class RandomPolicy(Heuristic):
    """Tamp each section independently with probability ``p`` (a baseline); its own generator from ``seed``.

    Stateful (the generator): :meth:`reset` restarts it, so a reset policy replays the same actions.
    """

    name = "random"

    def __init__(self, p: float = 0.1, seed: int = 0) -> None:
        if not 0.0 <= p <= 1.0:
            raise ValueError(f"p must be in [0, 1], got {p!r}")
        super().__init__(p=float(p), seed=int(seed))
        self.reset()

    def reset(self) -> None:
        self._rng = np.random.default_rng(self.params["seed"])

    def _act(self, obs):
        return self._rng.random(obs["section_sd"].shape) < self.params["p"]

    @classmethod
    def param_grid(cls):
        return [{"p": p, "seed": 0} for p in (0.02, 0.05, 0.1)]
