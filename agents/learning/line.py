"""Train the per-section policy (:mod:`trackenv_agents.learning.line_policy`) on TampingLine, and load a shipped one.

* :func:`train_line` — **counterfactual policy iteration**, then optionally MaskablePPO:

  1. The policy starts as the best tuned rule (the *advisor*, by default grouped-threshold with its tuned
     parameters), whose choice is also one of the policy's features.
  2. Each iteration runs the current policy on ``episodes_per_iteration`` new training episodes and prices the
     other choice of a random subset of its decisions by forking that one section and letting the policy go on
     deciding for it (:func:`~trackenv_agents.learning.line_counterfactual.section_counterfactuals`: exact replays on
     common random numbers). The network is then fitted to the cheaper choice over every decision priced so far,
     weighted by what is at stake (:func:`~trackenv_agents.learning.imitation.fit_choices`): one step of approximate
     policy iteration per iteration, the data of all earlier policies kept (as AggreVaTe does).
  3. After each iteration the policy is scored on the held-out ``eval_seeds`` through the harness, paired with
     the advisor on the same episodes (common random numbers); the best iteration is kept (``best_model.zip``).
  4. ``n_timesteps`` > 0 adds MaskablePPO on :class:`~trackenv_agents.learning.sb3_vec.SectionAgentsVecEnv`
     (each section an agent paid its own costs) from the best iteration, with the same held-out evaluation.

  Why not PPO alone: a default line makes ~10 line-steps a second on 2 cores, a few hundred episodes an hour,
  and PPO from the rule's clone stayed where it started or got worse over the first 80 episodes (the
  documentation's results page). A counterfactual fork measures the value of one choice without the noise of
  the other sections and of the future (both branches see the same draws), so an hour buys an improvement of
  the whole policy.
* :func:`load_line_trained` — a saved policy (default the shipped ``agents/learning/pretrained/ppo_tamping_line.zip``
  with its ``ppo_tamping_line_meta.json``) as a :class:`~trackenv_agents.learning.line_policy.LineAgent`: SB3-style
  ``predict`` on raw observations of any TampingLine scenario.

Seeds: training episodes are ``seed``, ``seed + 1``, ... (default 20 000, apart from the test seeds 0-199, the
tuning seeds 1000-1099 and the evaluation seeds 10 000-10 015). TensorBoard logs (``policy_iteration/``: per
iteration the samples, the fit and the held-out evaluation), a checkpoint per iteration, ``summary.json``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from trackenv.envs.line_config import LineConfig

from .line_policy import ADVISOR_FEATURES, FEATURES, LineAgent
from .settings import LineSettings
from .tamping import (
    DEFAULT_EVAL_SEEDS,
    DEFAULT_TRAIN_SEED,
    HERE,
    ZooSchema,
    _algo_class,
    _make_eval_callback,
    export_policy,
    load_hyperparams,
    make_progress_callback,
    single_torch_thread,
)

__all__ = ["DEFAULT_LINE_PRETRAINED", "LINE_ENV_ID", "LINE_ZOO", "export_line_policy", "line_meta_path",
           "load_line_trained", "train_line"]

LINE_ENV_ID = "trackenv/TampingLine-v0"
DEFAULT_LINE_PRETRAINED = HERE / "pretrained" / "ppo_tamping_line.zip"
META_SUFFIX = "_meta.json"
#: what :func:`train_line` reads from an RL Zoo entry (see :class:`trackenv_agents.learning.tamping.ZooSchema`)
LINE_ZOO = ZooSchema("MlpPolicy", "one network decides for every section from its features", ("net_arch",), False,
                     LineSettings)


def _feature_names(advisor: bool) -> list[str]:
    return [n for n, _ in FEATURES] + (list(ADVISOR_FEATURES) if advisor else [])


def line_meta_path(zip_path: str | Path) -> Path:
    """The JSON beside a saved line policy (``<stem>_meta.json``): algorithm, network, features, advisor (rule
    and parameters), reward scale and the config it was trained on."""
    zip_path = Path(zip_path)
    return zip_path.with_name(zip_path.stem + META_SUFFIX)


def _save_line_policy(model: Any, zip_path: Path, meta: dict) -> Path:
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
    algo = "maskable_ppo" if type(model).__name__ == "MaskablePPO" else "ppo"
    line_meta_path(zip_path).write_text(json.dumps({"algo": algo, **meta}, indent=1, default=str))
    return Path(zip_path)


def train_line(config: LineConfig | dict | str | None = None, total_timesteps: int | None = None,
               n_envs: int | None = None, seed: int = DEFAULT_TRAIN_SEED, out_dir: str | Path = "runs/ppo_line",
               hyperparams: LineSettings | dict | str | Path | None = None, progress: bool = True,
               eval_seeds: Sequence[int] | None = DEFAULT_EVAL_SEEDS, iterations: int | None = None,
               episodes_per_iteration: int | None = None, verbose: int = 1) -> Path:
    """Train on a TampingLine ``config`` (a LineConfig, its fields as a dict, or a scenario name; default the
    default line) by counterfactual policy iteration (then MaskablePPO for ``total_timesteps`` line-steps, 0 by
    default); save ``out_dir/model.zip`` (+ ``model_meta.json``) and return its path.

    ``hyperparams``: a dict, a flat JSON path or an RL Zoo YAML path (its ``trackenv/TampingLine-v0`` entry)
    overriding the shipped entry of ``agents/learning/hyperparams/ppo.yml`` key by key, or a whole
    :class:`LineSettings`; explicit arguments that are not None override both. Unknown keys and values out of
    range raise ValueError (:class:`LineSettings` lists the fields, their defaults and ranges).
    ``eval_seeds=None`` disables the held-out evaluation (then the last iteration is the model).
    ``out_dir`` gets ``summary.json`` (wall times, line-steps and fork steps per second, every iteration's
    samples, fit and evaluation), ``train_meta.json``, ``best_model.zip``, ``checkpoints/``, TensorBoard logs."""
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.utils import set_random_seed

    from ..evaluation.harness import evaluate_one
    from ..evaluation.statistics import paired_difference
    from .imitation import fit_choices, teacher_policy
    from .line_counterfactual import section_counterfactuals
    from .sb3_vec import SectionAgentsVecEnv

    if isinstance(hyperparams, LineSettings):
        s = hyperparams
    else:
        if isinstance(hyperparams, (str, Path)):
            hyperparams = load_hyperparams(hyperparams, env_id=LINE_ENV_ID, schema=LINE_ZOO)
        s = LineSettings.from_dict(load_hyperparams(env_id=LINE_ENV_ID, schema=LINE_ZOO)).updated(hyperparams or {})
    explicit = {"total_timesteps": total_timesteps, "n_envs": n_envs, "iterations": iterations,
                "episodes_per_iteration": episodes_per_iteration}
    s = s.updated({k: v for k, v in explicit.items() if v is not None})
    algo, n_envs, total_timesteps, n_iter, n_episodes = (s.algo, s.n_envs, s.total_timesteps, s.iterations,
                                                         s.episodes_per_iteration)
    reward_scale, fit_epochs, margin, focus_rate, other_rate, eval_freq = (
        s.reward_scale, s.fit_epochs, s.fit_margin, s.focus_rate, s.other_rate, s.eval_freq)
    config = LineConfig.coerce("default" if config is None else config)
    out_dir = Path(out_dir)
    (out_dir / "checkpoints").mkdir(parents=True, exist_ok=True)
    AlgoClass = _algo_class(algo)

    single_torch_thread()  # the physics (numba) wants the cores; the small network does not
    set_random_seed(seed)
    advisor = teacher_policy(s.advisor, config, None if s.advisor_params is None else dict(s.advisor_params))
    env = SectionAgentsVecEnv(n_envs, config, seed=seed + 1_000_000, reward_scale=reward_scale, advisor=advisor)
    model = AlgoClass("MlpPolicy", env, seed=seed, tensorboard_log=str(out_dir), verbose=0, device="cpu",
                      policy_kwargs={"net_arch": list(s.net_arch)}, **s.algo_kwargs())
    logger = configure(str(out_dir / "policy_iteration"), ["csv", "tensorboard"])
    meta = {"env_id": LINE_ENV_ID, "net_arch": list(s.net_arch),
            "features": _feature_names(True), "advisor": advisor.name, "advisor_params": dict(advisor.params),
            "reward_scale": reward_scale, "config": config.to_dict(), "seed": seed}
    (out_dir / "train_meta.json").write_text(json.dumps({"algo": algo, "hyperparams": s.to_dict(), **meta}, indent=1,
                                                        default=str))

    baseline = None
    if eval_seeds:
        t_base = time.time()  # the rule on the held-out episodes: every evaluation is paired with it
        baseline = evaluate_one(advisor, config, list(eval_seeds), batch_size=len(eval_seeds))
        if verbose:
            print(f"[baseline] {baseline.policy}: {baseline.cost.mean():.1f} k€ on {baseline.n_episodes} held-out "
                  f"episodes ({time.time() - t_base:.0f} s)", flush=True)

    def evaluate(agent: LineAgent) -> dict[str, Any]:
        t_eval = time.time()
        res = evaluate_one(agent, config, list(eval_seeds), batch_size=len(eval_seeds))
        return {"mean_cost": float(res.cost.mean()), "mean_return": float(res.sum_rewards.mean()),
                "vs_baseline": paired_difference(res, baseline), "eval_seconds": time.time() - t_eval,
                "cost_parts": {k: float(v.mean()) for k, v in res.cost_parts.items()}}

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=n_iter * config.horizon_steps, desc="policy iteration", unit="step")
    history: list[dict[str, Any]] = []
    data: list[dict[str, np.ndarray]] = []
    behaviour: Any = advisor
    best = -np.inf
    t0 = time.time()
    line_steps = fork_steps = 0
    for it in range(n_iter):
        t_it = time.time()
        seeds = list(range(seed + it * n_episodes, seed + (it + 1) * n_episodes))
        d = section_counterfactuals(config, seeds, behaviour, advisor=advisor,
                                    focus_rate=focus_rate, other_rate=other_rate, seed=seed + it,
                                    progress=bar.update if bar is not None else None)
        t_forks = time.time() - t_it
        data.append(d)
        pooled = {k: np.concatenate([x[k] for x in data]) for k in d}
        fit = fit_choices(model, pooled, reward_scale, epochs=fit_epochs, margin=margin, seed=seed + it)
        line_steps += n_episodes * config.horizon_steps
        fork_steps += int(np.sum(config.horizon_steps - d["step"]))
        rec: dict[str, Any] = {"iteration": it, "seeds": [seeds[0], seeds[-1]], "samples": int(d["step"].size),
                               "other_choice_cheaper": float(np.mean((d["q_tamp"] < d["q_wait"]) != d["acted"])),
                               "fork_seconds": t_forks, "fit_seconds": time.time() - t_it - t_forks, "fit": fit}
        agent = LineAgent(model.policy, advisor=advisor)
        _save_line_policy(model, out_dir / "checkpoints" / f"iteration_{it}.zip", meta)
        if baseline is not None:
            rec["evaluation"] = evaluate(agent)
            if rec["evaluation"]["mean_return"] > best:
                best = rec["evaluation"]["mean_return"]
                _save_line_policy(model, out_dir / "best_model.zip", meta)
            logger.record("eval/mean_cost", rec["evaluation"]["mean_cost"])
            logger.record("eval/vs_baseline", rec["evaluation"]["vs_baseline"]["mean_difference"])
        for k in ("samples", "other_choice_cheaper"):
            logger.record(f"policy_iteration/{k}", rec[k])
        logger.record("policy_iteration/target_share", fit["target_share"])
        logger.record("policy_iteration/value_mse", fit["value_mse"])
        logger.dump(it)
        history.append(rec)
        if verbose:
            ev = rec.get("evaluation")
            vs = "" if ev is None else (f"; held-out {ev['mean_cost']:.1f} k€, vs {baseline.policy} "
                                        f"{ev['vs_baseline']['mean_difference']:+.1f} "
                                        f"[{ev['vs_baseline']['ci_low']:+.1f}, {ev['vs_baseline']['ci_high']:+.1f}]")
            print(f"[iteration {it}] {rec['samples']} decisions priced ({rec['other_choice_cheaper']:.1%} cheaper "
                  f"the other way), fit {fit['weighted_target_share']:.3f}{vs} ({time.time() - t_it:.0f} s)",
                  flush=True)
        (out_dir / "summary.json").write_text(json.dumps({"iterations": history}, indent=1, default=float))
        behaviour = agent
    if bar is not None:
        bar.close()
    wall_pi = time.time() - t0
    if baseline is not None and history and (out_dir / "best_model.zip").exists():
        model = AlgoClass.load(str(out_dir / "best_model.zip"), env=env, device="cpu", tensorboard_log=str(out_dir))

    ppo: dict[str, Any] | None = None
    if total_timesteps > 0:
        from stable_baselines3.common.callbacks import CallbackList

        callbacks: list[Any] = []
        eval_cb = None
        if baseline is not None and eval_freq > 0:
            eval_cb = _make_eval_callback(
                config, list(eval_seeds), eval_freq * config.n_sections, out_dir,
                lambda m: LineAgent(m.policy, advisor=advisor),
                lambda m, agent, path: _save_line_policy(m, path, meta), "multibinary", verbose,
                evaluate_at_start=True, baseline=baseline)
            callbacks.append(eval_cb)
        t_ppo = time.time()
        # SB3 counts a step of every section agent: n_sections per line-step
        if progress:
            callbacks.append(make_progress_callback(f"train {algo}", unit="section-step"))
        model.learn(total_timesteps=total_timesteps * config.n_sections, callback=CallbackList(callbacks),
                    tb_log_name=algo)
        ppo = {"line_steps": total_timesteps, "wall_seconds": time.time() - t_ppo,
               "evaluations": eval_cb.history if eval_cb is not None else []}
    path = _save_line_policy(model, out_dir / "model.zip", meta)
    summary = {"iterations": history, "policy_iteration_seconds": wall_pi,
               "policy_runs_line_steps": line_steps, "fork_segment_steps": fork_steps,
               # what the physics did per second of the policy iteration: line-steps of the policies' own runs, and
               # the forks' section-steps counted as line-steps (a line-step is n_sections section-steps)
               "line_steps_per_second": (line_steps + fork_steps / config.n_sections) / max(wall_pi, 1e-9),
               "baseline": None if baseline is None else {"policy": baseline.policy, "params": baseline.params,
                                                          "mean_cost": float(baseline.cost.mean()),
                                                          "seeds": baseline.seeds.tolist()},
               "ppo": ppo}
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=1, default=float))
    env.close()
    return path


def export_line_policy(model_zip: str | Path, dest: str | Path = DEFAULT_LINE_PRETRAINED) -> Path:
    """Copy a saved line policy and its JSON to ``dest`` (default the shipped path)."""
    return export_policy(model_zip, dest, sidecar=line_meta_path)


def load_line_trained(path: str | Path | None = None, name: str = "ppo") -> LineAgent:
    """The line policy at ``path`` (default the shipped ``agents/learning/pretrained/ppo_tamping_line.zip``), with SB3's
    ``predict`` on raw observations of any TampingLine scenario (its advisor rule rebuilt from the JSON beside
    it). FileNotFoundError if there is none; ValueError if it was trained on other features."""
    from ..rules.line import LINE_HEURISTICS

    path = Path(path) if path is not None else DEFAULT_LINE_PRETRAINED
    if not path.exists():
        raise FileNotFoundError(f"no trained line policy at {path}")
    meta = json.loads(line_meta_path(path).read_text())
    advisor = meta.get("advisor")
    if meta.get("features") != _feature_names(advisor is not None):
        raise ValueError(f"{line_meta_path(path)}: trained on the features {meta.get('features')}, this version "
                         f"computes {_feature_names(advisor is not None)}")
    model = _algo_class(meta["algo"]).load(str(path), device="cpu")
    rule = None if advisor is None else LINE_HEURISTICS[advisor](**meta.get("advisor_params", {}))
    return LineAgent(model.policy, name=name, advisor=rule)
