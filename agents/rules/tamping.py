"""Rule-based tamping policies for the MultiBinary action space of ``trackenv/Tamping-v0``.

Every policy speaks stable-baselines3's ``predict(obs, state=None, episode_start=None, deterministic=True)
-> (action, state)``, as its models do, so one harness (:mod:`trackenv_agents.evaluation`) scores heuristics
and trained agents alike. ``obs`` is one observation dict (action shape ``(n_sections,)``) or a batched dict with
a leading env axis (``obs["time"].ndim == 2``; action shape ``(n_envs, n_sections)``). Actions are int8 0/1.

The policies are stateless: anything time-dependent is read from the observation (``time`` x horizon,
``tampings``), so the same object serves a whole batch of envs. Policies that need the planning calendar
(:class:`Periodic`, :class:`WorstFirst`) take ``horizon_years`` and ``steps_per_year``; :meth:`bind` returns a
copy with those set from a :class:`~trackenv.envs.config.TampingEnvConfig` (the evaluation harness calls it).

Each class has a ``name``, a ``params`` dict (its constructor arguments, JSON-friendly) and a
:meth:`param_grid` classmethod: the small grid that :func:`trackenv_agents.evaluation.tuning.tune` searches.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from trackenv.envs.wrappers import rank_mask

__all__ = [
    "HEURISTICS", "Campaign", "DefectThreshold", "Heuristic", "NoMaintenance", "Periodic", "RandomPolicy",
    "SDThreshold", "TUNED_PARAMS_FILE", "WorstFirst", "make_policy", "tuned_params",
]

# the parameters grid-tuned on training seeds that `trackenv evaluate` scores (experiments/tune_heuristics.py)
TUNED_PARAMS_FILE = Path(__file__).resolve().parent / "tuned_heuristics.json"

_DEFAULT_HORIZON_YEARS = 10.0
_DEFAULT_STEPS_PER_YEAR = 4


def _as_batch(obs: dict[str, Any]) -> tuple[dict[str, np.ndarray], bool]:
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
        b, batched = _as_batch(obs)
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


class _Calendar(Heuristic):
    """Mixin for policies that need the elapsed time in years and steps."""

    def __init__(self, horizon_years: float | None = None, steps_per_year: int | None = None,
                 **params: Any) -> None:
        super().__init__(**params)
        self.horizon_years = float(horizon_years) if horizon_years is not None else _DEFAULT_HORIZON_YEARS
        self.steps_per_year = int(steps_per_year) if steps_per_year is not None else _DEFAULT_STEPS_PER_YEAR

    def bind(self, config: Any) -> Heuristic:
        return type(self)(**self.params, horizon_years=config.horizon_years,
                          steps_per_year=config.steps_per_year)

    def _step_index(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(n_envs,) the step about to be taken, 0 at the start of an episode."""
        t = obs["time"][:, 0].astype(float)
        return np.rint(t * self.horizon_years * self.steps_per_year).astype(int)


class NoMaintenance(Heuristic):
    """Never tamp: the do-nothing baseline."""

    name = "no_maintenance"

    def __init__(self) -> None:
        super().__init__()

    def _act(self, obs):
        return np.zeros(obs["section_sd"].shape, dtype=bool)


class Periodic(_Calendar):
    """Tamp every ``interval_years`` years (at the steps k·interval, k >= 1; never at the start).

    ``sections="all"`` tamps every section; ``"worst"`` the ``n_worst`` sections with the highest SD
    (``n_worst`` is in ``params`` only then).
    """

    name = "periodic"

    def __init__(self, interval_years: float = 2.0, sections: str = "all", n_worst: int = 2,
                 horizon_years: float | None = None, steps_per_year: int | None = None) -> None:
        if not interval_years > 0:
            raise ValueError(f"interval_years must be > 0, got {interval_years!r}")
        if sections not in ("all", "worst"):
            raise ValueError(f"sections must be 'all' or 'worst', got {sections!r}")
        if int(n_worst) < 1:
            raise ValueError(f"n_worst must be >= 1, got {n_worst!r}")
        # n_worst only where it applies, so that a policy's params (and the tables that show them) never list
        # a parameter that does nothing (sections="all" tamps every section)
        worst = {"n_worst": int(n_worst)} if sections == "worst" else {}
        super().__init__(horizon_years, steps_per_year, interval_years=float(interval_years),
                         sections=sections, **worst)

    @property
    def interval_steps(self) -> int:
        return max(1, int(round(self.params["interval_years"] * self.steps_per_year)))

    def _act(self, obs):
        k = self._step_index(obs)
        due = (k > 0) & (k % self.interval_steps == 0)
        sd = obs["section_sd"]
        if self.params["sections"] == "all":
            return np.repeat(due[:, None], sd.shape[1], axis=1)
        n = np.where(due, self.params["n_worst"], 0)
        return rank_mask(sd, np.ones(sd.shape, dtype=bool), n)

    @classmethod
    def param_grid(cls):
        return ([{"interval_years": y, "sections": "all"} for y in (2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0, 6.0, 7.0)]
                + [{"interval_years": y, "sections": "worst", "n_worst": 2} for y in (1.0, 2.0, 4.0)])


