"""A model-predictive campaign planner for a line whose SD is measured every step without error (the 60 m track,
``trackenv/Tamping-v1``).

Every step it forecasts each section's SD over the rest of the horizon from what it has seen, prices every plan of
up to ``max_campaigns`` campaigns over the remaining steps (which sections each campaign tamps chosen per section,
at their cheapest), and tamps now where the cheapest plan's first campaign is now. It replans each step, so only
that first decision is ever carried out.

The forecast, per section: its SD grows linearly at the slope it showed over the last ``window_steps`` steps since
its last tamping (``prior_growth_mm_per_step`` before two observations); a tamping leaves
``tamped_sd_offset_mm + tamped_sd_slope`` × the SD before it, and the SD then grows ``regrowth_factor`` times as
fast (fresh ballast consolidates). With ``own_slope_weight`` > 0 a section's own tamping corrects its slope: once
the planner has seen one of its tampings, the slope moves that share of the way from the prior to what that
tamping did. Off by default: on the 60 m track what one tamping did does not tell what the next will do (the ratio
of SD after to SD before of a section's first and second tamping correlate at −0.2 over 72 sections, 12 training
episodes tamped whole at steps 8 and 24), while its growth does (0.99 between the growth after the two
tampings), so a learnt slope only adds noise. A campaign also takes the
neighbours of the sections it tamps whose SD is at least ``neighbour_mm``: the sections of the 60 m track share
one track, and a section left untamped beside a lifted one gets a step at their boundary, which the per-section
forecast does not see. The price of a plan is what the env charges for it within the horizon: the
possession per campaign, the tamping per section tamped, and each step's geometry cost of every section, quadratic
in its SD over the alert limit of its speed band. The forecast is uncertain, and the expected square of an
uncertain SD is its forecast's square plus the forecast error's variance: with ``forecast_error_mm_per_step`` σ >
0 the error grows by σ each step since the SD was last known (now, or a planned tamping, which sets the SD back
to what the model says), so a plan pays σ²k² more k steps out and a long interval without tamping costs more than
its mean forecast says. (The linear forecast's RMS error 16 steps ahead is about 0.19 mm under the grouped
threshold on training episodes, some 0.012 mm a step.) Costs after the horizon do not count, so the planner does
no work whose benefit comes too late, as the life-cycle cost asks. Speed restrictions and immediate actions are not
forecast (the 60 m track has none under the tuned rule or the hindsight schedules), nor is the mean-to-peak.

Why: on the 60 m track the cost is the geometry cost, quadratic in the SD, and the tuned grouped threshold waits
until a section's SD reaches its trigger; a plan that weighs the SD's squared growth against a campaign's fixed
price tamps at other times and not at the end of the horizon. The model's parameters were fitted to the grouped
threshold's tampings on training episodes (an SD after tamping of 0.06 + 0.44 × the SD before, regrowth 1.26 times
the growth before); the defaults are the slope, regrowth factor, neighbour SD, prior growth, own-slope weight and
forecast error that ``experiments/model_predictive.py`` chose on training episodes of the 60 m track (0.5, 1.26,
0.5 mm, 0.06 mm a step, 0 and 0.02 mm a step).

The planner reads the SD history it has been shown through SB3's ``state`` (the evaluation harness passes it back
each step and restarts it at ``episode_start``); called without a state it knows the current SD only and forecasts
at the prior growth. It is not a member of the tuned rule family (:data:`~.line.LINE_HEURISTICS`), so it is never
the reference that scores are normalised to.
"""

from __future__ import annotations

import itertools
import math
from typing import Any, ClassVar

import numpy as np

from trackenv.envs.line_config import LineConfig
from trackenv.physics._checks import check_int, check_scalar

from .base import as_batch
from .line import LineHeuristic

__all__ = ["MAX_PLANS", "ModelPredictive", "interval_square_sums"]

#: the most plans the planner prices in a step (max_campaigns = 3 over 40 steps: 10 701; 4 over 40: 102 091)
MAX_PLANS = 120_000
#: margin on the years since tamping (float32 in the observation) within which a section counts as tamped in the
#: step just run (one step's years)
_YEARS_TOLERANCE = 1e-3


