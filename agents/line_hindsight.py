"""The per-section hindsight bound of TampingLine: the cheapest schedule a search finds for one episode whose
future (every draw of the seed: wet-spot onsets, tamping residuals, measurement errors) it knows.

Why a per-section search can be exact: the sections of a line are physically independent (each is its own
segment), so a section's own costs (geometry, speed restriction, immediate action, tamping, renewal) depend only
on its own schedule; the only coupling is the possession cost, paid once per campaign step, and the capacity.
Any mix of per-section schedules can therefore be priced exactly from per-section replays
(:func:`section_costs`), and a coordinate descent over the sections' candidate schedules
(:func:`_descend`) optimises the exact total.

The search (:func:`hindsight_bound`):

1. **Closed-loop candidates on the true state** (:class:`TrueStateRule`): tamp a section when its *true* SD
   reaches a threshold, or its true D1 mean-to-peak a fraction of the intervention limit (a guard against speed
   restrictions), and not in the last ``stop_steps`` steps (the horizon truncates the episode, so a tamping
   whose benefit falls after it is wasted); plus the given rule's own schedule and no tamping. All are replayed in
   one batch; coordinate descent picks one per section. Optionally (``extra_schedules``) the schedules the
   tuned rules apply when the same episode is *recorded more often or without error*
   (:func:`recorded_rule_schedules`): a planner who knows the true state can act as any rule that measured it.
   The recording design changes nothing the physics or the costs see, so such a schedule is feasible on the
   episode and priced exactly like any other.
2. **Local search**, ``rounds`` times: each section's incumbent schedule varied one tamping at a time (the k-th
   tamping moved by ±1 or ±2 steps or dropped; a tamping added one or two steps before the section's first
   speed restriction); the distinct variants of all sections packed
   into as few replayed lines as possible; coordinate descent again, started from the incumbent, so the cost never
   rises.

It is a search, not an exact optimum, so the bound is an upper bound on the true hindsight optimum; the
final schedule is replayed in the env as a check of the pricing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["RECORDING_DESIGNS", "TrueStateRule", "hindsight_bound", "recorded_rule_schedules", "replay",
           "room_summary", "schedule_rows", "section_costs"]

#: Recording designs whose rule schedules :func:`recorded_rule_schedules` offers as hindsight candidates: every
#: step without error, and twice and once a year with the config's errors.
RECORDING_DESIGNS: tuple[dict[str, Any], ...] = (
    {"measurement_interval": 1, "sd_noise_mm": 0.0, "peak_noise_mm": 0.0},
    {"measurement_interval": 2},
    {"measurement_interval": 4},
)
_RECORDING_FIELDS = frozenset({"measurement_interval", "sd_noise_mm", "peak_noise_mm"})


@dataclass(frozen=True)
class TrueStateRule:
    """A closed-loop hindsight rule on the true state: tamp a section when its SD >= ``sd_mm`` or its D1 mean-to-
    peak >= ``peak_fraction`` × the intervention limit, except in the last ``stop_steps`` steps."""

    sd_mm: float = np.inf
    peak_fraction: float = np.inf
    stop_steps: int = 0


def section_costs(config: Any, seed: int, policies: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Replay episode ``seed`` once per policy, all in one batch. A policy is an (H, S) bool schedule (open
    loop) or a :class:`TrueStateRule`. Returns per line and section the cost without possession (M, S), the
    tamping schedule actually applied (M, H, S; masked tampings dropped) and the speed-restriction-or-worse
    flags (M, H, S)."""
    from trackenv.envs.line_episode import LineBatch
    from trackenv.physics.geometry import classify

    M, S, H = len(policies), config.n_sections, config.horizon_steps
    bt = LineBatch(config, M)
    bt.reset_lines(list(range(M)), [np.random.default_rng(seed) for _ in range(M)])
    cost = np.zeros((M, S))
    sched = np.zeros((M, H, S), dtype=bool)
    restricted = np.zeros((M, H, S), dtype=bool)
    limit = bt.limits.intervention_m
    for t in range(H):
        want = np.zeros((M, S), dtype=bool)
        for m, p in enumerate(policies):
            if isinstance(p, TrueStateRule):
                r = bt.rows(m)
                want[m] = ((bt.sd[r] * 1e3 >= p.sd_mm) | (bt.peak[r] >= p.peak_fraction * limit)) & (
                    t < H - p.stop_steps)
            else:
                want[m] = p[t]
        want &= bt.allowed()
        renew = bt.renewing().reshape(M, S) & want
        cost += want * config.section_tamping_cost + renew * config.section_renewal_cost
        bt.apply(want)
        bt.traffic()
        cost += bt.section_costs().reshape(M, S)
        sched[:, t] = want
        restricted[:, t] = (classify(bt.peak, bt.limits) >= 2).reshape(M, S)
    return cost, sched, restricted