class SDThreshold(Heuristic):
    """Tamp every section whose SD of the D1 level reaches ``threshold_mm`` (condition-based)."""

    name = "sd_threshold"

    def __init__(self, threshold_mm: float = 1.5) -> None:
        super().__init__(threshold_mm=float(threshold_mm))

    def _act(self, obs):
        return obs["section_sd"] >= self.params["threshold_mm"]

    @classmethod
    def param_grid(cls):
        return [{"threshold_mm": v} for v in (1.6, 2.0, 2.4, 2.8, 3.2, 4.0)]


class DefectThreshold(Heuristic):
    """Tamp every section whose D1 mean-to-peak (isolated defect) reaches ``threshold_mm``."""

    name = "defect_threshold"

    def __init__(self, threshold_mm: float = 8.0) -> None:
        super().__init__(threshold_mm=float(threshold_mm))

    def _act(self, obs):
        return obs["section_peak"] >= self.params["threshold_mm"]

    @classmethod
    def param_grid(cls):
        return [{"threshold_mm": v} for v in (4.5, 6.0, 8.0, 10.0, 12.0, 15.0)]


class WorstFirst(_Calendar):
    """A yearly budget of ``budget_sections_per_year`` section tampings, spent on the worst sections (by SD)
    among those at or above ``threshold_mm``.

    Stateless budget: by the end of the step about to be taken the episode may have used
    ``floor(budget · elapsed_years)`` section tampings (``obs["tampings"]`` counts those done), and one step
    never spends more than ``ceil(budget / steps_per_year)``, so unspent budget carries over but cannot pile
    up into one large campaign.
    """

    name = "worst_first"

    def __init__(self, budget_sections_per_year: float = 2.0, threshold_mm: float = 1.2,
                 horizon_years: float | None = None, steps_per_year: int | None = None) -> None:
        if not budget_sections_per_year > 0:
            raise ValueError(f"budget_sections_per_year must be > 0, got {budget_sections_per_year!r}")
        super().__init__(horizon_years, steps_per_year,
                         budget_sections_per_year=float(budget_sections_per_year),
                         threshold_mm=float(threshold_mm))

    def _act(self, obs):
        budget = self.params["budget_sections_per_year"]
        k = self._step_index(obs)
        allowed_total = np.floor(budget * (k + 1) / self.steps_per_year + 1e-9)
        used = obs["tampings"].sum(axis=1)
        per_step = max(1, math.ceil(budget / self.steps_per_year - 1e-9))
        n = np.clip(allowed_total - used, 0, per_step).astype(int)
        sd = obs["section_sd"]
        return rank_mask(sd, sd >= self.params["threshold_mm"], n)

    @classmethod
    def param_grid(cls):
        return [{"budget_sections_per_year": b, "threshold_mm": t}
                for b in (0.5, 1.0, 2.0) for t in (1.6, 2.2, 2.8)]


class Campaign(_Calendar):
    """Condition-triggered campaign: when the worst section's SD reaches ``trigger_mm``, mobilise and tamp
    every section at or above ``include_mm`` (0 = the whole track), unless fewer than ``stop_years`` of the
    horizon remain (a late campaign's benefit falls mostly outside the planning horizon)."""

    name = "campaign"

    def __init__(self, trigger_mm: float = 3.0, include_mm: float = 0.0, stop_years: float = 1.0,
                 horizon_years: float | None = None, steps_per_year: int | None = None) -> None:
        if not trigger_mm > 0:
            raise ValueError(f"trigger_mm must be > 0, got {trigger_mm!r}")
        if not 0 <= include_mm <= trigger_mm:
            raise ValueError(f"include_mm must be in [0, trigger_mm={trigger_mm}], got {include_mm!r}")
        if not stop_years >= 0:
            raise ValueError(f"stop_years must be >= 0, got {stop_years!r}")
        super().__init__(horizon_years, steps_per_year, trigger_mm=float(trigger_mm),
                         include_mm=float(include_mm), stop_years=float(stop_years))

    def _act(self, obs):
        remaining_years = self.horizon_years - self._step_index(obs) / self.steps_per_year
        sd = obs["section_sd"]
        go = (sd.max(axis=1) >= self.params["trigger_mm"]) & (remaining_years > self.params["stop_years"])
        return go[:, None] & (sd >= self.params["include_mm"])

    @classmethod
    def param_grid(cls):
        return [{"trigger_mm": t, "include_mm": i, "stop_years": y}
                for t in (2.0, 2.5, 3.0) for i in (0.0, 1.5) for y in (1.0, 2.0)]


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


HEURISTICS: dict[str, type[Heuristic]] = {
    cls.name: cls
    for cls in (NoMaintenance, Periodic, SDThreshold, DefectThreshold, WorstFirst, Campaign, RandomPolicy)
}


def make_policy(name: str, **params: Any) -> Heuristic:
    """The heuristic registered as ``name`` (see :data:`HEURISTICS`) with ``params``."""
    try:
        cls = HEURISTICS[name]
    except KeyError:
        raise ValueError(f"unknown heuristic {name!r}; known: {sorted(HEURISTICS)}") from None
    return cls(**params)


def tuned_params(path: str | Path | None = None) -> dict[str, dict[str, Any]]:
    """The tuned parameters per heuristic name in ``path`` (default :data:`TUNED_PARAMS_FILE`)."""
    return json.loads(Path(path or TUNED_PARAMS_FILE).read_text())["best_params"]