def interval_square_sums(v: np.ndarray, h: np.ndarray, ref: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Σ over the steps τ = a … b − 1 of (v + h·(τ − ref))², element by element (0 where b ≤ a): the summed
    squared SD of a section whose SD at the end of step τ is v + h·(τ − ref), in closed form."""
    k0, k1 = a - ref, b - 1 - ref
    n = np.maximum(b - a, 0)
    s1 = np.where(n > 0, (k0 + k1) * n / 2.0, 0.0)

    def squares_to(k: np.ndarray) -> np.ndarray:
        return k * (k + 1) * (2 * k + 1) / 6.0

    s2 = np.where(n > 0, squares_to(k1) - squares_to(k0 - 1), 0.0)
    return n * v * v + 2.0 * v * h * s1 + h * h * s2


class ModelPredictive(LineHeuristic):
    """The model-predictive campaign planner (see the module docstring); bound to a config that measures every step
    without error (else ValueError)."""

    name: ClassVar[str] = "model-predictive"
    #: its recurrent state remembers only what it was shown (the SD history), never what it chose: a copy of a line
    #: may carry the state on and make other choices (the line forks of the policy iteration,
    #: :func:`~trackenv_agents.learning.line_counterfactual.line_forks`)
    observation_state: ClassVar[bool] = True

    def __init__(self, tamped_sd_slope: float = 0.5, tamped_sd_offset_mm: float = 0.06, regrowth_factor: float = 1.26,
                 window_steps: int = 4, prior_growth_mm_per_step: float = 0.06, max_campaigns: int = 3,
                 neighbour_mm: float = 0.5, own_slope_weight: float = 0.0,
                 forecast_error_mm_per_step: float = 0.02, **kw: Any) -> None:
        super().__init__(
            tamped_sd_slope=check_scalar("tamped_sd_slope", tamped_sd_slope, low=0.0, high=1.0),
            own_slope_weight=check_scalar("own_slope_weight", own_slope_weight, low=0.0, high=1.0),
            tamped_sd_offset_mm=check_scalar("tamped_sd_offset_mm", tamped_sd_offset_mm, low=0.0, high=5.0),
            regrowth_factor=check_scalar("regrowth_factor", regrowth_factor, low=0.1, high=10.0),
            window_steps=check_int("window_steps", window_steps, low=1, high=40),
            prior_growth_mm_per_step=check_scalar("prior_growth_mm_per_step", prior_growth_mm_per_step, low=0.0,
                                                  high=5.0),
            max_campaigns=check_int("max_campaigns", max_campaigns, low=1, high=4),
            neighbour_mm=check_scalar("neighbour_mm", neighbour_mm, low=0.0, high=100.0),
            forecast_error_mm_per_step=check_scalar("forecast_error_mm_per_step", forecast_error_mm_per_step,
                                                    low=0.0, high=1.0), **kw)
        self.costs: dict[str, Any] | None = None

    @staticmethod
    def unfit_for(config: Any) -> str | None:
        """Why the planner cannot plan ``config`` (None where it can): it needs a line whose SD is measured every
        step without error (the leaderboard asks it of every scenario, as of a trained baseline)."""
        if not isinstance(config, LineConfig):
            return f"config must be a LineConfig, got {type(config).__name__}"
        if config.measurement_interval != 1 or config.sd_noise_mm > 0.0:
            return ("needs an SD measured every step without error: model-predictive forecasts from it, and this "
                    f"config measures every {config.measurement_interval} steps with sd_noise_mm="
                    f"{config.sd_noise_mm} (measurement_interval must be 1 and sd_noise_mm 0)")
        return None

    def bind(self, config: Any) -> ModelPredictive:
        why = self.unfit_for(config)
        if why is not None:
            raise ValueError(why)
        bound = super().bind(config)
        assert isinstance(bound, ModelPredictive)
        factors = np.asarray(config.length_factors, dtype=float)
        alert = np.array([config.quality_limits.for_speed(v / 3.6).sd_alert_m
                          for v in config.section_values("speed_kmh")]) * 1e3
        bound.costs = {  # k€, as the env charges them
            "possession": float(config.possession_cost),
            "tamping": config.tamping_cost_per_m * config.section_length_m * factors,  # per section tamped
            # per mm² of SD per section and step
            "geometry": config.geometry_cost_per_section_year / config.steps_per_year * factors / alert ** 2,
        }
        bound._plans(config.horizon_steps)
        return bound

    def _plans(self, horizon_steps: int) -> None:
        """Every plan of at most ``max_campaigns`` campaign steps (sorted tuples, the empty plan first) as padded
        arrays, with each plan's sub-plans (what one section may take of its campaigns) by index."""
        m = self.params["max_campaigns"]
        count = sum(math.comb(horizon_steps, k) for k in range(m + 1))
        if count > MAX_PLANS:
            raise ValueError(f"max_campaigns={m} over a horizon of {horizon_steps} steps makes {count} plans, more "
                             f"than {MAX_PLANS} (fewer campaigns, or a shorter horizon)")
        plans = [()] + [p for k in range(1, m + 1) for p in itertools.combinations(range(horizon_steps), k)]
        index = {p: i for i, p in enumerate(plans)}
        self.plan_steps = np.full((len(plans), m), horizon_steps, dtype=np.int64)
        self.sub_plans = np.zeros((len(plans), 2 ** m), dtype=np.int64)  # padded with the empty plan (index 0)
        for i, p in enumerate(plans):
            self.plan_steps[i, :len(p)] = p
            subs = [index[tuple(x for j, x in enumerate(p) if bits >> j & 1)] for bits in range(2 ** len(p))]
            self.sub_plans[i, :len(subs)] = subs
        self.plan_sizes = np.array([len(p) for p in plans])

    def _growth(self, history: np.ndarray, since: np.ndarray) -> np.ndarray:
        """(batch, S) growth per step [mm]: the slope over the last observations since each section's tamping
        (at most ``window_steps`` steps), else the prior."""
        growth = np.full(since.shape, self.params["prior_growth_mm_per_step"])
        for k in range(1, min(self.params["window_steps"], history.shape[1] - 1) + 1):
            growth = np.where(np.minimum(since, self.params["window_steps"]) == k,
                              (history[:, -1] - history[:, -1 - k]) / k, growth)
        return np.maximum(growth, 0.0)

    def _section_costs(self, sd: np.ndarray, growth: np.ndarray, plans: np.ndarray, step: int,
                       slope: np.ndarray) -> np.ndarray:
        """(plans, S) each section's cost [k€] to the horizon if tamped at exactly the steps of each plan (``slope``:
        each section's SD after a tamping per mm of SD before)."""
        p, horizon = self.params, self.horizon_steps
        n_plans, n_sections = plans.shape[0], sd.size
        v = np.broadcast_to(sd, (n_plans, n_sections)).copy()  # the SD at the end of step ref
        h = np.broadcast_to(growth, (n_plans, n_sections)).copy()
        ref = np.full((n_plans, 1), step - 1)
        start = np.full((n_plans, 1), step)
        squares = np.zeros((n_plans, n_sections))
        error = p["forecast_error_mm_per_step"]
        for j in range(plans.shape[1] + 1):
            end = plans[:, j:j + 1] if j < plans.shape[1] else np.full((n_plans, 1), horizon)
            squares += interval_square_sums(v, h, ref, start, end)
            if error:  # the variance of an error grown by σ a step since the plan's last known SD: the same for
                # every section of a plan, (plans, 1) broadcast over them
                squares += interval_square_sums(np.zeros(1), np.full(1, error), ref, start, end)
            if j == plans.shape[1]:
                break
            tamped = end < horizon
            before = v + h * (end - 1 - ref)
            v = np.where(tamped, p["tamped_sd_offset_mm"] + slope * before, v)
            h = np.where(tamped, p["regrowth_factor"] * growth, h)
            ref = np.where(tamped, end - 1, ref)
            start = end  # a padded step (the horizon) leaves nothing after it to count
        assert self.costs is not None
        n_tampings = (plans < horizon).sum(axis=1, keepdims=True)
        return squares * self.costs["geometry"] + n_tampings * self.costs["tamping"]

    def plan(self, sd: np.ndarray, growth: np.ndarray, step: int,
             slope: np.ndarray | None = None) -> tuple[float, tuple[int, ...], list[tuple[int, ...]]]:
        """The cheapest plan for one line from ``step`` on, given each section's SD (S,) [mm] at the end of the
        step before, its growth per step [mm] and its SD after a tamping per mm before (``slope``; None: the
        ``tamped_sd_slope`` of every section): its forecast cost to the horizon [k€], its campaign steps, and per
        section the steps at which it is tamped."""
        assert self.costs is not None
        slope = np.full(sd.shape, self.params["tamped_sd_slope"]) if slope is None else slope
        horizon = self.horizon_steps
        live = np.flatnonzero(self.plan_steps[:, 0] >= step)  # the empty plan, and plans of the remaining steps
        position = np.full(len(self.plan_steps), -1)
        position[live] = np.arange(live.size)
        per_section = self._section_costs(sd, growth, self.plan_steps[live], step, slope)
        subs = position[self.sub_plans[live]]  # (plans, sub-plans): every sub-plan of a live plan is live
        options = per_section[subs]  # (plans, sub-plans, S)
        total = options.min(axis=1).sum(axis=1) + self.costs["possession"] * self.plan_sizes[live]
        best = int(total.argmin())
        taken = subs[best][options[best].argmin(axis=0)]  # per section, the sub-plan it takes

        def steps(k: int) -> tuple[int, ...]:
            return tuple(int(x) for x in self.plan_steps[live[k]] if x < horizon)

        return float(total[best]), steps(best), [steps(int(k)) for k in taken]

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        if self.costs is None:
            raise ValueError("bind the planner to its config first (ModelPredictive().bind(config))")
        b, batched = as_batch(obs)
        sd = np.asarray(b["section_sd"], dtype=float)
        years_since = np.asarray(b["years_since_tamping"], dtype=float)
        step = self._step(b)
        prior = self.params["tamped_sd_slope"]
        if state is None or state[0].shape[0] != sd.shape[0]:  # a first step, or another batch: the SD of now only
            history, since, slope = sd[:, None], np.zeros(sd.shape, dtype=np.int64), np.full(sd.shape, prior)
        else:
            history, since, slope = state
            just = years_since <= 1.0 / self.steps_per_year + _YEARS_TOLERANCE
            # a section tamped in the step just run shows what a tamping did to it: its SD after over its SD before
            # (one step's growth included, so an overestimate) moves its own slope from the prior by own_slope_weight
            weight = self.params["own_slope_weight"]
            if weight > 0.0:
                seen = (sd - self.params["tamped_sd_offset_mm"]) / np.maximum(history[:, -1], 0.05)
                slope = np.where(just, weight * np.clip(seen, 0.0, 2.0) + (1.0 - weight) * prior, slope)
            keep = self.params["window_steps"]
            history = np.concatenate([history, sd[:, None]], axis=1)[:, -(keep + 1):]
            since = np.where(just, 0, since + 1)
            if episode_start is not None:  # a row whose episode starts now forgets the last one's sections
                start = np.asarray(episode_start, dtype=bool).reshape(-1, 1)
                since, slope = np.where(start, 0, since), np.where(start, prior, slope)
        growth = self._growth(history, since)
        want = np.array([[step[i] in tamped for tamped in self.plan(sd[i], growth[i], int(step[i]), slope[i])[2]]
                         for i in range(sd.shape[0])], dtype=bool)
        if self.params["neighbour_mm"] > 0.0:  # a campaign also takes the neighbours of its sections at this SD
            near = np.zeros_like(want)
            near[:, 1:] |= want[:, :-1]
            near[:, :-1] |= want[:, 1:]
            want |= near & (sd >= self.params["neighbour_mm"])
        act = np.asarray(self._cap(want, b), dtype=np.int8)
        return (act if batched else act[0]), (history, since, slope)