def replay(config: Any, seed: int, policy: Any) -> tuple[np.ndarray, float]:
    """Run episode ``seed`` of ``config`` in the env under ``policy``: an (H, S) bool schedule, or a policy with
    SB3's ``predict`` bound to ``config``. Returns the schedule the env applied (H, S) and the episode's cost
    (−Σ rewards, k€)."""
    from trackenv.envs.line import TampingLine

    env = TampingLine(config)
    obs, _ = env.reset(seed=seed)
    plan = np.zeros((config.horizon_steps, config.n_sections), dtype=bool)
    cost = 0.0
    for t in range(config.horizon_steps):
        action = policy[t].astype(np.int8) if isinstance(policy, np.ndarray) else policy.predict(obs)[0]
        obs, r, _, _, info = env.step(action)
        plan[t] = info["tamped_sections"]
        cost -= r
    return plan, cost


def recorded_rule_schedules(config: Any, seed: int, policies: list,
                            designs: tuple[dict[str, Any], ...] = RECORDING_DESIGNS) -> list[np.ndarray]:
    """The (H, S) schedules that ``policies`` (SB3 ``predict``; line heuristics are bound to each config) apply
    on episode ``seed`` of ``config`` recorded as each of ``designs`` (changes of ``measurement_interval``,
    ``sd_noise_mm``, ``peak_noise_mm`` only: what the planner sees, never the physics or the costs; the
    measurement errors are drawn as standard normals at reset whatever their size, so every design sees the same
    episode). One batched run per design; designs equal to ``config``'s own recording are skipped."""
    from .evaluation import _bound, _run_chunk, _vector_env

    out = []
    for design in designs:
        unknown = set(design) - _RECORDING_FIELDS
        if unknown:
            raise ValueError(f"designs may change only {sorted(_RECORDING_FIELDS)}, got {sorted(unknown)}")
        cfg = config.replace(**design)
        if cfg == config:
            continue
        env = _vector_env(len(policies), cfg, "multibinary")
        bound = [_bound(p, cfg) for p in policies]
        run = _run_chunk(env, [(i, seed) for i in range(len(policies))], bound, "multibinary", record=True)
        tamped = np.stack(run["traces"]["tamped"], axis=1).astype(bool)  # (P, H, S)
        out.extend(tamped)
    return out


def _total(plan: np.ndarray, section_cost: np.ndarray, config: Any) -> float:
    """Exact episode cost of a plan (H, S) whose sections cost ``section_cost`` (S,): inf over capacity."""
    per_step = plan.sum(axis=1)
    if (per_step > config.capacity).any():
        return np.inf
    return float(section_cost.sum() + config.possession_cost * np.count_nonzero(per_step))


def _descend(options: list[list[tuple[np.ndarray, float]]], choice: np.ndarray,
             config: Any) -> tuple[np.ndarray, float]:
    """Coordinate descent: per section j, ``options[j]`` is a list of (schedule (H,), cost) of which
    ``choice[j]`` is chosen; change one section at a time while the exact total falls."""
    S = len(options)

    def plan_of(ch):
        return np.stack([options[j][ch[j]][0] for j in range(S)], axis=1)

    def cost_of(ch):
        return np.array([options[j][ch[j]][1] for j in range(S)])

    best = _total(plan_of(choice), cost_of(choice), config)
    improved = True
    while improved:
        improved = False
        for j in range(S):
            for m in range(len(options[j])):
                if m == choice[j]:
                    continue
                trial = choice.copy()
                trial[j] = m
                v = _total(plan_of(trial), cost_of(trial), config)
                if v < best - 1e-9:
                    best, choice, improved = v, trial, True
    return choice, best


def _variants(column: np.ndarray, restricted: np.ndarray) -> list[np.ndarray]:
    """One section's schedule (H,) varied by one tamping: each moved by ±1/±2 steps or dropped; one added 1-2
    steps before the first step under a speed restriction (``restricted``, (H,) bool)."""
    H = column.size
    out = []
    for t in np.flatnonzero(column):
        for d in (-2, -1, 1, 2):
            u = t + d
            if 0 <= u < H and not column[u]:
                v = column.copy()
                v[t], v[u] = False, True
                out.append(v)
        v = column.copy()
        v[t] = False
        out.append(v)
    for f in np.flatnonzero(restricted)[:1]:
        for d in (1, 2):
            u = f - d
            if 0 <= u < H and not column[u]:
                v = column.copy()
                v[u] = True
                out.append(v)
    unique: dict[bytes, np.ndarray] = {}
    for v in out:
        unique.setdefault(v.tobytes(), v)
    return list(unique.values())


