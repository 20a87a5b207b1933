"""Warm start by behaviour cloning: before PPO explores, its policy learns to act like a tuned rule.

Why: exploration from a random (or never-tamping) policy spends most of a small training budget rediscovering
that a full campaign every few years beats doing nothing. Cloning the best tuned rule first puts PPO where
the rules are, and its own updates then only have to find the *improvements* (when a campaign can wait, when it
should come early). The cloned rule is only a starting point: the trained policy is judged on held-out seeds
like any other, against the same rule.

:func:`warm_start` rolls the teacher out on the (VecNormalize-wrapped) training env, which also warms the
observation and reward statistics, and then fits the policy head to the teacher's actions (cross-entropy) and
the value head to the normalised discounted returns of those episodes (squared error).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from trackenv.envs.config import TampingEnvConfig

from .actions import RANKED
from .heuristics import HEURISTICS, make_policy, tuned_params


def teacher_policy(rule: str, config: TampingEnvConfig, params: dict[str, Any] | None = None):
    """The heuristic ``rule`` with ``params`` (default: its tuned parameters in ``agents/tuned_heuristics.json``),
    bound to ``config``'s planning calendar."""
    if rule not in HEURISTICS:
        raise ValueError(f"warm_start_rule must be one of {sorted(HEURISTICS)}, got {rule!r}")
    if params is None:
        params = tuned_params().get(rule, {})
    return make_policy(rule, **params).bind(config)


def teacher_to_agent_actions(sections: np.ndarray, action_type: str) -> np.ndarray:
    """The agent's actions that reproduce the teacher's per-section actions (n_envs, n_sections).

    ``ranked``: the number of sections tamped (exact for rules that tamp all or the worst sections by SD,
    which every tuned rule here does); ``multibinary``: the sections themselves."""
    sections = np.asarray(sections, dtype=np.int64)
    if action_type == RANKED:
        return sections.sum(axis=1)
    if action_type == "multibinary":
        return sections
    raise ValueError(f"warm start supports action_type 'ranked' or 'multibinary', got {action_type!r} "
                     "(set warm_start_rule to null to train without a warm start)")


