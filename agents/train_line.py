"""Train the per-section policy (:mod:`trackenv_agents.line_policy`) on TampingLine, and load a shipped one.

* :func:`train_line` — MaskablePPO (sb3-contrib; or SB3's PPO) on
  :class:`~trackenv_agents.sb3_vec.TampingSB3VecEnv` over the native
  :class:`~trackenv.envs.line.TampingLineVectorEnv` (every line of the batch in one physics call), VecMonitor
  (raw k€ returns), rewards divided by a fixed ``reward_scale`` × n_sections
  (:class:`~trackenv_agents.sb3_vec.VecScaleReward`: a section's return is O(1), on any line length; no
  running statistics, so the policy is independent of the line it was trained on). Warm start by behaviour
  cloning the best tuned rule (:func:`trackenv_agents.imitation.warm_start`), TensorBoard logs, checkpoints,
  and the held-out evaluation on the training run's ``eval_seeds`` through the harness, paired with the rule on
  the same seeds (common random numbers: ``eval/vs_baseline`` < 0 is cheaper than the rule). Hyper-parameters:
  the ``trackenv/TampingLine-v0`` entry of ``agents/hyperparams/ppo.yml`` (schema :data:`LINE_ZOO`).
* :func:`load_line_trained` — a saved policy (default the shipped ``agents/pretrained/ppo_tamping_line.zip``
  with its ``ppo_tamping_line_scales.json``) as a :class:`~trackenv_agents.line_policy.LineAgent`: SB3-style
  ``predict`` on raw observations of any TampingLine scenario.

Seeds: training env ``i`` starts with ``seed + i`` (default 20 000, apart from the test seeds 0-199, the
tuning seeds 1000-1099 and the evaluation seeds 10 000-10 015).
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from trackenv.envs.line_config import LineConfig

from .line_policy import LineAgent, section_policy_class
from .train import (
    _ALGO_KEYS,
    DEFAULT_EVAL_SEEDS,
    DEFAULT_TRAIN_SEED,
    HERE,
    ZooSchema,
    _algo_class,
    _make_eval_callback,
    _set_initial_tamp_logit,
    export_policy,
    load_hyperparams,
    single_torch_thread,
)

__all__ = ["DEFAULT_LINE_PRETRAINED", "LINE_ENV_ID", "LINE_ZOO", "export_line_policy", "line_meta_path",
           "load_line_trained", "train_line"]

LINE_ENV_ID = "trackenv/TampingLine-v0"
DEFAULT_LINE_PRETRAINED = HERE / "pretrained" / "ppo_tamping_line.zip"
META_SUFFIX = "_scales.json"
_LINE_TRAIN_KEYS = ("algo", "n_envs", "total_timesteps", "hidden", "reward_scale", "eval_freq", "checkpoint_every",
                    "initial_tamp_logit", "warm_start_rule", "warm_start_episodes", "warm_start_epochs",
                    "warm_start_label_smoothing", "warm_start_params", "warm_start_relabel_copies",
                    "warm_start_relabel_sd_mm", "bootstrap_at_horizon")
#: what :func:`train_line` reads from an RL Zoo entry (see :class:`trackenv_agents.train.ZooSchema`)
LINE_ZOO = ZooSchema("SectionActorCritic", "one shared network scores every section", ("hidden",), False,
                     _ALGO_KEYS + _LINE_TRAIN_KEYS)


def line_meta_path(zip_path: str | Path) -> Path:
    """The JSON beside a saved line policy (``<stem>_scales.json``): algorithm, network size, feature and reward
    scales, and the config it was trained on."""
    zip_path = Path(zip_path)
    return zip_path.with_name(zip_path.stem + META_SUFFIX)


def _save_line_policy(model: Any, agent: LineAgent | None, zip_path: Path, extra: dict | None = None) -> Path:
    """``model`` at ``zip_path`` and its JSON (:func:`line_meta_path`). The optimiser's state is left out (a fresh
    one is saved): the file is the policy, a few tens of kB, not a run to continue."""
    policy = model.policy
    state = policy.optimizer
    policy.optimizer = policy.optimizer_class(policy.parameters(), **state.defaults)
    try:  # nor the last roll-out's observations and episode records
        model.save(zip_path, exclude=["_last_obs", "_last_episode_starts", "_last_original_obs", "ep_info_buffer",
                                      "ep_success_buffer"])
    finally:
        policy.optimizer = state
    meta = {"algo": "maskable_ppo" if type(model).__name__ == "MaskablePPO" else "ppo", "hidden": policy.hidden,
            "feature_scales": dict(policy.feature_scales), **(extra or {})}
    line_meta_path(zip_path).write_text(json.dumps(meta, indent=1, default=str))
    return Path(zip_path)


def train_line(config: LineConfig | dict | str | None = None, algo: str | None = None,
               total_timesteps: int | None = None, n_envs: int | None = None, seed: int = DEFAULT_TRAIN_SEED,
               out_dir: str | Path = "runs/ppo_line", hyperparams: dict | str | Path | None = None,
               progress: bool = True, eval_seeds: Sequence[int] | None = DEFAULT_EVAL_SEEDS,
               eval_freq: int | None = None, checkpoint_every: int | None = None, verbose: int = 1) -> Path:
    """Train on a TampingLine ``config`` (a LineConfig, its fields as a dict, or a scenario name; default the
    default line); save ``out_dir/model.zip`` (+ ``model_scales.json``) and return its path.

    ``hyperparams``: a dict, a flat JSON path or an RL Zoo YAML path (its ``trackenv/TampingLine-v0`` entry)
    overriding the shipped entry key by key; explicit arguments override both. ``eval_seeds=None`` or
    ``eval_freq=0`` disables the held-out evaluation. ``out_dir`` gets ``summary.json`` (timesteps, wall time,
    env steps per second, the warm start's fit, every evaluation), ``train_meta.json``, ``evaluations.json``,
    ``best_model.zip``, TensorBoard logs and ``checkpoints/``."""
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback
    from stable_baselines3.common.utils import set_random_seed
    from stable_baselines3.common.vec_env import VecMonitor

    from .evaluation import evaluate_one
    from .imitation import teacher_policy, warm_start
    from .sb3_vec import TampingSB3VecEnv, VecScaleReward

    hp = load_hyperparams(env_id=LINE_ENV_ID, schema=LINE_ZOO)
    if isinstance(hyperparams, (str, Path)):
        hyperparams = load_hyperparams(hyperparams, env_id=LINE_ENV_ID, schema=LINE_ZOO)
    unknown = set(hyperparams or {}) - set(LINE_ZOO.keys)
    if unknown:
        raise ValueError(f"unknown hyper-parameter(s) {sorted(unknown)}")
    hp.update(hyperparams or {})
    algo = algo or hp.get("algo", "maskable_ppo")
    n_envs = int(n_envs or hp.get("n_envs", 8))
    total_timesteps = int(total_timesteps or hp.get("total_timesteps", 1024))
    checkpoint_every = int(checkpoint_every if checkpoint_every is not None else hp.get("checkpoint_every", 0))
    eval_freq = int(eval_freq if eval_freq is not None else hp.get("eval_freq", 0))
    reward_scale = float(hp.get("reward_scale", 20.0))
    if not (np.isfinite(reward_scale) and reward_scale > 0):
        raise ValueError(f"reward_scale must be a number > 0 (k€ per section), got {reward_scale!r}")
    config = LineConfig.coerce("default" if config is None else config)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    AlgoClass = _algo_class(algo)

    single_torch_thread()  # the physics (numba) wants the cores; the small network does not
    set_random_seed(seed)
    raw = TampingSB3VecEnv(n_envs, config, seed=seed, bootstrap_at_horizon=bool(hp.get("bootstrap_at_horizon", False)))
    env = VecScaleReward(VecMonitor(raw), reward_scale * config.n_sections)
    algo_kw = {k: hp[k] for k in _ALGO_KEYS if k in hp}
    model = AlgoClass(section_policy_class(algo), env, seed=seed, tensorboard_log=str(out_dir), verbose=verbose,
                      policy_kwargs={"hidden": int(hp.get("hidden", 32))}, device="cpu", **algo_kw)
    if "initial_tamp_logit" in hp:
        _set_initial_tamp_logit(model, float(hp["initial_tamp_logit"]), "multibinary")

    warm = None
    rule = hp.get("warm_start_rule")
    if rule:
        t_warm = time.time()
        warm = warm_start(model, env, config, "multibinary", rule, n_episodes=int(hp.get("warm_start_episodes", 16)),
                          epochs=int(hp.get("warm_start_epochs", 300)), gamma=float(hp.get("gamma", 0.99)),
                          label_smoothing=float(hp.get("warm_start_label_smoothing", 0.02)),
                          params=hp.get("warm_start_params"), seed=seed,
                          relabel_copies=int(hp.get("warm_start_relabel_copies", 0)),
                          relabel_sd_mm=float(hp.get("warm_start_relabel_sd_mm", 0.15)))
        warm["wall_seconds"] = time.time() - t_warm
        if verbose:
            print(f"[warm start] {warm}", flush=True)

    meta = {"env_id": LINE_ENV_ID, "config": config.to_dict(), "reward_scale": reward_scale, "seed": seed}
    if warm is not None:  # the clone itself, a candidate like every later policy
        _save_line_policy(model, None, out_dir / "warm_start.zip", meta)
    callbacks: list[Any] = []
    if checkpoint_every > 0:
        callbacks.append(CheckpointCallback(save_freq=max(checkpoint_every // n_envs, 1),
                                            save_path=str(out_dir / "checkpoints"), name_prefix="model"))
    eval_cb = None
    baseline = None
    if eval_seeds and eval_freq > 0:
        t_base = time.time()
        # the rule on the same held-out episodes: every evaluation is paired with it (common random numbers)
        baseline = evaluate_one(teacher_policy(rule or "grouped-threshold", config, hp.get("warm_start_params")),
                                config, list(eval_seeds), batch_size=len(eval_seeds))
        if verbose:
            print(f"[baseline] {baseline.policy}: {baseline.cost.mean():.1f} k€ on {baseline.n_episodes} held-out "
                  f"episodes ({time.time() - t_base:.0f} s)", flush=True)
        eval_cb = _make_eval_callback(
            config, list(eval_seeds), eval_freq, out_dir, lambda m: LineAgent(m.policy),
            lambda m, agent, path: _save_line_policy(m, agent, path, meta), "multibinary", verbose,
            evaluate_at_start=True, baseline=baseline)
        callbacks.append(eval_cb)
    (out_dir / "train_meta.json").write_text(json.dumps(
        {"algo": algo, "n_envs": n_envs, "hyperparams": hp, **meta, "warm_start": warm}, indent=1, default=str))

    t0 = time.time()
    model.learn(total_timesteps=total_timesteps, callback=CallbackList(callbacks), progress_bar=progress,
                tb_log_name=algo)
    wall = time.time() - t0
    path = _save_line_policy(model, None, out_dir / "model.zip", meta)
    eval_seconds = sum(r["eval_seconds"] for r in eval_cb.history) if eval_cb is not None else 0.0
    summary = {"timesteps": int(model.num_timesteps), "wall_seconds": wall,
               # env (line-) steps per second of training: the learning wall time less the held-out evaluations
               "steps_per_second": model.num_timesteps / max(wall - eval_seconds, 1e-9),
               "eval_seconds": eval_seconds, "warm_start": warm,
               "baseline": None if baseline is None else {"policy": baseline.policy, "params": baseline.params,
                                                          "mean_cost": float(baseline.cost.mean()),
                                                          "seeds": baseline.seeds.tolist()},
               "evaluations": eval_cb.history if eval_cb is not None else []}
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=1, default=float))
    env.close()
    return path


def export_line_policy(model_zip: str | Path, dest: str | Path = DEFAULT_LINE_PRETRAINED) -> Path:
    """Copy a saved line policy and its JSON to ``dest`` (default the shipped path)."""
    return export_policy(model_zip, dest, sidecar=line_meta_path)


def load_line_trained(path: str | Path | None = None, name: str = "ppo") -> LineAgent:
    """The line policy at ``path`` (default the shipped ``agents/pretrained/ppo_tamping_line.zip``), with SB3's
    ``predict`` on raw observations of any TampingLine scenario. FileNotFoundError if there is none."""
    path = Path(path) if path is not None else DEFAULT_LINE_PRETRAINED
    if not path.exists():
        raise FileNotFoundError(f"no trained line policy at {path}")
    meta = json.loads(line_meta_path(path).read_text())
    model = _algo_class(meta["algo"]).load(str(path), device="cpu")
    agent = LineAgent(model.policy, name=name)
    if dict(model.policy.feature_scales) != {k: float(v) for k, v in meta["feature_scales"].items()}:
        raise ValueError(f"{line_meta_path(path)}: feature_scales differ from the model's")
    return agent

