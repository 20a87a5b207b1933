"""Learning from a teacher: behaviour cloning of a tuned rule (the SB3 trainer's warm start), and fitting a policy to
the cheaper of two priced choices (the line's counterfactual policy iteration).

Why a warm start: exploration from a random (or never-tamping) policy spends most of a small training budget
rediscovering that a full campaign every few years beats doing nothing. Cloning the best tuned rule first puts
PPO where the rules are, and its own updates then only have to find the *improvements* (when a campaign can
wait, when it should come early). The cloned rule is only a starting point: the trained policy is judged on
held-out seeds like any other, against the same rule.

:func:`warm_start` rolls the teacher out on the training env (under VecNormalize: the roll-out also warms its
observation and reward statistics; the fit sees normalised observations and returns) and then fits the policy
head to the teacher's actions (cross-entropy) and the value head to the discounted returns of those episodes in
the learner's reward units (squared error). :func:`fit_choices` fits a policy to priced choices instead of a
teacher's actions (:mod:`trackenv_agents.learning.line_counterfactual`, :mod:`trackenv_agents.learning.line`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from trackenv.envs.line_config import LineConfig
from trackenv.envs.problems import ProblemConfig

from ..rules import rules_for, tuned_rule
from ..rules.problems import PLANNERS
from .actions import RANKED


def teacher_policy(rule: str, config: ProblemConfig, params: dict[str, Any] | None = None):
    """The heuristic ``rule`` with ``params`` (default: the tuned parameters of ``config``'s preset,
    :func:`~trackenv_agents.rules.tuned_rule`), bound to ``config``'s planning calendar; or a planner of
    :data:`~trackenv_agents.rules.problems.PLANNERS` with ``params`` (default: its own)."""
    if rule in PLANNERS:
        return PLANNERS[rule](**(params or {})).bind(config)
    rules = rules_for(config)
    if rule not in rules:
        raise ValueError(f"warm_start_rule must be one of {sorted(rules) + sorted(PLANNERS)}, got {rule!r}")
    return (tuned_rule(config, rule) if params is None else rules[rule](**params)).bind(config)


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


def _raw_obs(env, obs: dict) -> dict:
    """The env's last observation before any normalisation (VecNormalize keeps it; other envs return it)."""
    original = getattr(env, "get_original_obs", None)
    return original() if callable(original) else obs


