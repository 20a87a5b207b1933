"""The hindsight bound of a line whose sections share a physics segment (``sections_per_segment`` > 1, e.g. the
60 m track ``"track60"``: one segment of six 10 m sections): the cheapest whole-line schedule a search finds for
an episode whose future it knows.

Why whole lines: where sections share a segment, a section's tamping lifts its neighbours' track too, so the
sections' costs are not separable and the per-section search of :mod:`.line_hindsight` (price each section
apart, then pick one schedule per section by an integer program) does not apply. Here a candidate is a schedule
of the **whole line**, an (H, S) tamp plan, and it is priced by replaying the whole line exactly: an episode is a
deterministic function of its seed and its actions (every random draw is made at reset), so a replay is the
env's own cost of that plan.

The replays are cheap where candidates share a past (:func:`replay_lines`): each episode's no-tamping line is a
root, every candidate follows a parent of its episode and is forked, an exact copy of the parent's line
(:meth:`~trackenv.envs.line_episode.LineBatch.get_state` / ``set_state``, physics and pre-drawn noise), only at
the first step where its decision differs; the candidates of many episodes step in one batch. Bit for bit the
numbers of replaying each candidate from the start (tested).

The search (:func:`whole_line_bounds`, per episode):

1. **Candidates**: the given schedules (the best rule's, the other tuned rules'), no tamping, and closed-loop
   campaign rules on the *true* state (:class:`TrueStateCampaignRule`): when the worst true SD of the line
   reaches a trigger (or a true D1 mean-to-peak a fraction of the intervention limit), tamp every section over an
   inclusion threshold, not in the last ``stop_steps`` steps.
2. **Local search**, ``rounds`` times, best improvement: every neighbour of the incumbent plan
   (:func:`campaign_variants`: a campaign moved by ±1/±2 steps (merged where it lands on another), dropped or
   merged with the next; one section's tamping moved, dropped, added before its first speed restriction or
   joined to a campaign (:func:`~.line_hindsight._variants`); a campaign of the whole line added at any step
   without one; a campaign of the newly restricted sections or of
   the whole line added at, or one or two steps before, each step where a section's speed restriction starts),
   each a fork of the incumbent where it parts from it; the cheapest replayed so far becomes the incumbent. It
   stops early where no neighbour is cheaper.

The given schedules are candidates, so the result is never above the cheapest of them (the best rule's own cost).
It is a search, not an exact optimum: the bound is an upper bound on the true hindsight optimum. The final
schedule is replayed in the env as a check of the pricing. Tamping only: a config with more choices than
tamping is refused (the 60 m track has none).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from trackenv.envs.choices import NOTHING, TAMP

from .line_hindsight import _variants, replay_schedules

__all__ = ["TrueStateCampaignRule", "campaign_variants", "replay_lines", "whole_line_bounds"]


@dataclass(frozen=True)
class TrueStateCampaignRule:
    """A closed-loop hindsight rule of the whole line on the true state, except in the last ``stop_steps`` steps:
    when the worst section's SD >= ``trigger_mm`` or a section's D1 mean-to-peak >= ``peak_fraction`` × its
    intervention limit, tamp every section whose SD >= ``include_mm`` (0: the whole line) and those that
    triggered."""

    trigger_mm: float
    include_mm: float = 0.0
    peak_fraction: float = np.inf
    stop_steps: int = 0

    def __post_init__(self) -> None:
        for name in ("trigger_mm", "include_mm", "peak_fraction"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if self.stop_steps < 0:
            raise ValueError(f"stop_steps must be >= 0, got {self.stop_steps!r}")

    def decide(self, t: int, horizon: int, sd_m: np.ndarray, peak_m: np.ndarray, limit_m: np.ndarray) -> np.ndarray:
        """The (S,) tamp codes at step ``t`` of ``horizon`` for a line of true SDs ``sd_m`` and mean-to-peaks
        ``peak_m`` (S,) [m] (intervention limits ``limit_m``)."""
        due = (sd_m * 1e3 >= self.trigger_mm) | (peak_m >= self.peak_fraction * limit_m)
        if t >= horizon - self.stop_steps or not due.any():
            return np.full(sd_m.shape, NOTHING, dtype=np.int64)
        return np.where(due | (sd_m * 1e3 >= self.include_mm), TAMP, NOTHING).astype(np.int64)


def _closeness(a: TrueStateCampaignRule, b: TrueStateCampaignRule) -> int:
    """How many fields two rules share (a rule forks from the closest earlier one: they part late, if at all)."""
    return sum(getattr(a, f.name) == getattr(b, f.name) for f in fields(a))


def _parents(seeds: list[int], candidates: list[tuple[int, Any]],
             shape: tuple[int, int]) -> tuple[list[Any], list[int], list[int]]:
    """The nodes of a replay: one root (no tamping) per episode, then the candidates; each node's policy, episode
    and parent (a root is its own parent). An open-loop candidate's parent is the earlier open-loop node of its
    episode with the longest common prefix, a rule's the earlier rule of its episode that shares most fields
    (else the root). ``shape``: a schedule's (H, S)."""
    episode = {e: k for k, e in enumerate(seeds)}
    policy: list[Any] = [np.full(shape, NOTHING, dtype=np.int64) for _ in seeds]
    of = list(range(len(seeds)))
    parent = list(range(len(seeds)))
    open_loop: list[list[int]] = [[k] for k in range(len(seeds))]
    rules: list[list[int]] = [[] for _ in seeds]
    for seed, p in candidates:
        i, k = len(policy), episode[int(seed)]
        if isinstance(p, TrueStateCampaignRule):
            near = max(rules[k], key=lambda m: _closeness(policy[m], p), default=k)
            parent.append(near)
            rules[k].append(i)
        else:
            p = np.asarray(p, dtype=np.int64)
            if p.shape != shape:
                raise ValueError(f"a schedule must have shape {shape} (steps, sections), got {p.shape}")
            prefix = [int(np.argmax(np.append((policy[m] != p).any(axis=1), True))) for m in open_loop[k]]
            parent.append(open_loop[k][int(np.argmax(prefix))])
            open_loop[k].append(i)
        policy.append(p)
        of.append(k)
    return policy, of, parent


