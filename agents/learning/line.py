"""Train the per-section policy (:mod:`trackenv_agents.learning.line_policy`) on TampingLine, and load a shipped one.

* :func:`train_line` — **counterfactual policy iteration**, then optionally MaskablePPO:

  1. The policy starts as the best tuned rule (the *advisor*, by default grouped-threshold with its tuned
     parameters), whose choice is also one of the policy's features.
  2. Each iteration runs the current policy on ``episodes_per_iteration`` new training episodes and prices the
     other choice of a random subset of its decisions by forking that one section and letting the policy go on
     deciding for it (:func:`~trackenv_agents.learning.line_counterfactual.section_counterfactuals`: exact replays on
     common random numbers); where sections share a physics segment (the 60 m track, ``"track60"``) the fork is
     the whole line, priced at the whole line's cost
     (:func:`~trackenv_agents.learning.line_counterfactual.line_forks`). The network is then fitted to the cheaper
     choice over every decision priced so far, weighted by what is at stake
     (:func:`~trackenv_agents.learning.imitation.fit_choices`): one step of approximate policy iteration per
     iteration, the data of all earlier policies kept (as AggreVaTe does).
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

from trackenv.envs.line_config import SCENARIOS, LineConfig

from ..shipped import CHOICE_PRETRAINED_FILE, LINE_PRETRAINED_FILE
from .checkpoint import (
    CHECKPOINT_FILE,
    META_FILE,
    Checkpoint,
    capture_random_states,
    finished_run,
    make_checkpoint_callback,
    read_checkpoint,
    read_run_meta,
    refuse_on_resume,
    restore_random_states,
    restore_vec_env_state,
    resume_folder,
    save_model_atomic,
    start_run_folder,
    vec_env_state,
    write_checkpoint,
    write_json_atomic,
)
from .line_policy import ADVISOR_FEATURES, CHOICE_FEATURES, FEATURES, LEARNABLE_CHOICES, LineAgent, is_choice_rule
from .settings import LineSettings
from .tamping import (
    DEFAULT_EVAL_SEEDS,
    DEFAULT_TRAIN_SEED,
    ZooSchema,
    _algo_class,
    _make_eval_callback,
    export_policy,
    load_hyperparams,
    make_progress_callback,
    single_torch_thread,
)

__all__ = ["DEFAULT_CHOICE_PRETRAINED", "DEFAULT_LINE_PRETRAINED", "LINE_ENV_ID", "LINE_ZOO", "export_line_policy",
           "line_meta_path", "load_line_trained", "train_line"]

LINE_ENV_ID = "trackenv/TampingLine-v0"
#: the shipped agents' files (:mod:`trackenv_agents.shipped`): cpi-agent's, and cpi-choice-agent's, the policy of the
#: lines with every choice (the choice rule as advisor: it answers in choice codes)
DEFAULT_LINE_PRETRAINED = LINE_PRETRAINED_FILE
DEFAULT_CHOICE_PRETRAINED = CHOICE_PRETRAINED_FILE
META_SUFFIX = "_meta.json"
#: what :func:`train_line` reads from an RL Zoo entry (see :class:`trackenv_agents.learning.tamping.ZooSchema`)
LINE_ZOO = ZooSchema("MlpPolicy", "one network decides for every section from its features", ("net_arch",), False,
                     LineSettings)


def _feature_names(advisor: bool, choices: bool = False) -> list[str]:
    return [n for n, _ in FEATURES] + (list(ADVISOR_FEATURES) if advisor else []) + (
        list(CHOICE_FEATURES) if choices else [])


def line_meta_path(zip_path: str | Path) -> Path:
    """The JSON beside a saved line policy (``<stem>_meta.json``): algorithm, network, features, advisor (rule
    and parameters), reward scale and the config it was trained on."""
    zip_path = Path(zip_path)
    return zip_path.with_name(zip_path.stem + META_SUFFIX)


def _save_line_policy(model: Any, zip_path: Path, meta: dict) -> Path:
    """``model`` at ``zip_path`` and its JSON (:func:`line_meta_path`), each replaced atomically (a run killed
    while saving leaves the previous file). The optimiser's state is left out (a fresh one is saved): the file
    is the policy, a few tens of kB, not a run to continue (that is the checkpoint's job)."""
    policy = model.policy
    state = policy.optimizer
    policy.optimizer = policy.optimizer_class(policy.parameters(), **state.defaults)
    try:  # nor the last roll-out's observations and episode records
        save_model_atomic(model, zip_path, exclude=["_last_obs", "_last_episode_starts", "_last_original_obs",
                                                    "ep_info_buffer", "ep_success_buffer"])
    finally:
        policy.optimizer = state
    algo = "maskable_ppo" if type(model).__name__ == "MaskablePPO" else "ppo"
    write_json_atomic(line_meta_path(zip_path), {"algo": algo, **meta})
    return Path(zip_path)


def _new_line_settings(hyperparams: LineSettings | dict | str | Path | None, **explicit: Any) -> LineSettings:
    """A new run's settings: the shipped entry, ``hyperparams`` over it key by key (or a whole
    :class:`LineSettings`), then the ``explicit`` arguments that are not None."""
    if isinstance(hyperparams, LineSettings):
        s = hyperparams
    else:
        if isinstance(hyperparams, (str, Path)):
            hyperparams = load_hyperparams(hyperparams, env_id=LINE_ENV_ID, schema=LINE_ZOO)
        s = LineSettings.from_dict(load_hyperparams(env_id=LINE_ENV_ID, schema=LINE_ZOO)).updated(hyperparams or {})
    return s.updated({k: v for k, v in explicit.items() if v is not None})


def train_line(config: LineConfig | dict | str | None = None, total_timesteps: int | None = None,
               n_envs: int | None = None, seed: int | None = None, out_dir: str | Path | None = None,
               hyperparams: LineSettings | dict | str | Path | None = None, progress: bool = True,
               eval_seeds: Sequence[int] | None = DEFAULT_EVAL_SEEDS, iterations: int | None = None,
               episodes_per_iteration: int | None = None, verbose: int = 1, resume: str | Path | None = None,
               checkpoint_every_s: float | None = None, init_policy: str | Path | None = None) -> Path:
    """Train on a TampingLine ``config`` (a LineConfig, its fields as a dict, or a scenario name; default the
    default line) by counterfactual policy iteration (then MaskablePPO for ``total_timesteps`` line-steps, 0 by
    default); save ``out_dir/model.zip`` (+ ``model_meta.json``) and return its path.

    ``hyperparams``: a dict, a flat JSON path or an RL Zoo YAML path (its ``trackenv/TampingLine-v0`` entry)
    overriding the shipped entry of ``agents/learning/hyperparams/ppo.yml`` key by key, or a whole
    :class:`LineSettings`; explicit arguments that are not None override both. Unknown keys and values out of
    range raise ValueError (:class:`LineSettings` lists the fields, their defaults and ranges). ``seed``
    (default :data:`DEFAULT_TRAIN_SEED`): the first training episode. ``eval_seeds=None`` disables the held-out
    evaluation (then the last iteration is the model). ``out_dir`` (default ``runs/ppo_line``) gets
    ``summary.json`` (wall times, line-steps and fork steps per second, every iteration's samples, fit and
    evaluation), ``train_meta.json``, ``best_model.zip``, ``checkpoints/iteration_<i>.zip`` (each iteration's
    policy), TensorBoard logs and ``checkpoint.zip``.

    Checkpoints (:mod:`.checkpoint`; none if ``checkpoint_every_s`` is 0): after the baseline's evaluation and
    after every iteration, the policy, the data of every iteration so far (the next fit pools them), the
    history, the best evaluation and the random generators; in the PPO stage, every ``checkpoint_every_s``
    seconds as :func:`~trackenv_agents.learning.tamping.train` keeps them. ``resume``: the folder of a run to
    continue in place from its last complete iteration (or PPO checkpoint), with the settings, config, seeds
    and held-out seeds it was started with (``eval_seeds`` is the run's own; the other arguments but
    ``progress``, ``verbose`` and ``checkpoint_every_s`` must be None); a finished run returns its model at
    once.

    ``init_policy``: a saved line policy (:func:`load_line_trained`'s files, of the same network and features)
    whose weights the network starts from, e.g. the shipped one: the first iteration then runs and forks that
    policy rather than the advisor, and the fits go on from its weights (policy iteration from a trained agent,
    e.g. onto a new line or a new advisor)."""
    if resume is not None:
        run_dir = resume_folder(resume, out_dir)
        refuse_on_resume(run_dir, config=config, total_timesteps=total_timesteps, n_envs=n_envs, seed=seed,
                         hyperparams=hyperparams, iterations=iterations, episodes_per_iteration=episodes_per_iteration,
                         init_policy=init_policy)
        run_meta = read_run_meta(run_dir)
        ckpt = read_checkpoint(run_dir)
        done = finished_run(run_dir, ckpt.info, int(ckpt.info["total"]))
        if done is not None:
            if verbose:
                print(f"[resume] {run_dir} is finished ({ckpt.info['done']} of {ckpt.info['total']} "
                      f"{ckpt.info['unit']}): {done}", flush=True)
            return done
        s = LineSettings.from_dict(run_meta["hyperparams"])
        if checkpoint_every_s is not None:
            s = s.updated({"checkpoint_every_s": checkpoint_every_s})
        trainer = _LineTrainer(s, LineConfig.coerce(run_meta["config"]), int(run_meta["seed"]), run_dir,
                               run_meta["eval_seeds"], progress, verbose)
        return trainer.run(ckpt)
    s = _new_line_settings(hyperparams, total_timesteps=total_timesteps, n_envs=n_envs, iterations=iterations,
                           episodes_per_iteration=episodes_per_iteration, checkpoint_every_s=checkpoint_every_s)
    run_dir = Path(out_dir) if out_dir is not None else Path("runs/ppo_line")
    start_run_folder(run_dir)
    trainer = _LineTrainer(s, LineConfig.coerce("default" if config is None else config),
                           DEFAULT_TRAIN_SEED if seed is None else int(seed), run_dir,
                           None if eval_seeds is None else [int(x) for x in eval_seeds], progress, verbose)
    if init_policy is not None:
        trainer.start_from(Path(init_policy))
    if verbose:
        print(f"[start] {s.iterations} policy iterations of {s.episodes_per_iteration} training episodes each "
              f"(minutes each on two cores), then {s.total_timesteps} line-steps of {s.algo}: iterations and "
              f"total_timesteps (--iterations, --timesteps) set them", flush=True)
    return trainer.run(None)


class _LineTrainer:
    """One run of :func:`train_line`: the policy iteration, then the PPO stage, each resumable from its
    checkpoint. Built the same way for a new run and a resumed one (the advisor, the section agents' env, a
    model of the settings' network), so that a resumed run replaces only what the checkpoint holds."""

    def __init__(self, s: LineSettings, config: LineConfig, seed: int, run_dir: Path,
                 eval_seeds: list[int] | None, progress: bool, verbose: int) -> None:
        from stable_baselines3.common.utils import set_random_seed

        from .imitation import teacher_policy
        from .sb3_vec import SectionAgentsVecEnv

        self.s, self.config, self.seed, self.run_dir = s, config, seed, run_dir
        self.eval_seeds, self.progress, self.verbose = eval_seeds, progress, verbose
        (run_dir / "checkpoints").mkdir(parents=True, exist_ok=True)
        self.AlgoClass = _algo_class(s.algo)
        single_torch_thread()  # the physics (numba) wants the cores; the small network does not
        set_random_seed(seed)
        self.advisor = teacher_policy(s.advisor, config, None if s.advisor_params is None else dict(s.advisor_params))
        if s.total_timesteps and getattr(self.advisor, "observation_state", False):
            raise ValueError(f"total_timesteps must be 0 with the advisor {s.advisor!r}: the PPO stage's section "
                             "agents ask their advisor on each observation alone, and this planner forecasts from "
                             "the history it has been shown (its recurrent state)")
        #: the choices the network decides (learn_choices: those of LEARNABLE_CHOICES the config enables)
        self.learned: tuple[str, ...] = ("tamp",)
        if s.learn_choices:
            if not is_choice_rule(self.advisor):
                raise ValueError(f"learn_choices needs a choice rule as advisor, got {s.advisor!r}")
            self.learned = tuple(c for c in LEARNABLE_CHOICES if c == "tamp" or c in config.choices)
        if s.campaign_forks and (config.sections_per_segment == 1 or s.learn_choices):
            raise ValueError("campaign_forks prices the tamping of sections that share a segment "
                             f"(sections_per_segment > 1, got {config.sections_per_segment}), without learn_choices")
        self.env = SectionAgentsVecEnv(s.n_envs, config, seed=seed + 1_000_000, reward_scale=s.reward_scale,
                                       advisor=self.advisor, choice_features=s.learn_choices)
        self.model = self.AlgoClass("MlpPolicy", self.env, seed=seed, tensorboard_log=str(run_dir), verbose=0,
                                    device="cpu", policy_kwargs={"net_arch": list(s.net_arch)}, **s.algo_kwargs())
        #: what is saved with every policy (line_meta_path)
        self.meta = {"env_id": _line_env_id(config), "net_arch": list(s.net_arch),
                     "features": _feature_names(True, s.learn_choices), "learned": list(self.learned),
                     "advisor": self.advisor.name, "advisor_params": dict(self.advisor.params),
                     "reward_scale": s.reward_scale, "config": config.to_dict(), "seed": seed}
        self.baseline: Any = None
        #: the saved policy the network started from (train_line's init_policy), if any
        self.init_policy: str | None = None
        #: the choices the saved policy decided (it runs the first iteration that way)
        self.init_learned: tuple[str, ...] = ("tamp",)
        self.checkpoint_seconds = 0.0
        self.checkpoint_count = 0

    def start_from(self, path: Path) -> None:
        """The network's weights from the saved line policy at ``path`` (same network; the same features, or the
        first of this run's: the new inputs get zero weights, so the network answers as the saved one did),
        else ValueError."""
        meta = json.loads(line_meta_path(path).read_text())
        features = list(meta.get("features") or [])
        if features != self.meta["features"][:len(features)] or not features \
                or list(meta.get("net_arch", [])) != self.meta["net_arch"]:
            raise ValueError(f"init_policy {path}: features {meta.get('features')} and network {meta.get('net_arch')}"
                             f", this run has {self.meta['features']} and {self.meta['net_arch']}")
        source = _algo_class(meta["algo"]).load(str(path), device="cpu")
        self.model.policy.load_state_dict(_widened_inputs(source.policy.state_dict(), self.model.policy.state_dict()))
        self.init_policy = str(path)
        self.init_learned = tuple(_meta(meta, "learned"))

    def _agent(self, policy: Any, learned: tuple[str, ...] | None = None) -> LineAgent:
        """The line agent of ``policy`` with this run's advisor and features, deciding ``learned`` (default the
        run's choices)."""
        return LineAgent(policy, advisor=self.advisor, choice_features=self.s.learn_choices,
                         learned=self.learned if learned is None else learned)

    # --- checkpoints ---
    def _checkpoint(self, info: dict[str, Any], state: dict[str, Any]) -> None:
        if self.s.checkpoint_every_s <= 0:
            return
        t0 = time.monotonic()
        write_checkpoint(self.run_dir, {"trainer": "line", **info},
                         {"random": capture_random_states(), "baseline": self.baseline, **state}, self.model)
        self.checkpoint_seconds += time.monotonic() - t0
        self.checkpoint_count += 1

    def _pi_checkpoint(self, pi: dict[str, Any]) -> None:
        self._checkpoint({"phase": "policy_iteration", "unit": "iterations", "done": pi["done"],
                          "total": self.s.iterations, "finished": False}, {"policy_iteration": pi})

    # --- the run ---
    def run(self, ckpt: Checkpoint | None) -> Path:
        if ckpt is None:
            write_json_atomic(self.run_dir / META_FILE, {"trainer": "line", "algo": self.s.algo,
                                                         "hyperparams": self.s.to_dict(), **self.meta,
                                                         "eval_seeds": self.eval_seeds,
                                                         "init_policy": self.init_policy})
            self._evaluate_baseline()
            pi = {"done": 0, "data": [], "history": [], "best": -np.inf, "line_steps": 0, "fork_steps": 0,
                  "seconds": 0.0}
            self._pi_checkpoint(pi)
        else:
            self.baseline = ckpt.state["baseline"]
            pi = ckpt.state["policy_iteration"]
            if ckpt.info["phase"] == "policy_iteration":
                self.model = self.AlgoClass.load(ckpt.model_file(), env=self.env, device="cpu",
                                                 tensorboard_log=str(self.run_dir))
            restore_random_states(ckpt.state["random"])
            if self.verbose:
                print(f"[resume] {self.run_dir}: {ckpt.info['phase']}, {ckpt.info['done']} of "
                      f"{ckpt.info['total']} {ckpt.info['unit']} done", flush=True)
        if ckpt is None or ckpt.info["phase"] == "policy_iteration":
            self._policy_iteration(pi)
            ppo_ckpt = None
        else:
            ppo_ckpt = ckpt
        ppo = self._ppo_stage(pi, ppo_ckpt) if self.s.total_timesteps > 0 else None
        path = _save_line_policy(self.model, self.run_dir / "model.zip", self.meta)
        self._checkpoint({"phase": "finished", "unit": "iterations", "done": pi["done"], "total": self.s.iterations,
                          "finished": True}, {"policy_iteration": pi})
        write_json_atomic(self.run_dir / "summary.json", self._summary(pi, ppo))
        self.env.close()
        return path

    def _evaluate_baseline(self) -> None:
        """The advisor on the held-out episodes: every evaluation is paired with it."""
        from ..evaluation.harness import evaluate_one

        if not self.eval_seeds:
            return
        t_base = time.time()
        self.baseline = evaluate_one(self.advisor, self.config, self.eval_seeds, batch_size=len(self.eval_seeds))
        if self.verbose:
            from ..evaluation.reporting import count_text

            b = self.baseline
            print(f"[baseline] {b.policy}: {b.cost.mean():.1f} k€ on {count_text(b.n_episodes, 'held-out episode')} "
                  f"({time.time() - t_base:.0f} s)", flush=True)

    def _evaluate(self, agent: LineAgent) -> dict[str, Any]:
        from ..evaluation.harness import evaluate_one
        from ..evaluation.statistics import paired_difference

        assert self.eval_seeds  # only called with a baseline
        t_eval = time.time()
        res = evaluate_one(agent, self.config, self.eval_seeds, batch_size=len(self.eval_seeds))
        return {"mean_cost": float(res.cost.mean()), "mean_return": float(res.sum_rewards.mean()),
                "vs_baseline": paired_difference(res, self.baseline), "eval_seconds": time.time() - t_eval,
                "cost_parts": {k: float(v.mean()) for k, v in res.cost_parts.items()}}

    def _logger(self, history: list[dict[str, Any]]) -> Any:
        """The policy iteration's CSV and TensorBoard logger. A resumed run writes the earlier iterations' rows
        into the CSV again (stable-baselines3's CSV output starts its file afresh); TensorBoard keeps them."""
        from stable_baselines3.common.logger import Logger, make_output_format

        folder = str(self.run_dir / "policy_iteration")
        logger = Logger(folder, [make_output_format("csv", folder)])
        for rec in history:
            _log_iteration(logger, rec)
        logger.output_formats.append(make_output_format("tensorboard", folder))
        return logger

    def _policy_iteration(self, pi: dict[str, Any]) -> None:
        """Iterations ``pi["done"]`` to the settings' last, each checkpointed (``pi`` is updated in place)."""
        from .imitation import fit_choices
        from .line_campaigns import campaign_counterfactuals
        from .line_counterfactual import section_counterfactuals

        s, config, seed = self.s, self.config, self.seed
        n_episodes, H = s.episodes_per_iteration, config.horizon_steps
        logger = self._logger(pi["history"])
        bar = None
        if self.progress:
            from tqdm.auto import tqdm

            bar = tqdm(total=s.iterations * H, initial=pi["done"] * H, desc="policy iteration", unit="step")
        started = pi["done"] > 0 or self.init_policy is not None or _run_started_from(self.run_dir)
        first = self.init_learned if pi["done"] == 0 and self.init_policy is not None else self.learned
        behaviour: Any = self._agent(self.model.policy, first) if started else self.advisor
        for it in range(pi["done"], s.iterations):
            t_it = time.time()
            seeds = list(range(seed + it * n_episodes, seed + (it + 1) * n_episodes))
            priced = campaign_counterfactuals if s.campaign_forks else section_counterfactuals
            more: dict[str, Any] = ({} if s.campaign_forks
                                    else {"choices": self.learned, "choice_features": s.learn_choices})
            d = priced(config, seeds, behaviour, advisor=self.advisor, focus_rate=s.focus_rate,
                       other_rate=s.other_rate, seed=seed + it, progress=bar.update if bar is not None else None,
                       **more)
            t_forks = time.time() - t_it
            pi["data"].append(d)
            pooled = {k: np.concatenate([x[k] for x in pi["data"]]) for k in d}
            fit = fit_choices(self.model, pooled, s.reward_scale, epochs=s.fit_epochs, margin=s.fit_margin,
                              seed=seed + it)
            pi["line_steps"] += n_episodes * H
            # a fork is one segment where each carries one section, else its whole line (line_forks)
            pi["fork_steps"] += _fork_steps(d, H, config)
            rec: dict[str, Any] = {"iteration": it, "seeds": [seeds[0], seeds[-1]], "samples": int(d["step"].size),
                                   "other_choice_cheaper": float(np.mean((d["q_do"] < d["q_skip"]) != d["did"])),
                                   "samples_per_choice": {name: int(np.sum(d["choice"] == i))
                                                          for i, name in enumerate(self.learned)},
                                   "fork_seconds": t_forks, "fit_seconds": time.time() - t_it - t_forks, "fit": fit}
            behaviour = self._agent(self.model.policy)
            _save_line_policy(self.model, self.run_dir / "checkpoints" / f"iteration_{it}.zip", self.meta)
            if self.baseline is not None:
                rec["evaluation"] = self._evaluate(behaviour)
                if rec["evaluation"]["mean_return"] > pi["best"]:
                    pi["best"] = rec["evaluation"]["mean_return"]
                    _save_line_policy(self.model, self.run_dir / "best_model.zip", self.meta)
            _log_iteration(logger, rec)
            pi["history"].append(rec)
            pi["done"] = it + 1
            pi["seconds"] += time.time() - t_it
            if self.verbose:
                self._print_iteration(rec, time.time() - t_it)
            write_json_atomic(self.run_dir / "summary.json", {"iterations": pi["history"]})
            self._pi_checkpoint(pi)
        if bar is not None:
            bar.close()
        logger.close()
        if self.baseline is not None and pi["history"] and (self.run_dir / "best_model.zip").exists():
            self.model = self.AlgoClass.load(str(self.run_dir / "best_model.zip"), env=self.env, device="cpu",
                                             tensorboard_log=str(self.run_dir))

    def _print_iteration(self, rec: dict[str, Any], seconds: float) -> None:
        from ..evaluation.reporting import ci_text

        ev, fit = rec.get("evaluation"), rec["fit"]
        vs = ""
        if ev is not None:
            d = ev["vs_baseline"]
            vs = (f"; held-out {ev['mean_cost']:.1f} k€, vs {self.baseline.policy} {d['mean_difference']:+.1f} "
                  f"{ci_text(d['ci_low'], d['ci_high'], d['n_episodes'], signed=True)}")
        print(f"[iteration {rec['iteration']}] {rec['samples']} decisions priced ({rec['other_choice_cheaper']:.1%} "
              f"cheaper the other way), fit {fit['weighted_target_share']:.3f}{vs} ({seconds:.0f} s)", flush=True)

    def _ppo_stage(self, pi: dict[str, Any], ckpt: Checkpoint | None) -> dict[str, Any]:
        """MaskablePPO on the section agents from the best iteration for the settings' line-steps, with the
        held-out evaluation and periodic checkpoints; continued from ``ckpt`` (a PPO checkpoint) if given."""
        from stable_baselines3.common.callbacks import CallbackList

        s, config = self.s, self.config
        total = s.total_timesteps * config.n_sections  # SB3 counts a step of every section agent
        if ckpt is not None:
            self.model = self.AlgoClass.load(ckpt.model_file(), env=self.env, device="cpu", force_reset=False,
                                             tensorboard_log=str(self.run_dir))
            restore_vec_env_state(self.env, ckpt.state["env"])
            restore_random_states(ckpt.state["random"])  # last: loading the model reseeded them
        callbacks: list[Any] = []
        eval_cb = None
        if self.baseline is not None and s.eval_freq > 0:
            eval_cb = _make_eval_callback(
                config, list(self.eval_seeds or []), s.eval_freq * config.n_sections, self.run_dir,
                lambda m: self._agent(m.policy),
                lambda m, agent, path: _save_line_policy(m, path, self.meta), "multibinary", self.verbose,
                evaluate_at_start=ckpt is None, baseline=self.baseline)
            if ckpt is not None and ckpt.state["evaluation"] is not None:
                eval_cb.set_state(ckpt.state["evaluation"])
            callbacks.append(eval_cb)

        def save(model: Any) -> None:
            self._checkpoint({"phase": "ppo", "unit": "iterations", "done": pi["done"], "total": s.iterations,
                              "ppo_timesteps": int(model.num_timesteps), "ppo_total": total, "finished": False},
                             {"policy_iteration": pi, "env": vec_env_state(self.env),
                              "evaluation": eval_cb.get_state() if eval_cb is not None else None})

        if s.checkpoint_every_s > 0:
            callbacks.append(make_checkpoint_callback(s.checkpoint_every_s, save, at_start=ckpt is None))
        if self.progress:
            callbacks.append(make_progress_callback(f"train {s.algo}", unit="section-step"))
        rollout = int(self.model.n_steps) * int(self.model.n_envs)  # section-steps a roll-out collects
        if self.verbose and total % rollout:
            runs = -(-total // rollout)
            print(f"[note] {s.algo} collects whole roll-outs of {rollout} section-steps "
                  f"({rollout / config.n_sections:g} line-steps): total_timesteps={s.total_timesteps} line-steps "
                  f"run as {runs} roll-out{'s' * (runs > 1)}, {runs * rollout // config.n_sections} line-steps",
                  flush=True)
        t_ppo = time.time()
        start = int(self.model.num_timesteps) if ckpt is not None else 0
        self.model.learn(total_timesteps=max(total - start, 0), callback=CallbackList(callbacks), tb_log_name=s.algo,
                         reset_num_timesteps=ckpt is None)
        return {"line_steps": s.total_timesteps, "line_steps_run": int(self.model.num_timesteps) // config.n_sections,
                "wall_seconds": time.time() - t_ppo,
                "resumed_from_line_steps": None if ckpt is None else start // config.n_sections,
                "evaluations": eval_cb.history if eval_cb is not None else []}

    def _summary(self, pi: dict[str, Any], ppo: dict[str, Any] | None) -> dict[str, Any]:
        b, config = self.baseline, self.config
        return {"iterations": pi["history"], "policy_iteration_seconds": pi["seconds"],
                "policy_runs_line_steps": pi["line_steps"], "fork_segment_steps": pi["fork_steps"],
                # what the physics did per second of the policy iteration: line-steps of the policies' own runs,
                # and the forks' segment-steps counted as line-steps (a line-step is n_segments segment-steps)
                "line_steps_per_second": (pi["line_steps"] + pi["fork_steps"] / config.n_segments)
                / max(pi["seconds"], 1e-9),
                "baseline": None if b is None else {"policy": b.policy, "params": b.params,
                                                    "mean_cost": float(b.cost.mean()), "seeds": b.seeds.tolist()},
                "ppo": ppo,
                "checkpoints": {"count": self.checkpoint_count, "seconds": self.checkpoint_seconds,
                                "bytes": (self.run_dir / CHECKPOINT_FILE).stat().st_size}
                if self.checkpoint_count else None}


def dearer_than_advisor(evaluation: dict[str, Any], what: str = "iteration") -> str | None:
    """One warning line where a held-out evaluation of :func:`train_line` (an iteration's ``evaluation`` in
    summary.json, or with ``what`` another, e.g. the MaskablePPO stage's; the run's best one) is dearer than the
    advisor rule, paired on at least 2 episodes with the whole 95 % CI of the difference above zero: the run then
    saved a policy the rule beats (``best_model.zip`` is only the best of its evaluations), and says so rather than
    leave it to pass for an improvement; None otherwise."""
    d = evaluation["vs_baseline"]
    if d["n_episodes"] < 2 or d["ci_low"] <= 0:
        return None
    from ..evaluation.reporting import ci_text

    return (f"warning: the best held-out {what} costs {d['mean_difference']:+.1f} k€ "
            f"{ci_text(d['ci_low'], d['ci_high'], d['n_episodes'], signed=True)} per episode more than its advisor "
            f"{d['b']}: the rule stays the better policy; more iterations (--iterations) or training episodes "
            "(episodes_per_iteration in --hyperparams) are needed")


def _line_env_id(config: LineConfig) -> str:
    """The registered id whose line preset ``config`` is (any horizon or engine:
    :func:`~trackenv_agents.rules.problems.as_preset`; a TampingLine id, or ``trackenv/Tamping-v1`` for the 60 m
    track), else :data:`LINE_ENV_ID` (the hyper-parameter file's entry): what a saved policy's
    metadata says it was trained on."""
    import gymnasium as gym

    import trackenv  # noqa: F401  (registers the ids)

    from ..evaluation.line_compare import scenario_of
    from ..rules.problems import preset_of

    preset = preset_of(config)
    for env_id in sorted(gym.registry):
        try:
            name = scenario_of(env_id)
        except ValueError:  # not an id of a line preset
            continue
        if preset is not None and name == preset:
            return env_id
    return LINE_ENV_ID


def _fork_steps(samples: dict[str, np.ndarray], horizon_steps: int, config: LineConfig) -> int:
    """Segment-steps the forks behind ``samples`` ran: a fork is one segment where each carries one section, else
    its whole line (line_forks); campaign forks (``branches``) are per line-step, each branch but the policy's."""
    if "branches" in samples:
        _, first = np.unique(np.stack([samples["seed"], samples["step"]]), axis=1, return_index=True)
        return int(np.sum((samples["branches"][first] - 1) * (horizon_steps - samples["step"][first]))) \
            * config.n_segments
    return int(np.sum(horizon_steps - samples["step"])) * (1 if config.sections_per_segment == 1
                                                           else config.n_segments)


def _run_started_from(run_dir: Path) -> bool:
    """Whether the run in ``run_dir`` started from a saved policy (its ``init_policy``): a resumed run at its
    first iteration then runs that network, not the advisor."""
    meta = run_dir / META_FILE
    return meta.exists() and json.loads(meta.read_text()).get("init_policy") is not None


def _log_iteration(logger: Any, rec: dict[str, Any]) -> None:
    """One iteration's record in the policy iteration's logs (step: the iteration)."""
    if "evaluation" in rec:
        logger.record("eval/mean_cost", rec["evaluation"]["mean_cost"])
        logger.record("eval/vs_baseline", rec["evaluation"]["vs_baseline"]["mean_difference"])
    for k in ("samples", "other_choice_cheaper"):
        logger.record(f"policy_iteration/{k}", rec[k])
    logger.record("policy_iteration/target_share", rec["fit"]["target_share"])
    logger.record("policy_iteration/value_mse", rec["fit"]["value_mse"])
    logger.dump(rec["iteration"])


def _widened_inputs(source: dict[str, Any], target: dict[str, Any]) -> dict[str, Any]:
    """``source`` (a network's state dict) shaped as ``target``: an input layer's weights (F_old inputs) padded with
    zero columns to ``target``'s F_new inputs (the inputs added last then change nothing); any other shape that
    differs raises ValueError."""
    import torch

    out = {}
    for key, value in source.items():
        want = target[key].shape
        if value.shape != want:
            if value.ndim != 2 or value.shape[0] != want[0] or value.shape[1] > want[1]:
                raise ValueError(f"{key}: shape {tuple(value.shape)} does not widen to {tuple(want)}")
            value = torch.cat([value, value.new_zeros(want[0], want[1] - value.shape[1])], dim=1)
        out[key] = value
    return out


def export_line_policy(model_zip: str | Path, dest: str | Path = DEFAULT_LINE_PRETRAINED) -> Path:
    """Copy a saved line policy and its JSON to ``dest`` (default the shipped path)."""
    return export_policy(model_zip, dest, sidecar=line_meta_path)


def load_line_trained(path: str | Path | None = None, name: str = "ppo") -> LineAgent:
    """The line policy at ``path`` (default the shipped ``agents/learning/pretrained/ppo_tamping_line.zip``), with SB3's
    ``predict`` on raw observations of any TampingLine scenario (its advisor rule rebuilt from the JSON beside
    it). The JSON's ``preset_weights`` (preset name -> a saved policy's file beside it, of the same features,
    advisor and learned choices) are the networks it plays on those presets (``LineAgent``'s
    ``preset_policies``). FileNotFoundError if there is none; ValueError if it was trained on other features."""
    from ..rules.problems import advisor_rules

    path = Path(path) if path is not None else DEFAULT_LINE_PRETRAINED
    meta, model = _load_line_policy(path)
    advisor = meta.get("advisor")
    rule = None if advisor is None else advisor_rules()[advisor](**meta.get("advisor_params", {}))
    # what a preset's network must share with the agent's (a choice rule as advisor is tuned per config anyway)
    same = ("features", "advisor", "learned") + (() if is_choice_rule(rule) else ("advisor_params",))
    presets = {}
    for preset, file in (meta.get("preset_weights") or {}).items():
        other, network = _load_line_policy(path.with_name(file))
        if preset not in SCENARIOS or any(_meta(other, k) != _meta(meta, k) for k in same):
            raise ValueError(f"{line_meta_path(path)}: preset_weights {preset!r}: {file} must be a preset's "
                             f"({sorted(SCENARIOS)}) network of the same {', '.join(same)}")
        presets[preset] = network.policy
    return LineAgent(model.policy, name=name, advisor=rule, horizon_years=meta.get("config", {}).get("horizon_years"),
                     choice_features=CHOICE_FEATURES[0] in (meta.get("features") or []),
                     learned=tuple(_meta(meta, "learned")), preset_policies=presets)


#: the metadata's values where a file written before the key existed has none
_META_DEFAULTS: dict[str, Any] = {"learned": ["tamp"]}


def _meta(meta: dict[str, Any], key: str) -> Any:
    """A saved line policy's metadata entry ``key``, or its default where the file predates it."""
    return meta.get(key, _META_DEFAULTS.get(key))


def _load_line_policy(path: Path) -> tuple[dict[str, Any], Any]:
    """The metadata and the model of the saved line policy at ``path``, its features checked against this
    version's."""
    if not path.exists():
        raise FileNotFoundError(f"no trained line policy at {path}")
    meta = json.loads(line_meta_path(path).read_text())
    advisor = meta.get("advisor")
    choice_features = CHOICE_FEATURES[0] in (meta.get("features") or [])
    if meta.get("features") != _feature_names(advisor is not None, choice_features):
        raise ValueError(f"{line_meta_path(path)}: trained on the features {meta.get('features')}, this version "
                         f"computes {_feature_names(advisor is not None, choice_features)}")
    return meta, _algo_class(meta["algo"]).load(str(path), device="cpu")
