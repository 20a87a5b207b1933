"""Env replays the forks' tests compare the forks with: the choice rule's own episodes (per seed the codes it
played at each step and its memory before each step), one section's cost from a step on under another choice
there, and a whole line's cost from a step on (where sections share a segment, :data:`SHARED`)."""

from __future__ import annotations

import numpy as np

from trackenv.envs import scenario
from trackenv.envs.choices import IS_TRACK_WORK, SPOT_TAMP
from trackenv.envs.line import TampingLine
from trackenv_agents.rules.choices import choice_view, remember_work

# the 60 m track cut to 30 m in 3 sections of one segment over 2 years of quarters (8 steps)
SHARED = scenario("track60", n_sections=3, segment_length_m=30.0, sections_per_segment=3, capacity=3,
                  horizon_years=2.0)


def line_cost_to_go(cfg, seed, policy, t, first) -> float:
    """The whole line's cost from step t in the env (every section and the possession) when it makes the codes
    ``first`` at step t and ``policy`` decides every other step."""
    env = TampingLine(cfg)
    obs, _ = env.reset(seed=seed)
    cost = 0.0
    for step in range(cfg.horizon_steps):
        a = np.asarray(first, dtype=np.int8) if step == t else policy.predict(obs)[0]
        obs, reward, *_ = env.step(a)
        if step >= t:
            cost -= reward
    return cost


def line_cost_to_go_remembering(cfg, seed, policy, t, first) -> float:
    """:func:`line_cost_to_go` for a policy with a recurrent state that records what it was shown: it is asked
    every step, step t included (its state sees that step's observation), and carries its state on."""
    env = TampingLine(cfg)
    obs, _ = env.reset(seed=seed)
    cost, state = 0.0, None
    for step in range(cfg.horizon_steps):
        codes, state = policy.predict({k: v[None] for k, v in obs.items()}, state=state,
                                      episode_start=np.array([step == 0]))
        a = np.asarray(first, dtype=np.int8) if step == t else np.asarray(codes[0], dtype=np.int8)
        obs, reward, *_ = env.step(a)
        if step >= t:
            cost -= reward
    return cost


def rule_plans(cfg, rule, seeds) -> tuple[dict, dict]:
    """``rule`` (bound to ``cfg``) played on the episodes ``seeds``: ({seed: (steps, sections) codes applied},
    {seed: [its state before each step]})."""
    plans, states = {}, {}
    for s in seeds:
        env, plan, memory = TampingLine(cfg, action_type="choices"), [], []
        obs, _ = env.reset(seed=s)
        state = None
        for t in range(cfg.horizon_steps):
            memory.append(state)
            codes, state = rule.predict({k: v[None] for k, v in obs.items()}, state=state,
                                        episode_start=np.array([t == 0]))
            obs, *_, info = env.step(codes[0])
            plan.append(info["section_choices"])
        plans[s], states[s] = np.array(plan), memory
    return plans, states


def section_cost(cfg, seed, policy, plan, states, j, t, first):
    """Section j's cost from step t in the env under ``first`` at step t then ``policy`` (its memory that of the
    policy's run, section j's own), the other sections replaying ``plan``: its own costs plus the possession the
    line pays beyond what it would pay without j's track work (read from the env's possession part)."""
    env = TampingLine(cfg, action_type="choices")
    obs, _ = env.reset(seed=seed)
    own, cost = None, 0.0
    for step in range(cfg.horizon_steps):
        a = plan[step].astype(np.int8).copy()
        memory = None if states[step] is None else states[step].copy()
        if own is not None:
            memory[0, :, j] = own
        choice, after = policy.predict({k: v[None] for k, v in obs.items()}, state=memory,
                                       episode_start=np.array([step == 0]))
        if step == t:
            a[j] = first
            base = np.full((1, 3, cfg.n_sections), -np.inf) if states[step] is None else states[step].copy()
            peak = choice_view({k: v[None] for k, v in obs.items()})["section_peak"]
            own = remember_work(base, a[None].astype(np.int64), step, peak)[0, :, j]
        elif step > t:
            a[j] = choice[0][j]
            own = after[0, :, j]
        obs, _, _, _, info = env.step(a)
        if step >= t:
            applied = np.asarray(info["section_choices"])
            others = np.delete(applied, j)
            work = IS_TRACK_WORK[others]
            spot_only = work.any() and (others[work] == SPOT_TAMP).all()
            without = 0.0 if not work.any() else cfg.possession_cost * (cfg.spot_possession_share if spot_only else 1)
            cost += info["section_costs"][j] + info["costs"]["possession"] - without
    return cost