def replay_lines(config: Any, candidates: list[tuple[int, Any]],
                 share_prefixes: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Replay every candidate (seed, policy) on its episode, whole lines, all in one batch. A policy is an (H, S)
    schedule (tamp codes or bool) or a :class:`TrueStateCampaignRule`. Returns per candidate the episode's cost
    (−Σ rewards, k€; (N,)), the codes the env carried out (N, H, S int8; over capacity it drops some) and the
    speed-restriction-or-worse flags of the sections after each step (N, H, S).

    With ``share_prefixes`` (the default) a candidate follows its parent (:func:`_parents`) and is forked, an
    exact copy of the parent's line, at the first step where its requested codes differ; without, every candidate
    is replayed from the first step. The numbers are the same (tested)."""
    from trackenv.envs.line_episode import LineBatch

    S, H = config.n_sections, config.horizon_steps
    seeds = sorted({int(e) for e, _ in candidates})
    policy, of, parent = _parents(seeds, candidates, (H, S))
    N = len(policy)
    if not share_prefixes:
        parent = [-1 if i >= len(seeds) else i for i in range(N)]
    starts = [i for i in range(N) if parent[i] in (-1, i)]  # the nodes replayed from the first step
    bt = LineBatch(config, N)
    row = np.full(N, -1)
    row[starts] = np.arange(len(starts))
    bt.start(list(range(len(starts))), [np.random.default_rng(seeds[of[i]]) for i in starts])
    cost, applied = np.zeros(N), np.zeros((N, H, S), dtype=np.int8)
    restricted = np.zeros((N, H, S), dtype=bool)
    free = len(starts)
    limit = bt.section_limits("intervention_m").reshape(N, S)
    host, want = np.zeros(N, dtype=int), np.zeros((N, S), dtype=np.int64)
    for t in range(H):
        sd, peak = (q.reshape(N, S) for q in bt.true_quality())
        for i in range(N):  # parents come before their children
            h = row[i] if row[i] >= 0 else host[parent[i]]
            p = policy[i]
            if isinstance(p, TrueStateCampaignRule):
                w = p.decide(t, H, sd[h], peak[h], limit[h])
            else:
                w = p[t]
            if row[i] < 0 and (w != want[parent[i]]).any():  # it parts from its parent: fork
                bt.set_state(free, bt.get_state(h))
                cost[free], applied[free], restricted[free] = cost[h], applied[h], restricted[h]
                sd[free], peak[free], limit[free] = sd[h], peak[h], limit[h]  # what its children decide on
                row[i], h, free = free, free, free + 1
            host[i], want[i] = h, w
        owned = row >= 0
        lines = np.sort(row[owned])
        codes = np.full((N, S), NOTHING, dtype=np.int64)
        codes[row[owned]] = want[owned]
        rewards, _, infos = bt.advance(codes, lines.tolist(), [])
        cost[lines] -= rewards[lines]
        flags = (bt.classify_rows(bt.true_quality()[1]) >= 2).reshape(N, S)
        for b in lines:
            applied[b, t] = infos[int(b)]["section_choices"]
            restricted[b, t] = flags[b]
    out = host[len(seeds):]
    return cost[out], applied[out], restricted[out]


def _tamp_codes(plan: np.ndarray) -> np.ndarray:
    """A tamp plan (tamp codes or bool) as int8 tamp codes."""
    return np.where(np.asarray(plan) != NOTHING, TAMP, NOTHING).astype(np.int8)


def campaign_variants(plan: np.ndarray, restricted: np.ndarray) -> list[np.ndarray]:
    """The neighbours of a whole-line tamp plan ``plan`` (H, S) whose sections were under a speed restriction or
    worse after the steps flagged in ``restricted`` (H, S): each campaign (a step with tamping) moved by ±1/±2
    steps (merged into a campaign it lands on), dropped, or merged with the next campaign at either's step; each
    section's schedule varied by one tamping (:func:`~.line_hindsight._variants`: moved, dropped, added before its
    first restriction, joined to a campaign); a campaign of the whole line added at any step without one; at each
    step where a section's restriction starts (after the step's
    traffic: a tamping at that step still prevents it), a campaign of the sections whose restriction starts there,
    or of the whole line, added at that step or one or two steps before (joined to a campaign there). Distinct,
    without ``plan``."""
    plan = _tamp_codes(plan)
    H, S = plan.shape
    out = []
    steps = np.flatnonzero(plan.any(axis=1))
    for k, t in enumerate(steps):
        for d in (-2, -1, 1, 2):
            if 0 <= t + d < H:
                v = plan.copy()
                v[t + d] = np.maximum(v[t + d], v[t])
                v[t] = NOTHING
                out.append(v)
        v = plan.copy()
        v[t] = NOTHING
        out.append(v)
        if k + 1 < len(steps):
            u = steps[k + 1]
            for at, gone in ((t, u), (u, t)):
                v = plan.copy()
                v[at] = np.maximum(plan[t], plan[u])
                v[gone] = NOTHING
                out.append(v)
    campaigns = np.asarray(plan.any(axis=1))
    for j in range(S):
        for column in _variants(plan[:, j], restricted[:, j], campaigns):
            v = plan.copy()
            v[:, j] = column
            out.append(v)
    for t in np.flatnonzero(~campaigns):  # a campaign of the whole line where there is none
        v = plan.copy()
        v[t] = TAMP
        out.append(v)
    onset = restricted & ~np.vstack([np.zeros((1, S), bool), restricted[:-1]])  # a section newly restricted
    for f in np.flatnonzero(onset.any(axis=1)):
        for d in (0, 1, 2):
            for sections in (onset[f], np.ones(S, bool)):
                if f - d >= 0:
                    v = plan.copy()
                    v[f - d] = np.where(sections, TAMP, v[f - d])
                    out.append(v)
    unique: dict[bytes, np.ndarray] = {plan.tobytes(): plan}
    for v in out:
        unique.setdefault(v.astype(np.int8).tobytes(), v.astype(np.int8))
    return list(unique.values())[1:]


def whole_line_bounds(config: Any, episodes: list[tuple[int, np.ndarray, tuple]], rounds: int = 2,
                      sd_thresholds_mm: tuple[float, ...] = (1.5, 2.0, 2.5, 3.0, 4.0),
                      include_mm: tuple[float, ...] = (0.0, 1.0, 1.5),
                      peak_fractions: tuple[float, ...] = (0.8, np.inf), stop_steps: tuple[int, ...] = (0, 4),
                      progress: bool = False) -> list[dict]:
    """The whole-line hindsight search of the module docstring on several episodes at once (each stage's replays
    of all episodes share one batch): ``episodes`` are (seed, base schedule (H, S), extra candidate schedules),
    tamp codes or bool. The closed-loop candidates: a :class:`TrueStateCampaignRule` per trigger of
    ``sd_thresholds_mm`` (and none: the peak guard alone), inclusion threshold of ``include_mm`` below it, peak
    fraction and stop. Returns per episode {"seed", "cost", "replayed_cost", "schedule" ((H, S) int8 codes),
    "search" (the best cost after each stage), "start_cost" (the base schedule's cost), "options" (distinct plans
    the env carried out, [n])}, the format of :func:`~.line_hindsight.hindsight_bounds`."""
    from tqdm.auto import tqdm

    if tuple(config.choices) != ("tamp",):
        raise ValueError(f"the whole-line hindsight search is tamping only; the config enables {config.choices}")
    seeds = [int(e[0]) for e in episodes]
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"episodes must have distinct seeds, got {seeds}")
    H, S = config.horizon_steps, config.n_sections
    rules = [TrueStateCampaignRule(s, i, p, k) for s in (*sd_thresholds_mm, np.inf) for i in include_mm
             for p in peak_fractions for k in stop_steps if i <= s and not (s == np.inf and p == np.inf)]
    bar = tqdm(total=rounds + 2, desc=f"whole-line hindsight x{len(seeds)}", disable=not progress)
    cands: list[tuple[int, Any]] = []
    for seed, base, extra in episodes:
        cands += [(seed, _tamp_codes(p)) for p in (base, np.zeros((H, S)), *extra)]
        cands += [(seed, r) for r in rules]
    cost, applied, restricted = replay_lines(config, cands)
    seen: list[dict[bytes, tuple[float, np.ndarray, np.ndarray]]] = [{} for _ in seeds]
    asked: list[set[bytes]] = [set() for _ in seeds]
    e_of = {seed: e for e, seed in enumerate(seeds)}

    def record(batch: list[tuple[int, Any]], c: np.ndarray, a: np.ndarray, r: np.ndarray) -> None:
        for n, (seed, p) in enumerate(batch):
            e = e_of[int(seed)]
            if isinstance(p, np.ndarray):
                asked[e].add(_tamp_codes(p).tobytes())
            seen[e].setdefault(a[n].tobytes(), (float(c[n]), a[n], r[n]))

    record(cands, cost, applied, restricted)
    first: dict[int, float] = {}
    for n, (seed, _) in enumerate(cands):
        first.setdefault(int(seed), float(cost[n]))  # each episode's first candidate: its base schedule

    def best(e: int) -> tuple[float, np.ndarray, np.ndarray]:
        return min(seen[e].values(), key=lambda x: x[0])

    record_cost = [[best(e)[0]] for e in range(len(seeds))]
    bar.update()
    for _ in range(rounds):
        batch: list[tuple[int, Any]] = []
        for e, seed in enumerate(seeds):
            _, plan, flags = best(e)
            var = [v for v in campaign_variants(plan, flags) if v.tobytes() not in asked[e]]
            if var and record_cost[e][-1] < (record_cost[e][-2] if len(record_cost[e]) > 1 else np.inf):
                batch += [(seed, plan)] + [(seed, v) for v in var]
        if batch:
            c2, a2, r2 = replay_lines(config, batch)
            record(batch, c2, a2, r2)
        for e in range(len(seeds)):
            record_cost[e].append(best(e)[0])
        bar.update()
    plans = [best(e)[1] for e in range(len(seeds))]
    replayed = replay_schedules(config, seeds, plans)
    bar.update()
    bar.close()
    return [{"seed": seed, "cost": record_cost[e][-1], "replayed_cost": float(replayed[e]), "schedule": plans[e],
             "search": record_cost[e], "start_cost": first[seed], "options": [len(seen[e])]}
            for e, seed in enumerate(seeds)]
