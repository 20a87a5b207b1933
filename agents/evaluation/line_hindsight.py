"""The per-section hindsight bound of TampingLine: the cheapest schedule a search finds for an episode whose
future (every draw of the seed: wet-spot onsets, tamping residuals, measurement errors) it knows.

Why a per-section search can be exact: the sections of a line are physically independent (each is its own
segment), so a section's own costs (geometry, speed restriction, immediate action, tamping, renewal) depend only
on its own schedule; the only coupling is the possession cost, paid once per campaign step, and the capacity.
Any mix of per-section schedules can therefore be priced exactly from per-section replays
(:func:`replay_sections`), and the cheapest pick of one candidate schedule per section, with the shared
possessions and the capacity, is a small integer program solved exactly (:func:`_select`).

The replays are cheap where candidates share a past: a candidate is a fork of the trajectory it agrees with
longest and runs its own passes only from the step where its decision differs (:func:`replay_sections`), and the
candidates of many episodes run in one batch (:func:`hindsight_bounds`). Bit for bit the same numbers as
replaying each from the start (tested).

The search (:func:`hindsight_bounds`, per episode):

1. **Closed-loop candidates on the true state** (:class:`TrueStateRule`): tamp a section when its *true* SD
   reaches a threshold, or its true D1 mean-to-peak a fraction of the intervention limit (a guard against speed
   restrictions), and not in the last ``stop_steps`` steps (the horizon truncates the episode, so a tamping
   whose benefit falls after it is wasted); plus the given rule's own schedule and no tamping. All are replayed in
   one batch; the selection picks one per section. Optionally (``extra_schedules``) the schedules the
   tuned rules apply when the same episode is *recorded more often or without error*
   (:func:`recorded_rule_schedules`): a planner who knows the true state can act as any rule that measured it.
   The recording design changes nothing the physics or the costs see, so such a schedule is feasible on the
   episode and priced exactly like any other.
2. **Local search**, ``rounds`` times: each section's incumbent schedule varied one tamping at a time (the k-th
   tamping moved by ±1 or ±2 steps, moved to a campaign of the incumbent plan within 4 steps, or dropped; a
   tamping added one or two steps before the section's first speed restriction or at any campaign of the plan),
   each new variant a fork of the incumbent; then the exact selection over *every* candidate replayed so far
   (never worse than the incumbent). Joining a campaign costs no possession, so these moves are where a
   per-section plan gains over a whole-line rule; the integer program moves several sections at once (it can
   empty a campaign), which a one-section-at-a-time descent cannot.

**The choices** (``action_type="choices"`` configs that enable more than tamping): a schedule is then a
sequence of per-step choice codes (:data:`~trackenv.envs.choices.CHOICES`) instead of tamp-or-wait, replayed
through the engine's per-section entry (:meth:`~trackenv.envs.line_episode.LineBatch.work_rows`). The
closed-loop candidates add what clairvoyance makes obvious (:class:`TrueStateRule`, :func:`choice_rules`):
drainage of a section with a wet spot at the first step it may get work, or at the spot's onset (the planner
knows where the spots are and when they start); spot tamping where the true D1 mean-to-peak is high while the SD
is still below the tamping threshold; a renewal instead of a tamping once the section has had a given number of
tampings since its last. Inspections and surveys change only what a planner sees, never the track or its costs,
so a planner that knows the truth gains nothing from them: the bound never buys them (a given schedule that
does is also offered without them). The local search also swaps one track-work choice for another (tamp, spot
tamp, renew) and adds spot tampings where it adds tampings. The selection counts each choice's **work**
(``config.choice_work``) against the capacity and pays the possession in a step with any track work. On a
tamping-only config every candidate, move and selection is the tamping-only one: the same bounds, bit for bit.

It is a search, not an exact optimum, so the bound is an upper bound on the true hindsight optimum; the
final schedule is replayed in the env as a check of the pricing.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from trackenv.envs.choices import (
    CHOICES,
    DRAINAGE,
    INSPECT,
    IS_TRACK_WORK,
    NOTHING,
    RENEW,
    SPOT_TAMP,
    SURVEY,
    TAMP,
    action_type_for,
    code,
    enabled_codes,
    spot_only_steps,
    work_on_sections,
    work_per_code,
)

__all__ = ["DRAINAGE_TIMINGS", "RECORDING_DESIGNS", "TrueStateRule", "choice_rules", "hindsight_bound",
           "hindsight_bounds", "recorded_rule_schedules", "replay", "replay_schedule_parts", "replay_schedules",
           "replay_sections", "room_summary", "saved_schedules", "schedule_from_rows", "schedule_rows"]

#: Recording designs whose rule schedules :func:`recorded_rule_schedules` offers as hindsight candidates: every
#: step without error, and twice and once a year with the config's errors.
RECORDING_DESIGNS: tuple[dict[str, Any], ...] = (
    {"measurement_interval": 1, "sd_noise_mm": 0.0, "peak_noise_mm": 0.0},
    {"measurement_interval": 2},
    {"measurement_interval": 4},
)
_RECORDING_FIELDS = frozenset({"measurement_interval", "sd_noise_mm", "peak_noise_mm"})


LOOKING = (INSPECT, SURVEY)
#: When a clairvoyant rule drains a section with a wet spot: never, at the first step the section may get work, or
#: at the step the spot starts working (one already working: the first step the section may get work).
DRAINAGE_TIMINGS = ("never", "first", "onset")


@dataclass(frozen=True)
class TrueStateRule:
    """A closed-loop hindsight rule on the true state, except in the last ``stop_steps`` steps: tamp a section when
    its SD >= ``sd_mm`` or its D1 mean-to-peak >= ``peak_fraction`` × the intervention limit. With the choices:
    drain a section with a wet spot (``drainage``: one of :data:`DRAINAGE_TIMINGS`) before anything else; renew
    instead of tamping once it has had ``renew_count`` tampings since its last renewal; spot-tamp it when its
    mean-to-peak >= ``spot_peak_fraction`` × the limit and it is not due for tamping."""

    sd_mm: float = np.inf
    peak_fraction: float = np.inf
    stop_steps: int = 0
    drainage: str = "never"
    spot_peak_fraction: float = np.inf
    renew_count: float = np.inf

    def __post_init__(self) -> None:
        if self.drainage not in DRAINAGE_TIMINGS:
            raise ValueError(f"drainage must be one of {DRAINAGE_TIMINGS}, got {self.drainage!r}")

    @property
    def tamping_only(self) -> bool:
        """Whether the rule only tamps (its decisions are those of the tamping-only search)."""
        return self.drainage == "never" and self.spot_peak_fraction == np.inf and self.renew_count == np.inf

    def decide(self, t: int, horizon: int, sd_m: float, peak_m: float, limit_m: float, wet: bool = False,
               wet_working: bool = False, tampings_since_renewal: float = 0.0) -> int:
        """The choice code at step ``t`` of ``horizon`` for a section of true SD ``sd_m`` and mean-to-peak
        ``peak_m`` [m] (intervention limit ``limit_m``), with a wet spot (``wet``) that works in this step's
        traffic (``wet_working``), after ``tampings_since_renewal`` tampings."""
        if t >= horizon - self.stop_steps:
            return NOTHING
        if wet and (self.drainage == "first" or (self.drainage == "onset" and wet_working)):
            return DRAINAGE
        if sd_m * 1e3 >= self.sd_mm or peak_m >= self.peak_fraction * limit_m:
            return RENEW if tampings_since_renewal >= self.renew_count else TAMP
        if peak_m >= self.spot_peak_fraction * limit_m:
            return SPOT_TAMP
        return NOTHING


def choice_rules(config: Any, rules: list[TrueStateRule], drainage: tuple[str, ...] = ("first", "onset"),
                 spot_peak_fractions: tuple[float, ...] = (0.6,),
                 renew_counts: tuple[float, ...] = (5,)) -> list[TrueStateRule]:
    """``rules`` followed by their variants with the choices ``config`` enables besides tamping: each rule with
    each drainage timing (``drainage``, with "drainage"), with each spot-tamping fraction (``spot_peak_fractions``,
    with "spot_tamp") alone and with each drainage timing, and with each renewal count (``renew_counts``, with
    "renew"); ``rules`` alone on a tamping-only config. Inspections and surveys never: they change what a planner
    sees, not the track. (Not every combination: a spot-tamping variant forks on most sections, so each one costs
    a replay of most of the line; a drainage variant forks on the wet sections only.)"""
    from dataclasses import replace

    drains = tuple(drainage) if "drainage" in config.choices else ()
    spots = tuple(spot_peak_fractions) if "spot_tamp" in config.choices else ()
    renews = tuple(renew_counts) if "renew" in config.choices else ()
    combos = ([(d, np.inf, np.inf) for d in drains] + [(d, f, np.inf) for f in spots for d in ("never", *drains)]
              + [("never", np.inf, k) for k in renews])
    return list(rules) + [replace(rule, drainage=d, spot_peak_fraction=f, renew_count=k) for rule in rules
                          for d, f, k in combos]


def _apart(a: TrueStateRule, b: TrueStateRule) -> tuple[int, int]:
    """How far two rules are apart for prefix sharing: the fields other than the drainage timing that differ, then
    whether the timing differs (a drainage variant parts from its rule on a wet section only)."""
    other = sum(getattr(a, f) != getattr(b, f) for f in ("peak_fraction", "stop_steps", "spot_peak_fraction",
                                                          "renew_count"))
    return int(other), int(a.drainage != b.drainage)


def replay_sections(config: Any, candidates: list[tuple[int, int, Any]],
                    share_prefixes: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Replay every candidate (seed, section j, policy) on its episode, all in one batch of segments (so many
    episodes share the kernel's batch). A policy is an (H,) schedule of section j (open loop: choice codes, or
    bool for tamp-or-wait) or a :class:`TrueStateRule`. Returns per candidate the section's cost without
    possession (N,), the schedule actually applied (N, H int8 codes; choices the config does not enable and masked
    track work dropped) and the speed-restriction-or-worse flags (N, H).

    With ``share_prefixes`` (the default) candidates share their common past: each (episode, section)'s
    no-tamping trajectory is a root, every candidate follows a parent of its episode and section (an open-loop
    one: the earlier open-loop candidate with the longest common prefix; a closed-loop one: the earlier rule
    with the same SD threshold, else the root; a rule with choices: the nearest of those, preferably one apart
    only in its drainage timing) and is forked, a copy of the parent's segment
    (:meth:`~trackenv.envs.line_episode.LineBatch.copy_rows`), only at the first step where its decision
    differs. Until then it costs nothing. The numbers are those of replaying every candidate from the start
    (a segment's numbers do not depend on its batch; tested), at a fraction of the passes."""
    from trackenv.envs.line_episode import LineBatch

    S, H = config.n_sections, config.horizon_steps
    seeds = sorted({int(e) for e, _, _ in candidates})
    episode = {e: k for k, e in enumerate(seeds)}
    if any(not 0 <= j < S for _, j, _ in candidates):
        raise ValueError(f"candidate sections must lie in [0, {S}), got {sorted({j for _, j, _ in candidates})}")
    # the nodes: one root (no tamping) per episode and section, then the candidates, each with its parent node
    n_roots = len(seeds) * S
    zero = np.zeros(H, dtype=np.int8)
    policy: list[Any] = [zero] * n_roots + [p if isinstance(p, TrueStateRule) else np.asarray(p, dtype=np.int8)
                                            for _, _, p in candidates]
    key = list(range(n_roots)) + [episode[int(e)] * S + j for e, j, _ in candidates]  # (episode, section) index
    parent = list(range(n_roots)) + [-1] * len(candidates)  # a root is its own parent; -1: replayed from the start
    open_loop: list[list[int]] = [[k] for k in range(n_roots)]
    rules: list[list[int]] = [[] for _ in range(n_roots)]
    for i in range(n_roots, len(policy)):
        k, p = key[i], policy[i]
        if not share_prefixes:
            continue
        if isinstance(p, TrueStateRule):
            same = [m for m in rules[k] if policy[m].sd_mm == p.sd_mm]
            if same and not p.tamping_only:  # the nearest (ties: the last): a variant forks where it first differs
                same = [max(same, key=lambda m: (tuple(-a for a in _apart(policy[m], p)), m))]
            parent[i] = same[-1] if same else k
            rules[k].append(i)
        else:
            prefix = [int(np.argmax(np.append(policy[m] != p, True))) for m in open_loop[k]]
            parent[i] = open_loop[k][int(np.argmax(prefix))]
            open_loop[k].append(i)
    N = len(policy)
    starts = [i for i in range(N) if parent[i] in (-1, i)]  # the nodes replayed from the first step
    bt = LineBatch(config, -(-N // S))
    ref = LineBatch(config, len(seeds))
    ref.start(list(range(len(seeds))), [np.random.default_rng(e) for e in seeds])
    row = np.full(N, -1)
    row[starts] = np.arange(len(starts))
    bt.copy_rows(row[starts], ref, np.array(key)[starts])
    G = bt.n_lines * S
    acc, sched, restr = np.zeros(G), np.zeros((G, H), dtype=np.int8), np.zeros((G, H), dtype=bool)
    free = len(starts)
    limit = bt.section_limits("intervention_m")  # each section's, of its speed band
    enabled = enabled_codes(config.choices)
    with_choices = [p for p in policy if isinstance(p, TrueStateRule) and not p.tamping_only]
    needs_count = any(p.renew_count < np.inf for p in with_choices)
    host, want = np.zeros(N, dtype=int), np.zeros(N, dtype=np.int64)
    wet, working, count = np.zeros(G, dtype=bool), np.zeros(G, dtype=bool), np.zeros(G)
    for t in range(H):
        allowed = bt.allowed_rows(t)
        sd, peak = bt.true_quality()
        if with_choices:  # what clairvoyance knows of the wet spots, and the tampings since renewal
            wet, working = bt.wet_present(), bt.wet_working_rows(t).copy()
            if needs_count:
                count = bt.section_entries(slice(None), t)["tampings_since_renewal"].astype(float)
        for i in range(N):  # parents come before their children
            h = row[i] if row[i] >= 0 else host[parent[i]]
            p = policy[i]
            if isinstance(p, TrueStateRule):
                w = p.decide(t, H, sd[h], peak[h], limit[h], wet[h], working[h], count[h])
            else:
                w = int(p[t])
            if not enabled[w] or (IS_TRACK_WORK[w] and not allowed[h]):
                w = NOTHING
            if row[i] < 0 and w != want[parent[i]]:  # it parts from its parent: fork
                bt.copy_rows(np.array([free]), bt, np.array([h]))
                acc[free], sched[free], restr[free], allowed[free] = acc[h], sched[h], restr[h], allowed[h]
                sd[free], peak[free] = sd[h], peak[h]
                wet[free], working[free], count[free] = wet[h], working[h], count[h]
                row[i], h, free = free, free, free + 1
            host[i], want[i] = h, w
        owned = row >= 0
        codes = np.zeros(G, dtype=np.int64)
        codes[row[owned]] = want[owned]
        act = np.zeros(G, dtype=bool)
        act[row[owned]] = True
        acc += bt.choice_costs(codes)
        bt.work_rows(codes, t)
        bt.traffic_rows(act, t)
        acc[act] += bt.section_costs()[act]
        sched[act, t] = codes[act]
        restr[act, t] = bt.classify_rows(bt.true_quality()[1][act], act) >= 2
    out = host[n_roots:]
    return acc[out], sched[out], restr[out]


def replay(config: Any, seed: int, policy: Any) -> tuple[np.ndarray, float]:
    """Run episode ``seed`` of ``config`` in the env under ``policy``: an (H, S) schedule (choice codes, or bool:
    tamp), or a policy with SB3's ``predict`` bound to ``config``. Returns the choices the env applied (H, S) int8
    codes and the episode's cost (−Σ rewards, k€)."""
    from trackenv.envs.line import TampingLine

    env = TampingLine(config, action_type=action_type_for(config))
    obs, _ = env.reset(seed=seed)
    plan = np.zeros((config.horizon_steps, config.n_sections), dtype=np.int8)
    cost = 0.0
    for t in range(config.horizon_steps):
        action = policy[t].astype(np.int8) if isinstance(policy, np.ndarray) else policy.predict(obs)[0]
        obs, r, _, _, info = env.step(action)
        plan[t] = info["section_choices"]
        cost -= r
    return plan, cost


def recorded_rule_schedules(config: Any, seeds: list[int], policies: list,
                            designs: tuple[dict[str, Any], ...] = RECORDING_DESIGNS,
                            batch_size: int = 32) -> list[list[np.ndarray]]:
    """Per seed of ``seeds``, the (H, S) schedules that ``policies`` (SB3 ``predict``; line heuristics are bound
    to each config) apply on that episode of ``config`` recorded as each of ``designs`` (changes of
    ``measurement_interval``, ``sd_noise_mm``, ``peak_noise_mm`` only: what the planner sees, never the physics
    or the costs; the measurement errors are drawn as standard normals at reset whatever their size, so every
    design sees the same episode). All episodes of a design run batched (:func:`~.evaluation.evaluate_many`);
    designs equal to ``config``'s own recording are skipped."""
    from .harness import evaluate_many

    out: list[list[np.ndarray]] = [[] for _ in seeds]
    for design in designs:
        unknown = set(design) - _RECORDING_FIELDS
        if unknown:
            raise ValueError(f"designs may change only {sorted(_RECORDING_FIELDS)}, got {sorted(unknown)}")
        cfg = config.replace(**design)
        if cfg == config:
            continue
        for r in evaluate_many(policies, cfg, seeds, batch_size=batch_size):
            tamped = r.tamped
            assert tamped is not None  # evaluate_many records every step's tampings
            for k in range(len(seeds)):
                out[k].append(tamped[k])
    return out


def _total(plan: np.ndarray, section_cost: np.ndarray, config: Any) -> float:
    """Exact episode cost of a plan (H, S) of choice codes (bool: tamp) whose sections cost ``section_cost``
    (S,): their costs and a possession per step with track work (``spot_possession_share`` of it where the step's
    only track work is spot tamping); inf where a step's work exceeds the capacity."""
    codes = np.asarray(plan, dtype=np.int64)
    work = work_on_sections(work_per_code(config.choice_work), codes, config.length_factors[None, :])
    if (work.sum(axis=1) > config.capacity + 1e-9).any():
        return np.inf
    steps = np.count_nonzero(IS_TRACK_WORK[codes].any(axis=1))
    spot_only = np.count_nonzero(spot_only_steps(codes))
    return float(section_cost.sum() + config.possession_cost * (steps - spot_only
                                                                  + config.spot_possession_share * spot_only))


def _plan(options: list[list[tuple[np.ndarray, float]]], choice: np.ndarray) -> np.ndarray:
    """The (H, S) plan of ``choice`` (S,): option ``choice[j]`` of each section's ``options[j]``."""
    return np.stack([options[j][choice[j]][0] for j in range(len(options))], axis=1)


def _choice_total(options: list[list[tuple[np.ndarray, float]]], choice: np.ndarray, config: Any) -> float:
    """Exact episode cost (:func:`_total`) of ``choice`` over ``options``."""
    return _total(_plan(options, choice), np.array([options[j][choice[j]][1] for j in range(len(options))]), config)


def _select(options: list[list[tuple[np.ndarray, float]]], config: Any,
            incumbent: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """The cheapest pick of one option per section: ``options[j]`` is a list of (schedule (H,) of choice codes or
    bool, cost) of section j; the total is the sections' costs plus the possession cost of every step with track
    work, within the capacity (:func:`_total`). Solved exactly as a small integer program (HiGHS through
    :func:`scipy.optimize.milp`): binaries x[j, o] (section j takes option o, one per section) and y[t] (a
    campaign at step t) with Σ_j,o work[j, o, t]·x[j, o] <= capacity·y[t] (work: the choice's ``choice_work``,
    a tamping's and a renewal's scaled by the section's length;
    track work of no work counts 1e-9, so that it still needs the campaign). Returns the choice (S,) and its
    total; never worse than ``incumbent`` (a choice, e.g. the last one) if the solver stops before it proves the
    optimum. With a cheaper spot possession (``spot_possession_share`` < 1) a step may instead have a spot
    possession z[t] (y[t] + z[t] <= 1, at that share of the cost) whose work is spot tamping only."""
    from scipy.optimize import Bounds, LinearConstraint, milp
    from scipy.sparse import coo_array

    S, H = len(options), config.horizon_steps
    n = [len(o) for o in options]
    first = np.concatenate([[0], np.cumsum(n)])
    nx = int(first[-1])
    spot = config.spot_possession_share < 1.0
    P = H * (2 if spot else 1)  # possession variables: y (any work), then z (spot tamping only)
    c = np.concatenate([[cost for _, cost in o] for o in options] + [np.full(H, config.possession_cost)]
                       + ([np.full(H, config.spot_possession_share * config.possession_cost)] if spot else []))
    # one option per section
    rows = np.repeat(np.arange(S), n)
    pick = coo_array((np.ones(nx), (rows, np.arange(nx))), shape=(S, nx + P))
    # track work at step t needs a campaign at t, of at most capacity work
    codes = np.concatenate([np.stack([sched for sched, _ in o]) for o in options]).astype(np.int64)  # (nx, H)
    length = config.length_factors[rows][:, None]  # each option's section's
    per_code = np.where(IS_TRACK_WORK, np.maximum(work_per_code(config.choice_work), 1e-9), 0.0)
    work = work_on_sections(per_code, codes, length)

    def load(work: np.ndarray, possessions: tuple[int, ...]) -> coo_array:
        """Σ work·x − capacity · (the possession variables ``possessions`` of each step) <= 0, per step."""
        r, q = np.nonzero(work.T)
        steps = np.arange(H)
        return coo_array((np.concatenate([work.T[r, q], np.full(H * len(possessions), -float(config.capacity))]),
                          (np.concatenate([r, *(steps for _ in possessions)]),
                           np.concatenate([q, *(nx + k * H + steps for k in possessions)]))), shape=(H, nx + P))

    constraints = [LinearConstraint(pick, 1, 1)]
    if not spot:
        constraints.append(LinearConstraint(load(work, (0,)), -np.inf, 0))
    else:  # any work within a possession of either kind; work other than spot tamping within a full one
        full = work_on_sections(np.where(np.arange(per_code.size) == SPOT_TAMP, 0.0, per_code), codes, length)
        one = coo_array((np.ones(2 * H), (np.tile(np.arange(H), 2), nx + np.arange(2 * H))), shape=(H, nx + P))
        constraints += [LinearConstraint(load(work, (0, 1)), -np.inf, 0),
                        LinearConstraint(load(full, (0,)), -np.inf, 0), LinearConstraint(one, -np.inf, 1)]
    res = milp(c, integrality=np.ones(nx + P), bounds=Bounds(0, 1), constraints=constraints,
               options={"time_limit": 60.0})
    found = None
    if res.x is not None:
        x = res.x[:nx] > 0.5
        found = np.array([int(np.argmax(x[first[j]:first[j + 1]])) for j in range(S)])
    picks = [ch for ch in (found, incumbent) if ch is not None]
    if not picks:
        raise RuntimeError(f"the selection found no feasible choice ({res.message}) and has no incumbent")
    totals = [_choice_total(options, ch, config) for ch in picks]
    k = int(np.argmin(totals))
    return picks[k], totals[k]


def _variants(column: np.ndarray, restricted: np.ndarray, campaigns: np.ndarray | None = None,
              reach: int = 4, swaps: tuple[int, ...] = ()) -> list[np.ndarray]:
    """One section's schedule (H,) (choice codes, or bool: tamp) varied by one intervention: each moved by ±1/±2
    steps or dropped; a tamping added 1-2 steps before the first step under a speed restriction (``restricted``,
    (H,) bool). With ``campaigns`` (H,) bool (the steps where the line's plan has track work), also the moves
    that join a campaign, where the possession is paid anyway: each intervention moved to a campaign step within
    ``reach`` steps, and a tamping added at any campaign step. With ``swaps`` (choice codes, e.g. tamp, spot
    tamp, renew), also each intervention of one of them replaced by each other, and each added tamping added as
    each of them instead."""
    H = column.size
    out = []
    join = np.flatnonzero(campaigns) if campaigns is not None else np.zeros(0, dtype=int)
    for t in np.flatnonzero(column):
        moves = {t + d for d in (-2, -1, 1, 2)} | {int(u) for u in join if 0 < abs(int(u) - t) <= reach}
        for u in sorted(moves):
            if 0 <= u < H and not column[u]:
                v = column.copy()
                v[t], v[u] = 0, column[t]
                out.append(v)
        v = column.copy()
        v[t] = 0
        out.append(v)
    adds = {f - d for f in np.flatnonzero(restricted)[:1] for d in (1, 2)} | {int(u) for u in join}
    for u in sorted(adds):
        if 0 <= u < H and not column[u]:
            v = column.copy()
            v[u] = TAMP
            out.append(v)
    for t in np.flatnonzero(np.isin(column, swaps)) if swaps else ():
        for other in swaps:
            if other != column[t]:
                v = column.copy()
                v[t] = other
                out.append(v)
    for u in sorted(adds) if swaps else ():
        for other in swaps:
            if 0 <= u < H and not column[u] and other != TAMP:
                v = column.copy()
                v[u] = other
                out.append(v)
    unique: dict[bytes, np.ndarray] = {}
    for v in out:
        unique.setdefault(v.tobytes(), v)
    return list(unique.values())


def replay_schedules(config: Any, seeds: list[int], plans: list[np.ndarray]) -> np.ndarray:
    """Each (H, S) schedule of ``plans`` (choice codes, or bool: tamp) run on its episode of ``seeds`` in the env
    itself (one native vector env, NEXT_STEP autoreset); returns the episodes' costs (−Σ rewards, k€). The check
    of the per-section pricing."""
    return replay_schedule_parts(config, seeds, plans)[0]


def replay_schedule_parts(config: Any, seeds: list[int],
                          plans: list[np.ndarray]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """:func:`replay_schedules`, and each episode's cost split into the parts of ``info["costs"]`` (k€): where a
    schedule's cost goes."""
    from gymnasium.vector import AutoresetMode

    from trackenv.envs.line import TampingLineVectorEnv

    env = TampingLineVectorEnv(len(seeds), config, action_type=action_type_for(config),
                               autoreset_mode=AutoresetMode.NEXT_STEP)
    env.reset(seed=[int(s) for s in seeds])
    plans_ = np.stack([np.asarray(p, dtype=np.int8) for p in plans])
    cost = np.zeros(len(seeds))
    parts: dict[str, np.ndarray] = {}
    for t in range(config.horizon_steps):
        _, reward, _, _, info = env.step(plans_[:, t])
        cost -= reward
        for key, value in info["costs"].items():
            if not key.startswith("_"):  # (the vector env's mask of where an entry is set)
                parts[key] = parts.get(key, 0.0) + np.asarray(value, dtype=float)
    env.close()
    return cost, parts


class _Pool:
    """One (episode, section)'s replayed candidates: one option (applied schedule, cost) per distinct schedule
    the env applied, its restriction flags, and the requested schedules already replayed (never replayed
    twice)."""

    def __init__(self) -> None:
        self.options: list[tuple[np.ndarray, float]] = []
        self.flags: list[np.ndarray] = []
        self.index: dict[bytes, int] = {}
        self.asked: set[bytes] = set()

    def add(self, asked: Any, cost: float, sched: np.ndarray, restr: np.ndarray) -> int:
        """Record a replay; returns the index of its option."""
        if not isinstance(asked, TrueStateRule):
            self.asked.add(np.asarray(asked, dtype=np.int8).tobytes())
        key = sched.tobytes()
        if key not in self.index:
            self.index[key] = len(self.options)
            self.options.append((sched, float(cost)))
            self.flags.append(restr)
        return self.index[key]

    def new(self, schedules: list[np.ndarray]) -> list[np.ndarray]:
        """The schedules of ``schedules`` not yet replayed."""
        return [v for v in schedules if v.tobytes() not in self.asked and v.tobytes() not in self.index]


def hindsight_bounds(config: Any, episodes: list[tuple[int, np.ndarray, tuple]], rounds: int = 2,
                     sd_thresholds_mm: tuple[float, ...] = (1.5, 2.0, 2.5, 3.0, 4.0),
                     peak_fractions: tuple[float, ...] = (0.8, np.inf), stop_steps: tuple[int, ...] = (0, 4),
                     progress: bool = False, choice_search: dict[str, Any] | None = None) -> list[dict]:
    """The hindsight search of the module docstring on several episodes at once (each stage's replays of all
    episodes share one batch): ``episodes`` are (seed, base schedule (H, S): a feasible schedule, e.g. the best
    rule's, extra candidate schedules), schedules of choice codes or bool (tamp). On a config with choices
    besides tamping, the closed-loop rules are extended by :func:`choice_rules` (``choice_search``: its keyword
    arguments) and the local search swaps and adds the enabled track work (tamp, spot tamp, renew). Returns per
    episode {"seed", "cost", "replayed_cost", "schedule" ((H, S) int8 codes), "search" (the best total after
    each stage), "start_cost" (the base schedule's total), "options" (candidates replayed per section)}.

    Where sections share a physics segment (``sections_per_segment`` > 1) they cannot be priced apart: the search
    is then the whole-line one of :mod:`.line_hindsight_whole` (tamping only), in the same format."""
    from tqdm.auto import tqdm

    if config.sections_per_segment > 1:  # sections not separable: the whole-line search
        from .line_hindsight_whole import whole_line_bounds

        if choice_search is not None:
            raise ValueError("the whole-line hindsight search (sections sharing a segment) is tamping only: "
                             "choice_search must be None")
        return whole_line_bounds(config, episodes, rounds=rounds, sd_thresholds_mm=sd_thresholds_mm,
                                 peak_fractions=peak_fractions, stop_steps=stop_steps, progress=progress)
    S, H = config.n_sections, config.horizon_steps
    if config.annual_budget > 0:
        raise ValueError(f"the hindsight search prices sections independently and cannot keep an annual budget; "
                         f"annual_budget must be 0, got {config.annual_budget}")
    seeds = [int(e[0]) for e in episodes]
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"episodes must have distinct seeds, got {seeds}")
    rules = [TrueStateRule(s, p, k) for s in (*sd_thresholds_mm, np.inf) for p in peak_fractions for k in stop_steps
             if not (s == np.inf and p == np.inf)]
    rules = choice_rules(config, rules, **(choice_search or {}))
    swaps = tuple(code(n) for n in ("tamp", "spot_tamp", "renew") if n in config.choices)
    swaps = swaps if len(swaps) > 1 else ()
    bar = tqdm(total=rounds + 2, desc=f"hindsight x{len(seeds)}", disable=not progress)
    pools = [[_Pool() for _ in range(S)] for _ in seeds]
    # (seed, section, schedule or rule); an episode's candidates start with its base schedule's S columns
    cands: list[tuple[int, int, Any]] = []
    firsts: list[int] = []
    for seed, base, extra in episodes:
        pols = [np.asarray(base, dtype=np.int8), np.zeros((H, S), dtype=np.int8),
                *(np.asarray(x, dtype=np.int8) for x in extra)]
        pols += [np.where(np.isin(p, LOOKING), NOTHING, p).astype(np.int8) for p in list(pols)
                 if np.isin(p, LOOKING).any()]  # looking changes nothing a clairvoyant planner needs
        firsts.append(len(cands))
        cands += [(seed, j, p[:, j]) for p in pols for j in range(S)] + [(seed, j, r) for r in rules for j in range(S)]
    cost, sched, restr = replay_sections(config, cands)
    e_of = {seed: e for e, seed in enumerate(seeds)}
    options_of = [[pool.options for pool in pools[e]] for e in range(len(seeds))]  # live views of the pools
    for i, (seed, j, p) in enumerate(cands):
        pools[e_of[seed]][j].add(p, cost[i], sched[i], restr[i])
    bar.update()
    choice, best, record, start = [], [], [], []
    for e in range(len(seeds)):
        base = np.array([pools[e][j].index[sched[firsts[e] + j].tobytes()] for j in range(S)])
        start.append(_choice_total(options_of[e], base, config))
        ch, b = _select(options_of[e], config, incumbent=base)
        choice.append(ch)
        best.append(b)
        record.append([b])
    for _ in range(rounds):
        # each section's incumbent varied (moves, drops, adds, joins of the plan's campaigns), the new variants
        # replayed as forks of the incumbent where they part from it; the selection then sees every option so far
        cands = []
        for e, seed in enumerate(seeds):
            campaigns = IS_TRACK_WORK[_plan(options_of[e], choice[e])].any(axis=1)
            for j in range(S):
                inc, flag = pools[e][j].options[choice[e][j]][0], pools[e][j].flags[choice[e][j]]
                var = pools[e][j].new(_variants(inc, flag, campaigns, swaps=swaps))
                if var:
                    cands += [(seed, j, inc)] + [(seed, j, v) for v in var]
        if cands:
            c2, s2, r2 = replay_sections(config, cands)
            for i, (seed, j, p) in enumerate(cands):
                pools[e_of[seed]][j].add(p, c2[i], s2[i], r2[i])
        for e in range(len(seeds)):
            choice[e], best[e] = _select(options_of[e], config, incumbent=choice[e])
            record[e].append(best[e])
        bar.update()
    plans = [_plan(options_of[e], choice[e]) for e in range(len(seeds))]
    replayed = replay_schedules(config, seeds, plans)
    bar.update()
    bar.close()
    return [{"seed": seed, "cost": best[e], "replayed_cost": float(replayed[e]), "schedule": plans[e],
             "search": record[e], "start_cost": start[e],
             "options": [len(pools[e][j].options) for j in range(S)]} for e, seed in enumerate(seeds)]


def hindsight_bound(config: Any, seed: int, base_schedule: np.ndarray, rounds: int = 2,
                    extra_schedules: tuple = (), **search: Any) -> dict:
    """:func:`hindsight_bounds` of one episode."""
    return hindsight_bounds(config, [(seed, base_schedule, tuple(extra_schedules))], rounds=rounds, **search)[0]


def schedule_rows(plan: np.ndarray) -> list[str]:
    """An (H, S) schedule of choice codes (bool: tamp) as H strings of S digits, each section's code ('0'/'1'
    on a tamping-only schedule; JSON for the results files; a later search can start from it)."""
    return ["".join(str(int(x)) for x in row) for row in np.asarray(plan, dtype=np.int64)]


_CODE_DIGITS = frozenset(str(i) for i in range(len(CHOICES)))


def schedule_from_rows(rows: list[str]) -> np.ndarray:
    """The (H, S) int8 schedule of choice codes of :func:`schedule_rows`' strings (ValueError on anything but
    equal-length rows of the digits of the codes)."""
    if not rows or len({len(r) for r in rows}) != 1 or any(set(r) - _CODE_DIGITS for r in rows):
        raise ValueError(f"a schedule is a non-empty list of equal-length strings of choice codes "
                         f"(digits 0-{len(CHOICES) - 1})")
    return np.array([[int(c) for c in r] for r in rows], dtype=np.int8)


def saved_schedules(paths: list[str | Path], config: Any) -> tuple[list[int], list[np.ndarray], list[float]]:
    """The cheapest saved hindsight schedule per episode over the search files ``paths`` (``line_room.py``
    results, their ``hindsight.episodes``; e.g. ``experiments/searches/line_room_milp_*.json``), each checked
    against ``config``'s (horizon_steps, n_sections): sorted seeds, their (H, S) schedules and their costs (k€,
    as replayed in the env when found). A search on another scenario is a ValueError."""
    import json

    best: dict[int, tuple[float, np.ndarray]] = {}
    for path in paths:
        payload = json.loads(Path(path).read_text())
        for e in payload.get("hindsight", {}).get("episodes", []):
            plan = schedule_from_rows(e["schedule"])
            if plan.shape != (config.horizon_steps, config.n_sections):
                raise ValueError(f"{path}: seed {e['seed']}'s schedule has shape {plan.shape}, the config needs "
                                 f"({config.horizon_steps}, {config.n_sections})")
            cost = float(e["replayed"])
            seed = int(e["seed"])
            if seed not in best or cost < best[seed][0]:
                best[seed] = (cost, plan)
    if not best:
        raise ValueError(f"no hindsight schedule in {[str(p) for p in paths]}")
    seeds = sorted(best)
    return seeds, [best[s][1] for s in seeds], [best[s][0] for s in seeds]


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