def collect_demonstrations(env, teacher, action_type: str, n_episodes: int, gamma: float) -> dict[str, Any]:
    """Roll ``teacher`` out on ``env`` (an SB3 VecEnv over :class:`~agents.sb3_vec.TampingSB3VecEnv` whose top
    layer has ``get_original_reward``: VecNormalize or VecScaleReward) for at least ``n_episodes`` whole
    episodes; return raw observations, agent actions and discounted raw returns.

    Under VecNormalize the statistics update as it steps (it should be in training mode), which is the point:
    PPO starts with observation and reward scales measured on sensible behaviour."""
    n_envs = env.num_envs
    obs_raw = _raw_obs(env, env.reset())
    rounds = -(-int(n_episodes) // n_envs)
    observations: list[dict[str, np.ndarray]] = []
    actions, rewards, dones = [], [], []
    completed = 0
    state, starts = None, np.ones(n_envs, dtype=bool)  # a teacher with a recurrent state (a planner) keeps it
    while completed < rounds * n_envs:
        sections, state = teacher.predict(obs_raw, state=state, episode_start=starts)
        act = teacher_to_agent_actions(sections, action_type)
        observations.append({k: np.array(v, copy=True) for k, v in obs_raw.items()})
        actions.append(act)
        obs, _, done, _ = env.step(act)
        starts = done.copy()  # the env resets a finished episode: the next observation starts a new one
        rewards.append(env.get_original_reward().astype(np.float64))
        dones.append(done.copy())
        completed += int(done.sum())
        obs_raw = _raw_obs(env, obs)
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
    heads = getattr(distribution, "distributions", None)  # sb3-contrib's masked MultiCategorical/MultiBinary
    if heads is not None:
        uniform = sum(-torch.log_softmax(h.logits, dim=-1).mean(dim=-1) for h in heads)
        return ((1.0 - label_smoothing) * nll + label_smoothing * uniform).mean()
    inner = distribution.distribution
    if isinstance(inner, torch.distributions.Categorical):
        uniform = -torch.log_softmax(inner.logits, dim=-1).mean(dim=-1)
    else:  # Bernoulli heads: half the smoothing on each value
        log_p1 = torch.nn.functional.logsigmoid(inner.logits)
        log_p0 = torch.nn.functional.logsigmoid(-inner.logits)
        uniform = -(0.5 * (log_p1 + log_p0)).sum(dim=-1)
    return ((1.0 - label_smoothing) * nll + label_smoothing * uniform).mean()


def return_scale(env) -> float:
    """What the learner's rewards are the raw ones divided by: VecNormalize's running return scale (if it
    normalises rewards), :class:`~trackenv_agents.learning.sb3_vec.VecScaleReward`'s fixed scale, else 1."""
    if getattr(env, "norm_reward", False):
        return float(np.sqrt(env.ret_rms.var + env.epsilon))
    return float(getattr(env, "reward_scale", 1.0))


def _adam_epochs(policy, n: int, epochs: int, batch_size: int, learning_rate: float, seed: int, batch_loss) -> None:
    """Adam on ``policy``'s parameters over ``epochs`` shuffled passes of ``n`` samples in minibatches;
    ``batch_loss(indices)`` gives a minibatch's loss (a torch scalar). The shuffles come from ``seed``."""
    import torch

    gen = torch.Generator().manual_seed(seed)
    optimizer = torch.optim.Adam(policy.parameters(), lr=learning_rate)
    policy.set_training_mode(True)
    for _ in range(int(epochs)):
        order = torch.randperm(n, generator=gen)
        for start in range(0, n, batch_size):
            loss = batch_loss(order[start:start + batch_size])
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
    policy.set_training_mode(False)


def fit_policy(model, env, demos: dict[str, Any], epochs: int = 300, batch_size: int = 256,
               learning_rate: float = 1e-3, vf_coef: float = 0.5, label_smoothing: float = 0.02,
               seed: int = 0) -> dict[str, float]:
    """Fit ``model.policy`` to the demonstrations: cross-entropy on the actions (with ``label_smoothing``),
    squared error of the value on the returns (divided by :func:`return_scale`). The observations are
    normalised as the env does for the learner (VecNormalize), or passed raw. Returns the final losses, the
    training accuracy of the deterministic action (the whole action; ``section_accuracy``: per section for
    MultiBinary) and the mean probability of the teacher's action."""
    import torch
    from stable_baselines3.common.utils import obs_as_tensor

    policy = model.policy
    obs = demos["obs"]
    obs = {k: v.copy() for k, v in obs.items()} if isinstance(obs, dict) else np.array(obs, copy=True)
    normalize = getattr(env, "normalize_obs", None)
    if callable(normalize):
        obs = normalize(obs)
    target = torch.as_tensor(demos["returns"] / return_scale(env), dtype=torch.float32)
    obs_t = obs_as_tensor(obs, policy.device)
    act_t = torch.as_tensor(demos["actions"], device=policy.device)
    if isinstance(policy.action_space, spaces.MultiBinary):
        act_t = act_t.float()  # Bernoulli heads take their 0/1 targets as floats
    n = len(target)

    def batch_loss(idx):
        batch = {k: v[idx] for k, v in obs_t.items()} if isinstance(obs_t, dict) else obs_t[idx]
        value_loss = torch.nn.functional.mse_loss(policy.predict_values(batch).flatten(), target[idx])
        return _smoothed_nll(policy.get_distribution(batch), act_t[idx], label_smoothing) + vf_coef * value_loss

    _adam_epochs(policy, n, epochs, batch_size, learning_rate, seed, batch_loss)
    with torch.no_grad():
        values, log_prob, _ = policy.evaluate_actions(obs_t, act_t)
        chosen = policy.get_distribution(obs_t).mode()
    match = (chosen == act_t)
    section_accuracy = float(match.float().mean())
    if match.ndim > 1:
        match = match.all(dim=1)
    return {"nll": float(-log_prob.mean()), "teacher_probability": float(log_prob.exp().mean()),
            "value_mse": float(((values.flatten() - target) ** 2).mean()),
            "accuracy": float(match.float().mean()), "section_accuracy": section_accuracy, "samples": int(n)}


def fit_choices(model, samples: dict[str, np.ndarray], reward_scale: float, epochs: int = 30,
                batch_size: int = 512, learning_rate: float = 1e-3, vf_coef: float = 0.5, margin: float = 1.0,
                seed: int = 0) -> dict[str, float]:
    """Fit ``model.policy`` (an SB3 policy with ``Discrete(2)`` actions: 1 = make the choice, e.g. tamp) to the
    cheaper of two priced choices per sample (``samples``: ``features``, ``q_do``, ``q_skip`` k€ to the horizon
    for making the sample's choice and not, ``did``, ``weight``, as
    :func:`trackenv_agents.learning.line_counterfactual.section_counterfactuals` gives them): cost-sensitive
    classification, the cross-entropy of the cheaper choice weighted by ``weight`` ×
    max(|q_do − q_skip|, ``margin``) (a choice that costs much when wrong counts as much). Where the two
    differ by less than ``margin`` k€ the target is the choice the data's policy made: a difference that small
    is within what one sampled future decides, and keeping the policy's choice there keeps the learner from
    wandering where nothing is gained. The value head is fitted to minus the cost-to-go of the choice made, over
    ``reward_scale`` (the learner's reward units). Returns the final losses, the share of samples whose target
    the policy now chooses, and that share weighted."""
    import torch

    policy = model.policy
    x = torch.as_tensor(samples["features"], dtype=torch.float32, device=policy.device)
    q_tamp, q_wait = np.asarray(samples["q_do"], float), np.asarray(samples["q_skip"], float)
    acted = np.asarray(samples["did"], bool)
    if not (np.isfinite(margin) and margin >= 0):
        raise ValueError(f"margin must be a number >= 0 (k€), got {margin!r}")
    clear = np.abs(q_tamp - q_wait) >= margin
    target = torch.as_tensor(np.where(clear, q_tamp < q_wait, acted), dtype=torch.long, device=policy.device)
    stake = np.asarray(samples["weight"], float) * np.maximum(np.abs(q_tamp - q_wait), margin)
    if not stake.sum() > 0:
        raise ValueError("the samples carry no cost difference to learn from")
    w = torch.as_tensor(stake / stake.mean(), dtype=torch.float32, device=policy.device)
    made = np.where(acted, q_tamp, q_wait)
    value = torch.as_tensor(-made / reward_scale, dtype=torch.float32, device=policy.device)
    n = len(target)

    def batch_loss(idx):
        choice_loss = -(w[idx] * policy.get_distribution(x[idx]).log_prob(target[idx])).mean()
        return choice_loss + vf_coef * torch.nn.functional.mse_loss(policy.predict_values(x[idx]).flatten(),
                                                                    value[idx])

    _adam_epochs(policy, n, epochs, batch_size, learning_rate, seed, batch_loss)
    with torch.no_grad():
        dist = policy.get_distribution(x)
        right = (dist.mode() == target).float()
        choice_loss = -(w * dist.log_prob(target)).mean()
        value_mse = torch.nn.functional.mse_loss(policy.predict_values(x).flatten(), value)
    return {"choice_loss": float(choice_loss), "value_mse": float(value_mse), "samples": int(n),
            "target_share": float(right.mean()), "weighted_target_share": float((right * w).sum() / w.sum())}


def warm_start(model, env, config: LineConfig, action_type: str, rule: str, n_episodes: int = 64,
               epochs: int = 300, gamma: float = 0.99, label_smoothing: float = 0.02,
               params: dict[str, Any] | None = None, seed: int = 0) -> dict[str, Any]:
    """Clone ``rule`` (with ``params``, default its tuned ones) into ``model`` (see the module docstring); return
    a summary of the fit."""
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