def hindsight_bound(config: Any, seed: int, base_schedule: np.ndarray, rounds: int = 2,
                    sd_thresholds_mm: tuple[float, ...] = (1.5, 2.0, 2.5, 3.0, 4.0),
                    peak_fractions: tuple[float, ...] = (0.8, np.inf), stop_steps: tuple[int, ...] = (0, 4),
                    extra_schedules: tuple = ()) -> dict:
    """The hindsight search of the module docstring on episode ``seed``, from ``base_schedule`` ((H, S) bool,
    a feasible schedule, e.g. the best rule's). Returns {"cost", "replayed_cost", "schedule", "search" (the
    best total after each stage), "start_cost" (the base schedule's total)}."""
    S, H = config.n_sections, config.horizon_steps
    rules = [TrueStateRule(s, p, k) for s in (*sd_thresholds_mm, np.inf) for p in peak_fractions for k in stop_steps
             if not (s == np.inf and p == np.inf)]
    cands = [np.asarray(base_schedule, dtype=bool), np.zeros((H, S), dtype=bool),
             *(np.asarray(x, dtype=bool) for x in extra_schedules), *rules]
    cost, sched, restr = section_costs(config, seed, cands)
    options = [[(sched[m, :, j], cost[m, j]) for m in range(len(cands))] for j in range(S)]
    start = _total(sched[0], cost[0], config)
    choice, best = _descend(options, np.zeros(S, dtype=int), config)
    record = [best]
    flags = [[restr[m, :, j] for m in range(len(cands))] for j in range(S)]
    for _ in range(rounds):
        # the incumbent and its per-section variants, packed: line m carries the m-th variant of every section
        inc = [options[j][choice[j]] for j in range(S)]
        inc_flag = [flags[j][choice[j]] for j in range(S)]
        var = [_variants(inc[j][0], inc_flag[j]) for j in range(S)]
        n_lines = max((len(v) for v in var), default=0)
        if n_lines == 0:
            break
        plans = np.zeros((n_lines, H, S), dtype=bool)
        for j in range(S):
            for m in range(n_lines):
                plans[m, :, j] = var[j][m] if m < len(var[j]) else inc[j][0]
        c2, s2, r2 = section_costs(config, seed, list(plans))
        options = [[inc[j]] + [(s2[m, :, j], c2[m, j]) for m in range(min(len(var[j]), n_lines))] for j in range(S)]
        flags = [[inc_flag[j]] + [r2[m, :, j] for m in range(min(len(var[j]), n_lines))] for j in range(S)]
        choice, best = _descend(options, np.zeros(S, dtype=int), config)
        record.append(best)
    plan = np.stack([options[j][choice[j]][0] for j in range(S)], axis=1)
    return {"cost": best, "replayed_cost": replay(config, seed, plan)[1], "schedule": plan, "search": record,
            "start_cost": start}


def schedule_rows(plan: np.ndarray) -> list[str]:
    """An (H, S) bool schedule as H strings of S '0'/'1' (JSON for the results files; a later search can start
    from it)."""
    return ["".join("1" if x else "0" for x in row) for row in np.asarray(plan, dtype=bool)]


def room_summary(rule_costs: dict[int, float], searches: list[dict]) -> dict:
    """Room to learn from hindsight searches: per episode of ``rule_costs`` (seed -> the best rule's cost) that
    any of ``searches`` ({"seed", "hindsight"} each) covers, the cheapest cost found (never above the rule's: its
    own schedule is always a candidate); the mean difference with its paired bootstrap CI, absolute and
    relative to the rule's mean."""
    from .statistics import bootstrap_ci

    best: dict[int, float] = {}
    for s in searches:
        seed = int(s["seed"])
        if seed in rule_costs:
            best[seed] = min(best.get(seed, np.inf), float(s["hindsight"]))
    if not best:
        raise ValueError("no search covers an episode of the rule's costs")
    seeds = sorted(best)
    r = np.array([rule_costs[s] for s in seeds], dtype=float)
    h = np.minimum([best[s] for s in seeds], r)
    diff = h - r
    lo, hi = bootstrap_ci(diff)
    mean_rule = float(r.mean())
    return {"n_episodes": len(seeds), "seeds": seeds, "rule_mean": mean_rule, "hindsight_mean": float(h.mean()),
            "mean_difference": float(diff.mean()), "ci_low": lo, "ci_high": hi,
            "relative": float(diff.mean()) / mean_rule, "relative_ci": [lo / mean_rule, hi / mean_rule],
            "per_episode_relative": [float(v) for v in diff / r]}