def collect_demonstrations(env, teacher, action_type: str, n_episodes: int, gamma: float) -> dict[str, Any]:
    """Roll ``teacher`` out on ``env`` (VecNormalize over :class:`~agents.sb3_vec.TampingSB3VecEnv`) for at
    least ``n_episodes`` whole episodes; return raw observations, agent actions and discounted raw returns.

    The env's statistics update as it steps (it should be in training mode), which is the point: PPO starts
    with observation and reward scales measured on sensible behaviour."""
    n_envs = env.num_envs
    env.reset()
    obs_raw = env.get_original_obs()
    rounds = -(-int(n_episodes) // n_envs)
    observations: list[dict[str, np.ndarray]] = []
    actions, rewards, dones = [], [], []
    completed = 0
    while completed < rounds * n_envs:
        sections, _ = teacher.predict(obs_raw)
        act = teacher_to_agent_actions(sections, action_type)
        observations.append({k: np.array(v, copy=True) for k, v in obs_raw.items()})
        actions.append(act)
        _, _, done, _ = env.step(act)
        rewards.append(env.get_original_reward().astype(np.float64))
        dones.append(done.copy())
        completed += int(done.sum())
        obs_raw = env.get_original_obs()
    rew = np.stack(rewards)  # (T, n_envs)
    done = np.stack(dones)
    returns = np.zeros_like(rew)
    running = np.zeros(n_envs)
    for t in range(len(rew) - 1, -1, -1):
        running = rew[t] + gamma * running * (~done[t])
        returns[t] = running
    # keep only steps of completed episodes (the tail of a still-running episode has a truncated return)
    keep = np.zeros_like(done)
    for i in range(n_envs):
        idx = np.flatnonzero(done[:, i])
        if idx.size:
            keep[: idx[-1] + 1, i] = True
    obs_cat = {k: np.stack([o[k] for o in observations])[keep] for k in observations[0]}
    return {"obs": obs_cat, "actions": np.stack(actions)[keep], "returns": returns[keep],
            "episodes": int(done.sum()), "mean_episode_return": float(rew[keep].sum() / max(done.sum(), 1))}


def _smoothed_nll(distribution, actions, label_smoothing: float):
    """Cross-entropy with the target ``1 - ε`` on the teacher's action and ``ε`` spread over all actions
    (per head for MultiBinary), so that the clone keeps some probability on the alternatives and PPO's
    sampling still explores them."""
    import torch

    nll = -distribution.log_prob(actions)
    if label_smoothing <= 0.0:
        return nll.mean()
    inner = distribution.distribution
    if isinstance(inner, torch.distributions.Categorical):
        uniform = -torch.log_softmax(inner.logits, dim=-1).mean(dim=-1)
    else:  # Bernoulli heads: half the smoothing on each value
        log_p1 = torch.nn.functional.logsigmoid(inner.logits)
        log_p0 = torch.nn.functional.logsigmoid(-inner.logits)
        uniform = -(0.5 * (log_p1 + log_p0)).sum(dim=-1)
    return ((1.0 - label_smoothing) * nll + label_smoothing * uniform).mean()


def fit_policy(model, env, demos: dict[str, Any], epochs: int = 300, batch_size: int = 256,
               learning_rate: float = 1e-3, vf_coef: float = 0.5, label_smoothing: float = 0.02,
               seed: int = 0) -> dict[str, float]:
    """Fit ``model.policy`` to the demonstrations: cross-entropy on the actions (with ``label_smoothing``),
    squared error of the value on the returns (normalised by the env's reward scale). Returns the final losses,
    the training accuracy of the deterministic action and the mean probability of the teacher's action."""
    import torch
    from stable_baselines3.common.utils import obs_as_tensor

    policy = model.policy
    obs = env.normalize_obs({k: v.copy() for k, v in demos["obs"].items()})
    ret_scale = float(np.sqrt(env.ret_rms.var + env.epsilon)) if env.norm_reward else 1.0
    target = torch.as_tensor(demos["returns"] / ret_scale, dtype=torch.float32)
    obs_t = obs_as_tensor(obs, policy.device)
    act_t = torch.as_tensor(demos["actions"], device=policy.device)
    if isinstance(policy.action_space, spaces.MultiBinary):
        act_t = act_t.float()  # Bernoulli heads take their 0/1 targets as floats
    n = len(target)
    gen = torch.Generator().manual_seed(seed)
    optimizer = torch.optim.Adam(policy.parameters(), lr=learning_rate)
    policy.set_training_mode(True)
    for _ in range(int(epochs)):
        order = torch.randperm(n, generator=gen)
        for start in range(0, n, batch_size):
            idx = order[start:start + batch_size]
            batch = {k: v[idx] for k, v in obs_t.items()}
            distribution = policy.get_distribution(batch)
            values = policy.predict_values(batch)
            value_loss = torch.nn.functional.mse_loss(values.flatten(), target[idx])
            loss = _smoothed_nll(distribution, act_t[idx], label_smoothing) + vf_coef * value_loss
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
    policy.set_training_mode(False)
    with torch.no_grad():
        values, log_prob, _ = policy.evaluate_actions(obs_t, act_t)
        chosen = policy.get_distribution(obs_t).mode()
    match = (chosen == act_t)
    if match.ndim > 1:
        match = match.all(dim=1)
    return {"nll": float(-log_prob.mean()), "teacher_probability": float(log_prob.exp().mean()),
            "value_mse": float(((values.flatten() - target) ** 2).mean()),
            "accuracy": float(match.float().mean()), "samples": int(n)}


def warm_start(model, env, config: TampingEnvConfig, action_type: str, rule: str, n_episodes: int = 64,
               epochs: int = 300, gamma: float = 0.99, label_smoothing: float = 0.02,
               params: dict[str, Any] | None = None, seed: int = 0) -> dict[str, Any]:
    """Clone ``rule`` (with ``params``, default its tuned ones) into ``model`` (see the module docstring);
    return a summary of the fit."""
    if int(n_episodes) < 1:
        raise ValueError(f"warm_start_episodes must be >= 1, got {n_episodes!r}")
    if int(epochs) < 1:
        raise ValueError(f"warm_start_epochs must be >= 1, got {epochs!r}")
    if not 0.0 <= label_smoothing < 1.0:
        raise ValueError(f"warm_start_label_smoothing must be in [0, 1), got {label_smoothing!r}")
    teacher = teacher_policy(rule, config, params)
    demos = collect_demonstrations(env, teacher, action_type, n_episodes, gamma)
    fit = fit_policy(model, env, demos, epochs=epochs, label_smoothing=label_smoothing, seed=seed)
    return {"rule": rule, "params": teacher.params, "episodes": demos["episodes"],
            "teacher_mean_return": demos["mean_episode_return"], **fit}
