"""What a section's choice is worth: counterfactual replays of one section's other choice, on common random
numbers, for learning a TampingLine planner by policy improvement.

Why. A line's cost is almost a sum over its sections (each is its own physics segment; only the possession of
a campaign is shared), and an episode is a deterministic function of its seed and its actions. So the value of
one section's choice at one step can be *measured*: run a policy on the line, and at a step ``t`` fork one
section's segment, make the other choice, and let the same policy go on deciding for that section (the other
sections as they were) to the horizon. The difference of the two costs-to-go is one exact sample of the
advantage of tamping now over waiting, with the same future (wet-spot onsets, tamping residuals, measurement
errors) on both branches, so none of the noise of the other eleven sections and little of the section's own.
A learner fitted to prefer the cheaper choice in the states it sees is one step of approximate policy iteration
(the greedy improvement of the policy that generated the data; with the data of each new policy added, as
AggreVaTe does with an expert's cost-to-go).

:func:`section_counterfactuals` runs a policy on some episodes, forks the chosen (step, section) decisions and
prices both choices; the samples carry the features the learner sees
(:func:`trackenv_agents.learning.line_policy.section_features`). Costs are k€ from the step to the horizon: the
section's own (tamping or renewal, geometry, speed restriction, immediate action; ``info["section_costs"]``)
plus the possession wherever the section tamps in a step no other section of its line tamps (its marginal
possession). Approximation: the other sections keep what they did on the policy's run (a fork does not move
their campaigns), and a fork ignores the annual budget (the default line has none).

**With every choice** (a config whose action type is the choice codes,
:func:`~trackenv.envs.choices.action_type_for`) the decision priced is still the policy's tamping (a tamping or
a renewal) against its absence; the section's other choice in the fork is what the policy's advisor makes of
that (:func:`~trackenv_agents.learning.line_policy.compose_choices`: without the tamping, the rule's spot
tamping, inspection or survey stand), and decisions that the tamping does not change
(the rule drains the section either way) are not priced. Forks apply every choice as the env does (spot tamping,
drainage, surveys, inspections at the end of the step) and pay each its price. A policy with a recurrent state
per section (the choice rules' memory of their track work, (batch, k, S)) gets its own on each fork: the line's,
with the fork's section's own.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

__all__ = ["section_counterfactuals"]


def _query_rates(features: np.ndarray, names: Sequence[str], acted: np.ndarray, focus_rate: float,
                 other_rate: float) -> np.ndarray:
    """(E, S) probability of pricing each decision: ``focus_rate`` where the choice is in question (the policy
    tamps, or the section is a known zone, or its projected SD or peak is high), ``other_rate`` elsewhere (a
    plain section well within its limits: the learner still needs some of those)."""
    col = {n: i for i, n in enumerate(names)}
    x = features
    focus = (acted.astype(bool) | (x[..., col["plain"]] < 0.5) | (x[..., col["projected_sd_mm"]] * 2.0 >= 1.5)
             | (x[..., col["projected_peak_mm"]] * 10.0 >= 8.0))
    return np.where(focus, focus_rate, other_rate)


def section_counterfactuals(config: Any, seeds: Sequence[int], policy: Any, advisor: Any = None,
                            focus_rate: float = 0.5, other_rate: float = 0.1, seed: int = 0,
                            progress: Callable[[int], Any] | None = None) -> dict[str, np.ndarray]:
    """Run ``policy`` (SB3 ``predict`` on batched line observations, deterministic; bound to ``config``) on the
    episodes ``seeds`` of ``config`` (one batch), and price the other choice of a random subset of its decisions
    (each section and step that may be tamped, with probability ``focus_rate`` or ``other_rate``, see
    :func:`_query_rates`; drawn from ``seed``) by a fork continued under ``policy`` itself.

    Returns arrays over the priced decisions: ``features`` (N, F) as the learner sees the section then (with
    ``advisor``'s choice as the last feature, see :func:`~trackenv_agents.learning.line_policy.section_features`),
    ``q_tamp`` and ``q_wait`` (k€ to the horizon for tamping now and for not tamping, each then under
    ``policy``), ``acted`` (the policy's choice: it tamps), ``weight`` (1 / the probability of pricing it: sums
    over the samples estimate sums over every decision), ``seed``, ``step``, ``section``."""
    from gymnasium.vector import AutoresetMode

    from trackenv.envs.choices import INSPECT, IS_TRACK_WORK, NOTHING, TAMP, action_type_for
    from trackenv.envs.line import TampingLineVectorEnv
    from trackenv.envs.line_episode import LineBatch

    from ..evaluation.harness import _bound
    from ..rules.choices import choice_view, remember_work
    from .line_policy import FEATURES, compose_choices, section_features, tamping_codes

    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("seeds must not be empty")
    for name, rate in (("focus_rate", focus_rate), ("other_rate", other_rate)):
        if not 0.0 < rate <= 1.0:
            raise ValueError(f"{name} must be in (0, 1], got {rate!r}")
    c = config
    E, S, H = len(seeds), c.n_sections, c.horizon_steps
    policy = _bound(policy, c)
    advisor = None if advisor is None else _bound(advisor, c)
    names = [n for n, _ in FEATURES]
    rng = np.random.default_rng(seed)
    env = TampingLineVectorEnv(E, c, autoreset_mode=AutoresetMode.NEXT_STEP, action_type=action_type_for(c))
    obs, _ = env.reset(seed=seeds)
    base = env.batch
    forks = LineBatch(c, E * H)  # room for every decision of every episode to be priced
    n_forks = 0
    f_line, f_sec, f_step, f_first = (np.zeros(E * H * S, dtype=np.int64) for _ in range(4))
    f_cost = np.zeros(E * H * S)
    f_memory: np.ndarray | None = None  # each fork's own recurrent state of its section (a policy with one)
    state: Any = None
    base_cost = np.zeros((H, E, S))  # the policy's own run, per step and section (marginal possession)
    samples: dict[str, list] = {k: [] for k in ("features", "acted", "weight", "row", "valid")}
    for t in range(H):
        start = np.full(E, t == 0)
        before = state
        codes, state = policy.predict(obs, state=before, episode_start=start)
        codes = np.asarray(codes, dtype=np.int64).reshape(E, S)
        per_section = isinstance(state, np.ndarray) and state.ndim == 3 and state.shape[::2] == (E, S)
        if per_section and f_memory is None:
            f_memory = np.zeros((E * H * S, state.shape[1]))
        acted = tamping_codes(codes)
        advice = None if advisor is None else np.asarray(
            advisor.predict(obs, state=before, episode_start=start)[0], dtype=np.int64).reshape(E, S)
        other = np.where(acted, NOTHING, TAMP) if advice is None else compose_choices(~acted, advice)
        allowed = base.allowed().reshape(E, S)
        feats = section_features(obs, advisor, advice)
        rate = _query_rates(feats, names, acted, focus_rate, other_rate)
        ask = allowed & (other != codes) & (rng.random((E, S)) < rate)
        # forks of this step: copies of the sections as they are now, making the other choice
        b_new, j_new = np.nonzero(ask)
        new = np.arange(n_forks, n_forks + b_new.size)
        forks.copy_rows(new, base, b_new * S + j_new)
        f_line[new], f_sec[new], f_step[new] = b_new, j_new, t
        f_first[new] = other[b_new, j_new]
        if f_memory is not None and b_new.size:
            own = (np.full((b_new.size, f_memory.shape[1]), -np.inf) if before is None
                   else np.asarray(before)[b_new, :, j_new])
            peak = choice_view(obs)["section_peak"][b_new, j_new]
            f_memory[new] = remember_work(own[..., None], other[b_new, j_new, None], t, peak[:, None])[..., 0]
        samples["features"].append(feats[b_new, j_new])
        samples["acted"].append(acted[b_new, j_new])
        samples["weight"].append(1.0 / rate[b_new, j_new])
        samples["row"].append(new)
        n_forks += b_new.size
        live = np.arange(n_forks)
        # every fork's choice now: its first one, or the policy's on the line as it is with the fork's section
        fork_codes = np.zeros(forks.n_lines * S, dtype=np.int64)
        fork_codes[new] = f_first[new]
        old = live[f_step[live] < t]
        if old.size:
            at = np.arange(old.size)
            seen = {k: np.asarray(v)[f_line[old]].copy() for k, v in obs.items()}
            for k, v in forks.section_entries(old, t).items():
                seen[k][at, f_sec[old]] = v
            seen_state = None
            if f_memory is not None:
                seen_state = np.asarray(before)[f_line[old]].copy()
                seen_state[at, :, f_sec[old]] = f_memory[old]
            choice, seen_state = policy.predict(seen, state=seen_state, episode_start=np.zeros(old.size, bool))
            choice = np.asarray(choice, dtype=np.int64)[at, f_sec[old]]
            fork_codes[old] = np.where(IS_TRACK_WORK[choice] & ~forks.allowed_rows(t)[old], NOTHING, choice)
            if f_memory is not None:
                f_memory[old] = np.asarray(seen_state)[at, :, f_sec[old]]
        if live.size:
            f_cost[live] += forks.choice_costs(fork_codes)[live]
            forks.work_rows(fork_codes, t)
            on = np.zeros(forks.n_lines * S, dtype=bool)
            on[live] = True
            forks.traffic_rows(on, t)
            f_cost[live] += forks.section_costs()[live]
            if (t + 1) % c.measurement_interval == 0:
                forks.measure_rows(on, t + 1)
            forks.inspect_rows(fork_codes == INSPECT, t + 1)
        # the policy's own step
        obs, _, _, _, info = env.step(codes.astype(np.int8))
        applied = np.asarray(info["section_choices"], dtype=np.int64)
        # a choice the env did not carry out as asked (over capacity) is not the policy's: not a sample
        samples["valid"].append(applied[b_new, j_new] == codes[b_new, j_new])
        work = IS_TRACK_WORK[applied]
        alone = work.sum(axis=1, keepdims=True) - work == 0  # no other section of the line works now
        base_cost[t] = info["section_costs"] + c.possession_cost * (work & alone)
        others = work.sum(axis=1)[f_line[live]] - work[f_line[live], f_sec[live]]
        f_cost[live] += c.possession_cost * (IS_TRACK_WORK[fork_codes[live]] & (others == 0))
        if progress is not None:
            progress(1)
    to_go = np.cumsum(base_cost[::-1], axis=0)[::-1]  # (H, E, S): the policy's cost from each step on
    valid = np.concatenate(samples["valid"]).astype(bool)
    rows = np.concatenate(samples["row"]).astype(np.int64)[valid]
    acted = np.concatenate(samples["acted"]).astype(bool)[valid]
    q_policy = to_go[f_step[rows], f_line[rows], f_sec[rows]]
    q_other = f_cost[rows]
    return {"features": np.concatenate(samples["features"]).astype(np.float32)[valid],
            "q_tamp": np.where(acted, q_policy, q_other), "q_wait": np.where(acted, q_other, q_policy),
            "acted": acted, "weight": np.concatenate(samples["weight"])[valid],
            "seed": np.asarray(seeds)[f_line[rows]], "step": f_step[rows], "section": f_sec[rows]}
