"""Rules a railway would use on TampingLine, with SB3's ``predict`` (batched observation dicts).

All act on what the planner observes (measured SD, register, years since tamping, time) and respect the
possession capacity themselves, worst measured SD first, so the env never has to clip them:

* :class:`UniformPeriodic` — the whole line every ``interval_years`` (in capacity-sized campaigns on
  consecutive steps);
* :class:`SectionThreshold` — each section when its measured SD reaches ``threshold_mm``;
* :class:`GroupedThreshold` — a campaign is called when a section reaches ``trigger_mm``; it then takes every
  section above ``include_mm`` (opportunistic grouping, Soleimanmeigouni et al. 2021);
* :class:`RegisterPeriodic` — plain track every ``plain_years``, known zones (register) every ``zone_years``;
* :class:`BudgetedWorstFirst` — every ``every_years`` a campaign of the ``n_worst`` worst sections above
  ``min_sd_mm``.

:func:`hindsight_bound` is the per-section hindsight search (see there).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from .heuristics import Heuristic, _as_batch

__all__ = ["BudgetedWorstFirst", "GroupedThreshold", "LINE_HEURISTICS", "RegisterPeriodic", "SectionThreshold",
           "UniformPeriodic", "LineNoMaintenance", "hindsight_bound", "LINE_TUNED_FILE", "line_tuned_params"]


def _keep_worst(want: np.ndarray, score: np.ndarray, k: int) -> np.ndarray:
    s = np.where(want, score, -np.inf)
    order = np.argsort(-s, axis=1, kind="stable")
    rank = np.argsort(order, axis=1)
    return want & (rank < k)


class LineHeuristic(Heuristic):
    """Base: knows the line's calendar and capacity once bound to its config."""

    def __init__(self, steps_per_year: int = 4, horizon_steps: int = 40, capacity: int = 6, **params: Any) -> None:
        super().__init__(**params)
        self.steps_per_year = int(steps_per_year)
        self.horizon_steps = int(horizon_steps)
        self.capacity = int(capacity)

    def bind(self, config: Any) -> LineHeuristic:
        return type(self)(**self.params, steps_per_year=config.steps_per_year,
                          horizon_steps=config.horizon_steps, capacity=config.capacity)

    def _step(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        return np.rint(obs["time"][:, 0].astype(float) * self.horizon_steps).astype(int)

    def _steps(self, years: float) -> int:
        return max(int(round(years * self.steps_per_year)), 1)

    def _cap(self, want: np.ndarray, obs: dict[str, np.ndarray]) -> np.ndarray:
        return _keep_worst(want, obs["section_sd"], self.capacity)

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        b, batched = _as_batch(obs)
        act = np.asarray(self._cap(self._act(b), b), dtype=np.int8)
        return (act if batched else act[0]), state


class LineNoMaintenance(LineHeuristic):
    name: ClassVar[str] = "no-maintenance"

    def _act(self, obs):
        return np.zeros_like(obs["section_sd"], dtype=bool)


class UniformPeriodic(LineHeuristic):
    """The whole line every ``interval_years``: campaign i of a cycle tamps sections [i·k, (i+1)·k) (k the
    capacity) on consecutive steps, starting at ``offset_years`` into the episode."""

    name: ClassVar[str] = "uniform-periodic"

    def __init__(self, interval_years: float = 3.0, offset_years: float = 0.0, **kw: Any) -> None:
        super().__init__(interval_years=interval_years, offset_years=offset_years, **kw)

    def _act(self, obs):
        S = obs["section_sd"].shape[1]
        t = self._step(obs) - self._steps(self.params["offset_years"]) + 1
        phase = np.mod(t, self._steps(self.params["interval_years"]))
        chunk = np.arange(S) // self.capacity
        return (t[:, None] >= 0) & (chunk[None, :] == phase[:, None])

    @classmethod
    def param_grid(cls):
        return [{"interval_years": i, "offset_years": 0.0} for i in (2.0, 3.0, 4.0, 6.0)]


class SectionThreshold(LineHeuristic):
    name: ClassVar[str] = "section-threshold"

    def __init__(self, threshold_mm: float = 2.0, **kw: Any) -> None:
        super().__init__(threshold_mm=threshold_mm, **kw)

    def _act(self, obs):
        return obs["section_sd"] >= self.params["threshold_mm"]

    @classmethod
    def param_grid(cls):
        return [{"threshold_mm": v} for v in (1.5, 2.0, 2.5, 3.0)]


class GroupedThreshold(LineHeuristic):
    name: ClassVar[str] = "grouped-threshold"

    def __init__(self, trigger_mm: float = 2.5, include_mm: float = 1.5, **kw: Any) -> None:
        super().__init__(trigger_mm=trigger_mm, include_mm=include_mm, **kw)

    def _act(self, obs):
        sd = obs["section_sd"]
        call = (sd >= self.params["trigger_mm"]).any(axis=1, keepdims=True)
        return call & (sd >= min(self.params["include_mm"], self.params["trigger_mm"]))

    @classmethod
    def param_grid(cls):
        return [{"trigger_mm": t, "include_mm": i} for t, i in ((2.0, 1.25), (2.5, 1.5), (3.0, 1.5), (2.5, 1.0))]


class RegisterPeriodic(LineHeuristic):
    """Plain sections every ``plain_years``, known zones (register > 0) every ``zone_years``, each set in
    capacity-sized campaigns on consecutive steps."""

    name: ClassVar[str] = "register-periodic"

    def __init__(self, plain_years: float = 5.0, zone_years: float = 1.5, **kw: Any) -> None:
        super().__init__(plain_years=plain_years, zone_years=zone_years, **kw)

    def _act(self, obs):
        t = self._step(obs) + 1
        zone = obs["register"] > 0
        out = np.zeros_like(zone)
        for sel, years in ((~zone, self.params["plain_years"]), (zone, self.params["zone_years"])):
            rank = np.cumsum(sel, axis=1) - 1  # order of the section within its set
            phase = np.mod(t, self._steps(years))
            out |= sel & (rank // self.capacity == phase[:, None])
        return out

    @classmethod
    def param_grid(cls):
        return [{"plain_years": p, "zone_years": z} for p, z in ((6.0, 1.5), (6.0, 2.5), (10.0, 1.5), (10.0, 2.5))]


class BudgetedWorstFirst(LineHeuristic):
    name: ClassVar[str] = "budgeted-worst-first"

    def __init__(self, every_years: float = 1.0, n_worst: int = 3, min_sd_mm: float = 1.5, **kw: Any) -> None:
        super().__init__(every_years=every_years, n_worst=n_worst, min_sd_mm=min_sd_mm, **kw)

    def _act(self, obs):
        t = self._step(obs)
        due = (np.mod(t, self._steps(self.params["every_years"])) == 0)[:, None]
        want = due & (obs["section_sd"] >= self.params["min_sd_mm"])
        return _keep_worst(want, obs["section_sd"], int(self.params["n_worst"]))

    @classmethod
    def param_grid(cls):
        return [{"every_years": e, "n_worst": k, "min_sd_mm": m}
                for e, k, m in ((1.0, 2, 1.5), (1.0, 4, 1.5), (0.5, 2, 1.5), (1.0, 3, 2.0))]


LINE_HEURISTICS: dict[str, type[LineHeuristic]] = {
    c.name: c for c in (LineNoMaintenance, UniformPeriodic, SectionThreshold, GroupedThreshold, RegisterPeriodic,
                        BudgetedWorstFirst)
}


# ---------------------------------------------------------------------------------------------------------
# Per-section hindsight bound
# ---------------------------------------------------------------------------------------------------------
def _run_schedules(config: Any, seed: int, policies: list) -> tuple[np.ndarray, np.ndarray]:
    """Replay one episode (``seed``) once per policy, all in one batch. A policy is an (H, S) bool schedule
    (open loop) or a float threshold on the *true* SD [mm] (closed loop, hindsight). Returns per line and
    section the cost without possession (M, S) and the tamping schedule (M, H, S). Sections are physically
    independent, so a section's cost depends only on its own schedule."""
    from trackenv.envs.line_episode import LineBatch

    M, S, H = len(policies), config.n_sections, config.horizon_steps
    bt = LineBatch(config, M)
    bt.reset_lines(list(range(M)), [np.random.default_rng(seed) for _ in range(M)])
    cost = np.zeros((M, S))
    sched = np.zeros((M, H, S), dtype=bool)
    for t in range(H):
        want = np.zeros((M, S), dtype=bool)
        for m, p in enumerate(policies):
            want[m] = p[t] if isinstance(p, np.ndarray) else bt.sd[bt.rows(m)] * 1e3 >= p
        want &= bt.allowed()
        renew = (bt.count >= bt.tm.max_tampings_before_renewal).reshape(M, S) & want
        cost += want * config.section_tamping_cost + renew * config.section_renewal_cost
        bt.apply(want)
        bt.traffic()
        cost += bt.section_costs().reshape(M, S)
        sched[:, t] = want
    return cost, sched


def _total(choice: np.ndarray, cost: np.ndarray, sched: np.ndarray, config: Any) -> float:
    S = cost.shape[1]
    plan = sched[choice, :, np.arange(S)].T  # (H, S)
    per_step = plan.sum(axis=1)
    if (per_step > config.capacity).any():
        return np.inf
    return float(cost[choice, np.arange(S)].sum() + config.possession_cost * np.count_nonzero(per_step))


def _greedy(choice: np.ndarray, cost: np.ndarray, sched: np.ndarray, config: Any) -> tuple[np.ndarray, float]:
    """Coordinate descent over the sections' choices (exact totals: possession and capacity included)."""
    best = _total(choice, cost, sched, config)
    improved = True
    while improved:
        improved = False
        for j in range(cost.shape[1]):
            for m in range(cost.shape[0]):
                if m == choice[j]:
                    continue
                trial = choice.copy()
                trial[j] = m
                v = _total(trial, cost, sched, config)
                if v < best - 1e-9:
                    best, choice, improved = v, trial, True
    return choice, best


def _shifted(plan: np.ndarray, delta: int, gap: int) -> np.ndarray:
    """Each section's tampings moved by ``delta`` steps (clipped to the horizon; too-close repeats dropped)."""
    H = plan.shape[0]
    out = np.zeros_like(plan)
    for j in range(plan.shape[1]):
        last = -(10**6)
        for t in np.flatnonzero(plan[:, j]):
            u = min(max(t + delta, 0), H - 1)
            if u - last > gap:
                out[u, j] = True
                last = u
    return out


def hindsight_bound(config: Any, seed: int, base_schedule: np.ndarray,
                    thresholds_mm: tuple[float, ...] = (1.0, 1.5, 2.0, 2.5, 3.0, 4.0), rounds: int = 2,
                    extra_schedules: tuple = ()) -> dict:
    """A per-section schedule for one episode found with its future known: an upper bound on the best cost.

    The search: (1) candidate schedules per section from per-section thresholds on the *true* SD
    (``thresholds_mm``), the best rule's own schedule (``base_schedule``, (H, S) bool, feasible) and no
    tamping, all replayed on the same episode in one batch; coordinate descent picks one candidate per
    section with the exact total (per-section costs + possession per campaign step; schedules over the
    capacity rejected). (2) ``rounds`` of local search: each section's chosen tampings shifted by -2..+2
    steps (open loop, replayed in one batch), coordinate descent again. Sections are physically independent
    (each is its own segment), so the per-section costs are exact for any combination; the final schedule is
    replayed in the env as a check. Returns its cost, the schedule and the search's record."""
    from trackenv.envs.line import TampingLine

    gap = config.min_steps_between_tampings
    cands: list = [base_schedule.astype(bool), np.zeros_like(base_schedule, dtype=bool),
                   *(np.asarray(x, dtype=bool) for x in extra_schedules), *thresholds_mm]
    cost, sched = _run_schedules(config, seed, cands)
    choice, best = _greedy(np.zeros(config.n_sections, dtype=int), cost, sched, config)
    record = [best]
    for _ in range(rounds):
        plan = sched[choice, :, np.arange(config.n_sections)].T
        shifts = [_shifted(plan, d, gap) for d in (-2, -1, 1, 2)]
        c2, s2 = _run_schedules(config, seed, shifts)
        cost = np.concatenate([cost[choice, np.arange(config.n_sections)][None], c2])
        sched = np.concatenate([plan[None], s2])
        choice, best = _greedy(np.zeros(config.n_sections, dtype=int), cost, sched, config)
        record.append(best)
    plan = sched[choice, :, np.arange(config.n_sections)].T
    env = TampingLine(config)
    env.reset(seed=seed)
    replay = 0.0
    for t in range(config.horizon_steps):
        _, r, _, _, _ = env.step(plan[t].astype(np.int8))
        replay -= r
    return {"cost": best, "replayed_cost": replay, "schedule": plan, "search": record}


#: the line heuristics' parameters tuned on training seeds by experiments/line_room.py --save-tuned
LINE_TUNED_FILE = Path(__file__).resolve().parent / "line_tuned_heuristics.json"


def line_tuned_params(path: str | Path | None = None) -> dict[str, dict[str, Any]]:
    """The shipped tuned parameters by heuristic name ({} when none were saved)."""
    p = Path(path) if path is not None else LINE_TUNED_FILE
    return json.loads(p.read_text())["params"] if p.exists() else {}
