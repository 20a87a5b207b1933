"""The choice rule's own episodes, which the forks' tests replay: per seed the codes it played at each step and
its memory (recurrent state) before each step."""

from __future__ import annotations

import numpy as np

from trackenv.envs.line import TampingLine


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
