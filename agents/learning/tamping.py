"""Train PPO / MaskablePPO on the tamping environment, and load the shipped policy.

* :func:`train` — SB3 PPO (or sb3-contrib MaskablePPO) on :class:`~.sb3_vec.TampingSB3VecEnv` with
  VecMonitor + VecNormalize (observations and rewards), TensorBoard logs, checkpoints, a held-out-seed
  evaluation callback and reproducible seeding. Hyper-parameters: ``agents/learning/hyperparams/ppo.yml`` (RL Zoo's
  form, one entry per env id), read by :func:`load_hyperparams`.
* :func:`load_trained` — a trained policy (a run's ``model.zip``, or one exported with :func:`export_policy` to
  ``agents/learning/pretrained/ppo_tamping.zip``, where none ships today, + its observation statistics) as an
  object with SB3-style ``predict`` on *raw* env observations.

Policies are scored by :func:`trackenv_agents.evaluation.harness.evaluate_one` (the held-out evaluation during
training too); the baselines are the heuristics (:class:`~trackenv_agents.rules.line.LineNoMaintenance`,
:class:`~trackenv_agents.rules.base.RandomPolicy`).
"""

from __future__ import annotations

import copy
import importlib
import json
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from trackenv.envs.line_config import LineConfig
from trackenv.envs.problems import problem_config
from trackenv.envs.wrappers import ranked_choice_masks, ranked_fit

from ..evaluation.harness import evaluate_one
from .actions import RANKED, RANKED_CHOICES, decode_ranked_choices, env_action_type, ranked_to_sections
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
from .sb3_vec import TampingSB3VecEnv, filter_observation
from .settings import AlgoSettings, TampingSettings, TrainingSettings

HERE = Path(__file__).resolve().parent
DEFAULT_HYPERPARAMS = HERE / "hyperparams" / "ppo.yml"
DEFAULT_ENV_ID = "trackenv/Tamping-v1"
DEFAULT_PRETRAINED = HERE / "pretrained" / "ppo_tamping.zip"
DEFAULT_EVAL_SEEDS = tuple(range(10_000, 10_016))
# training env i starts with seed DEFAULT_TRAIN_SEED + i: apart from the test (0-199), tuning (1000-1099) and
# evaluation (10000-10015) seeds, so that no held-out episode is ever trained on
DEFAULT_TRAIN_SEED = 20_000
STATS_SUFFIX = "_obs_stats.json"

# keys of the flat hyper-parameters that go to the algorithm's constructor (the rest configure train() itself)
_ALGO_KEYS = AlgoSettings.ALGO_KEYS


@dataclass(frozen=True)
class ZooSchema:
    """What one trainer reads from an RL Zoo entry: the ``policy`` it builds (and why that one), the
    ``policy_kwargs`` it honours (flattened into the hyper-parameters), whether it trains under VecNormalize
    (``normalize``) and its ``settings`` class, whose fields are every flat key it reads (``keys``; others
    raise ValueError)."""

    policy: str
    policy_note: str
    policy_keys: tuple[str, ...]
    normalize: bool
    settings: type[TrainingSettings]

    @property
    def keys(self) -> tuple[str, ...]:
        return self.settings.field_names()


#: the schema of :func:`train` (the 60 m track, Tamping-v1); TampingLine's is ``trackenv_agents.learning.line.LINE_ZOO``
TAMPING_ZOO = ZooSchema("MultiInputPolicy", "the observation is a Dict", ("net_arch",), True, TampingSettings)


def load_hyperparams(path: str | Path | None = None, env_id: str = DEFAULT_ENV_ID,
                     schema: ZooSchema = TAMPING_ZOO) -> dict[str, Any]:
    """The flat hyper-parameters that a trainer (:func:`train`, or the line's with its ``schema``) reads, from
    ``path`` (default ``agents/learning/hyperparams/ppo.yml``): a YAML file in RL Zoo's form (its entry for ``env_id``,
    see :func:`from_zoo`) or a flat JSON object of the same keys: those the file sets, to override settings key
    by key. Unknown keys, and values out of their range (see ``schema.settings``), raise ValueError."""
    path = Path(path) if path is not None else DEFAULT_HYPERPARAMS
    if path.suffix in (".yml", ".yaml"):
        import yaml

        try:
            table = yaml.safe_load(path.read_text()) or {}
        except (yaml.YAMLError, UnicodeDecodeError) as exc:
            raise ValueError(f"{path}: not a YAML file ({' '.join(str(exc).split())})") from None
        if not isinstance(table, dict):
            raise ValueError(f"{path}: an RL Zoo file is a mapping of env ids to entries, got {type(table).__name__}")
        if env_id not in table:
            raise ValueError(f"{path} has no entry for env id {env_id!r} (it has {sorted(table)})")
        if not isinstance(table[env_id], dict):
            raise ValueError(f"{path}: the entry for {env_id!r} must be a mapping of settings, got "
                             f"{type(table[env_id]).__name__}")
        hp = from_zoo(table[env_id], schema)
    else:
        try:
            hp = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ValueError(f"{path}: not a JSON object of hyper-parameters ({exc}); a YAML file in RL Zoo's form "
                             "needs the .yml or .yaml suffix") from None
    if not isinstance(hp, dict):
        raise ValueError(f"{path}: hyper-parameters must be a mapping of names to values, got {hp!r}")
    schema.settings.from_dict(hp)  # unknown keys and values out of range raise here, naming the file's key
    return hp


def from_zoo(entry: dict[str, Any], schema: ZooSchema = TAMPING_ZOO) -> dict[str, Any]:
    """One RL Zoo entry as flat hyper-parameters: the algorithm's arguments as they are; Zoo's ``n_timesteps``
    → ``total_timesteps``, ``policy_kwargs`` (those of ``schema.policy_keys``, e.g. ``net_arch``) as they are,
    ``normalize.clip_obs`` → ``clip_obs``, ``n_envs`` as is; the ``trackenv`` block's training options merged
    in. What the trainer cannot honour (another policy class, other policy_kwargs, training without
    normalisation under VecNormalize's schema, with it under the line's) raises ValueError."""
    e = dict(entry)
    hp = dict(e.pop("trackenv", None) or {})
    policy = e.pop("policy", schema.policy)
    if policy != schema.policy:
        raise ValueError(f"policy must be {schema.policy} ({schema.policy_note}), got {policy!r}")
    kwargs = dict(e.pop("policy_kwargs", None) or {})
    unsupported = sorted(set(kwargs) - set(schema.policy_keys))
    if unsupported:
        raise ValueError(f"unsupported policy_kwargs {unsupported} (only {', '.join(schema.policy_keys)})")
    hp.update({k: list(v) if k == "net_arch" else v for k, v in kwargs.items()})
    if "n_timesteps" in e:
        hp["total_timesteps"] = int(e.pop("n_timesteps"))
    norm = e.pop("normalize", None)
    if norm is not None and schema.normalize:
        norm = dict(norm) if isinstance(norm, dict) else {"norm_obs": bool(norm), "norm_reward": bool(norm)}
        if not (norm.pop("norm_obs", True) and norm.pop("norm_reward", True)):
            raise ValueError("train() always normalises observations and rewards (VecNormalize)")
        if "clip_obs" in norm:
            hp["clip_obs"] = float(norm.pop("clip_obs"))
        if norm:
            raise ValueError(f"unsupported normalize keys {sorted(norm)}")
    elif norm is not None and (any(dict(norm).values()) if isinstance(norm, dict) else bool(norm)):
        raise ValueError(f"normalize must be false for {schema.policy}: it normalises with fixed scales of its own")
    hp.update(e)
    return hp


def single_torch_thread() -> None:
    """One thread for torch, the cores for the physics. Numba's OpenMP threading layer sets the process's
    OpenMP thread count when it starts (at the first parallel physics call), and torch reads that same count:
    so numba's threads are started first, then torch's count is set. The other order left torch on 2 threads
    competing with numba's, and every small torch op ~50x slower after the first env step (measured: a
    behaviour-cloning fit took 630 s instead of 15 s)."""
    import numba
    import torch

    numba.get_num_threads()  # starts numba's threading layer
    torch.set_num_threads(1)


#: the stable-baselines3 / sb3-contrib algorithms a saved model is loaded with, by the name its sidecar gives
#: (``algo``): module and class
SB3_ALGOS: dict[str, tuple[str, str]] = {"ppo": ("stable_baselines3", "PPO"), "a2c": ("stable_baselines3", "A2C"),
                                         "dqn": ("stable_baselines3", "DQN"),
                                         "maskable_ppo": ("sb3_contrib", "MaskablePPO")}


def _algo_class(algo: str):
    if algo not in SB3_ALGOS:
        raise ValueError(f"algo must be one of {sorted(SB3_ALGOS)}, got {algo!r}")
    module, name = SB3_ALGOS[algo]
    return getattr(importlib.import_module(module), name)


# --- policies on raw observations ---
class NormalizedPolicy:
    """An SB3 model plus frozen VecNormalize observation statistics: ``predict`` on raw env observations
    (one observation dict, or a batched one), the interface of SB3's ``model.predict``.

    A model trained in the ``ranked`` parameterisation (:mod:`trackenv_agents.learning.actions`) answers with the env's
    MultiBinary actions (its count of worst sections translated on the observation's SD); one in ``ranked_choices``
    (a count per enabled choice of the line ``config``) with the env's choice codes, decoded on the observation and
    the env's action masks, which ``predict`` then needs (``action_masks``, as the harness passes them). Given the
    env's masks, a MaskablePPO model is masked with its own (the env's, or those of its ranked counts)."""

    def __init__(self, model, obs_keys: Sequence[str], mean: dict, var: dict, clip_obs: float = 10.0,
                 epsilon: float = 1e-8, name: str = "ppo", algo: str = "ppo",
                 action_type: str = "multibinary", config: Any = None, raw_keys: Sequence[str] = ()) -> None:
        self.model = model
        self.obs_keys = list(obs_keys)
        self.mean = {k: np.asarray(mean[k], dtype=np.float64) for k in self.obs_keys}
        self.var = {k: np.asarray(var[k], dtype=np.float64) for k in self.obs_keys}
        self.clip_obs = float(clip_obs)
        self.epsilon = float(epsilon)
        self.name = name
        self.algo = algo
        self.action_type = action_type
        #: the keys the model read as the env gives them (a VecNormalize that normalised only some, or none)
        self.raw_keys = [k for k in raw_keys if k in self.obs_keys]
        self.heads: tuple[str, ...] | None = None
        self.fit: tuple[np.ndarray, float] | None = None
        if action_type == RANKED_CHOICES:  # what its counts rank: the line's enabled choices, capped by the possession
            if config is None:
                raise ValueError("a ranked_choices policy needs the config of the line it was trained on")
            line = LineConfig.coerce(config)
            self.heads = tuple(line.choices)
            self.fit = ranked_fit(line, self.heads, line.n_sections)

    @classmethod
    def from_vecnormalize(cls, model, vecnorm, obs_keys: Sequence[str], **kw) -> NormalizedPolicy:
        rms = vecnorm.obs_rms
        return cls(model, obs_keys, {k: rms[k].mean.copy() for k in obs_keys},
                   {k: rms[k].var.copy() for k in obs_keys}, clip_obs=vecnorm.clip_obs,
                   epsilon=vecnorm.epsilon, **kw)

    def normalize(self, obs: dict) -> dict:
        obs = filter_observation(obs, self.obs_keys)
        return {k: np.asarray(obs[k], dtype=np.float32) if k in self.raw_keys else
                np.clip((np.asarray(obs[k], dtype=np.float64) - self.mean[k]) / np.sqrt(self.var[k] + self.epsilon),
                        -self.clip_obs, self.clip_obs).astype(np.float32) for k in self.obs_keys}

    def predict(self, observation: dict, state=None, episode_start=None, deterministic: bool = True,
                action_masks: np.ndarray | None = None):
        """The env's actions for ``observation``; ``action_masks``: the env's (``env.action_masks()``), or None."""
        own = self._own_masks(action_masks)
        kw = {} if own is None or self.algo != "maskable_ppo" else {"action_masks": own}
        action, state = self.model.predict(self.normalize(observation), state=state, episode_start=episode_start,
                                           deterministic=deterministic, **kw)
        if self.action_type == RANKED:
            action = ranked_to_sections(action, observation["section_sd"])
        elif self.action_type == RANKED_CHOICES:
            action = decode_ranked_choices(self.name, action, observation, action_masks, self.heads)
        return action, state

    def _own_masks(self, env_masks: np.ndarray | None) -> np.ndarray | None:
        """The model's masks from the env's: none for ranked counts of tamping (every count is valid), the counts'
        masks for ranked choices, else the env's own."""
        if env_masks is None or self.action_type == RANKED:
            return None
        if self.action_type == RANKED_CHOICES:
            assert self.heads is not None
            return ranked_choice_masks(env_masks, self.heads, self.fit)
        return np.asarray(env_masks)

    def stats_dict(self) -> dict:
        return {"obs_keys": self.obs_keys, "mean": {k: v.tolist() for k, v in self.mean.items()},
                "var": {k: v.tolist() for k, v in self.var.items()}, "clip_obs": self.clip_obs,
                "epsilon": self.epsilon, "algo": self.algo, "action_type": self.action_type,
                **({"raw_keys": self.raw_keys} if self.raw_keys else {})}


# --- callbacks ---
def make_progress_callback(desc: str, unit: str = "step"):
    """A progress bar over the timesteps of one ``model.learn`` call (tqdm, a dependency of the library), for
    ``callback=``. stable-baselines3's own (``progress_bar=True``) needs ``rich`` as well, which the ``rl`` extra
    does not install: ``trackenv train`` without ``--json`` raised ImportError."""
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm.auto import tqdm

    class TqdmProgress(BaseCallback):
        """Advances by the vector env's width at every step; closed at the end of training."""

        def _on_training_start(self) -> None:
            # on-policy algorithms collect whole rollouts: the run ends at the first multiple of one past the total
            rollout = getattr(self.model, "n_steps", 1) * self.training_env.num_envs
            remaining = self.locals["total_timesteps"] - self.model.num_timesteps
            self.bar = tqdm(total=-(-remaining // rollout) * rollout, desc=desc, unit=unit)

        def _on_step(self) -> bool:
            self.bar.update(self.training_env.num_envs)
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    return TqdmProgress()


def _make_eval_callback(config, eval_seeds, eval_freq, out_dir: Path, make_policy: Callable, save_policy: Callable,
                        action_type: str, verbose: int, evaluate_at_start: bool = False, on_evaluation=None,
                        baseline: Any = None):
    """The held-out evaluation during training. ``make_policy(model)``: the policy to score, with ``predict``
    on raw observations; ``save_policy(model, policy, path)`` keeps the best one. ``baseline``: an
    :class:`~trackenv_agents.evaluation.harness.EvaluationResult` on the same seeds (e.g. the rule the learner was
    cloned from): each evaluation then records the paired difference of the costs (common random numbers)."""
    from stable_baselines3.common.callbacks import BaseCallback

    from ..evaluation.statistics import paired_difference

    class HeldOutEvalCallback(BaseCallback):
        """Every ``eval_freq`` timesteps (and at the end): deterministic returns on held-out seeds with the
        current policy (and its VecNormalize statistics); logs ``eval/mean_return`` (and
        ``eval/vs_baseline`` with a baseline), keeps ``best_model.zip``."""

        def __init__(self):
            super().__init__(verbose)
            self.last_eval = 0
            self.best = -np.inf
            self.history: list[dict] = []

        def _evaluate(self) -> None:
            self.last_eval = self.num_timesteps
            policy = make_policy(self.model)
            t0 = time.time()
            result = evaluate_one(policy, config, eval_seeds, env_action_type(action_type),
                                  batch_size=len(eval_seeds))
            ret = result.sum_rewards
            rec: dict[str, Any] = {"timesteps": int(self.num_timesteps), "mean_return": float(ret.mean()),
                                   "std_return": float(ret.std()), "eval_seconds": time.time() - t0}
            if baseline is not None:
                rec["vs_baseline"] = paired_difference(result, baseline)
            self.history.append(rec)
            if on_evaluation is not None:  # e.g. a Ray Tune report (experiments/tune_ppo.py)
                on_evaluation(rec)
            self.logger.record("eval/mean_return", rec["mean_return"])
            self.logger.record("eval/std_return", rec["std_return"])
            if baseline is not None:  # < 0: cheaper than the baseline on the same episodes
                self.logger.record("eval/vs_baseline", rec["vs_baseline"]["mean_difference"])
            if verbose:
                print(f"[eval] {rec}", flush=True)
            write_json_atomic(out_dir / "evaluations.json", self.history)
            if rec["mean_return"] > self.best:
                self.best = rec["mean_return"]
                save_policy(self.model, policy, out_dir / "best_model.zip")

        def get_state(self) -> dict[str, Any]:
            """The bookkeeping a resumed run continues from (for its checkpoint): when it last evaluated, the
            best mean return so far (its model is ``best_model.zip``) and every evaluation's record."""
            return {"last_eval": int(self.last_eval), "best": float(self.best), "history": copy.deepcopy(self.history)}

        def set_state(self, state: dict[str, Any]) -> None:
            self.last_eval, self.best = int(state["last_eval"]), float(state["best"])
            self.history = copy.deepcopy(state["history"])

        def _on_training_start(self) -> None:
            if evaluate_at_start:  # the warm-started policy is a candidate like every later one
                self._evaluate()

        def _on_step(self) -> bool:
            if eval_freq and self.num_timesteps - self.last_eval >= eval_freq:
                self._evaluate()
            return True

        def _on_training_end(self) -> None:
            if self.num_timesteps != self.last_eval:
                self._evaluate()

    return HeldOutEvalCallback()


def _save_policy(model, policy: NormalizedPolicy, zip_path: Path, extra: dict | None = None) -> Path:
    zip_path = save_model_atomic(model, zip_path)  # the best model survives a run killed while saving it
    write_json_atomic(stats_path(zip_path), {**policy.stats_dict(), **(extra or {})})
    return zip_path


def stats_path(zip_path: str | Path) -> Path:
    """Where the observation statistics of the model ``zip_path`` live (``<stem>_obs_stats.json``)."""
    zip_path = Path(zip_path)
    return zip_path.with_name(zip_path.stem + STATS_SUFFIX)


# --- training ---
def _new_run_settings(algo: str | None, total_timesteps: int | None, n_envs: int | None,
                      hyperparams: TampingSettings | dict | str | Path | None, checkpoint_every_s: float | None,
                      eval_freq: int | None) -> TampingSettings:
    """A new run's settings: the shipped hyper-parameters, ``hyperparams`` over them key by key (or a whole
    :class:`TampingSettings`), then the explicit arguments that are not None."""
    if isinstance(hyperparams, TampingSettings):
        settings = hyperparams
    else:
        if isinstance(hyperparams, (str, Path)):
            hyperparams = load_hyperparams(hyperparams)
        settings = TampingSettings.from_dict(load_hyperparams()).updated(hyperparams or {})
    explicit = {"algo": algo, "n_envs": n_envs, "total_timesteps": total_timesteps,
                "checkpoint_every_s": checkpoint_every_s, "eval_freq": eval_freq}
    return settings.updated({k: v for k, v in explicit.items() if v is not None})


@dataclass(frozen=True)
class _Run:
    """What a training run trains with: its folder, settings, env config, seed and held-out seeds, its
    ``train_meta.json`` (as written or read) and, resumed, the checkpoint it continues from."""

    run_dir: Path
    settings: TampingSettings
    config: LineConfig
    seed: int
    eval_seeds: list[int] | None
    meta: dict[str, Any]
    checkpoint: Checkpoint | None = None


def _new_run(out_dir: str | Path | None, settings: TampingSettings, config: Any, seed: int | None,
             eval_seeds: Sequence[int] | None) -> _Run:
    """A new run in ``out_dir`` (default ``runs/ppo``; refused if it holds an unfinished run)."""
    run_dir = Path(out_dir) if out_dir is not None else Path("runs/ppo")
    start_run_folder(run_dir)
    config = problem_config(config)
    seed = DEFAULT_TRAIN_SEED if seed is None else int(seed)
    seeds = None if eval_seeds is None else [int(x) for x in eval_seeds]
    s = settings
    meta = {"trainer": "sb3", "env_id": DEFAULT_ENV_ID, "algo": s.algo, "action_type": s.action_type,
            "keep_per_sleeper": s.keep_per_sleeper, "seed": seed, "n_envs": s.n_envs, "hyperparams": s.to_dict(),
            "config": config.to_dict(), "eval_seeds": seeds, "warm_start": None}
    return _Run(run_dir, settings, config, seed, seeds, meta)


def _resumed_run(resume: str | Path, out_dir: str | Path | None, total_timesteps: int | None,
                 checkpoint_every_s: float | None) -> _Run:
    """The run in ``resume`` as its ``train_meta.json`` and checkpoint describe it, to ``total_timesteps`` (its
    own total if None) and with ``checkpoint_every_s`` if given."""
    run_dir = resume_folder(resume, out_dir)
    meta = read_run_meta(run_dir)
    ckpt = read_checkpoint(run_dir)
    total = int(total_timesteps) if total_timesteps is not None else int(ckpt.info["total"])
    changes: dict[str, Any] = {"total_timesteps": total}
    if checkpoint_every_s is not None:
        changes["checkpoint_every_s"] = checkpoint_every_s
    s = TampingSettings.from_dict(meta["hyperparams"]).updated(changes)
    return _Run(run_dir, s, LineConfig.coerce(meta["config"]), int(meta["seed"]), meta["eval_seeds"], meta,
                ckpt)


def train(algo: str | None = None, config: LineConfig | dict | str | None = None,
          total_timesteps: int | None = None, n_envs: int | None = None, seed: int | None = None,
          out_dir: str | Path | None = None, hyperparams: TampingSettings | dict | str | Path | None = None,
          progress: bool = True, eval_seeds: Sequence[int] | None = DEFAULT_EVAL_SEEDS,
          checkpoint_every_s: float | None = None, eval_freq: int | None = None, verbose: int = 1,
          resume: str | Path | None = None, on_evaluation: Callable[[dict], None] | None = None,
          workers: int = 1) -> Path:
    """Train; save ``out_dir/model.zip`` (+ ``model_obs_stats.json``, ``vecnormalize.pkl``); return its path.

    ``hyperparams``: a dict, a flat JSON path or an RL Zoo YAML path (its ``trackenv/Tamping-v1`` entry)
    overriding ``agents/learning/hyperparams/ppo.yml`` key by key, or a whole :class:`TampingSettings`. Explicit
    arguments (algo, total_timesteps, n_envs, checkpoint_every_s, eval_freq) that are not None override both.
    Unknown keys and values out of range raise ValueError (:class:`TampingSettings` lists the fields, their
    defaults and ranges). ``seed`` (default :data:`DEFAULT_TRAIN_SEED`): env i starts with ``seed + i``.
    ``out_dir`` defaults to ``runs/ppo``. ``eval_seeds=None`` or ``eval_freq=0`` disables the periodic held-out
    evaluation; ``on_evaluation(record)`` is called after each (``{"timesteps", "mean_return", "std_return",
    "eval_seconds"}``; Ray Tune reports it in tune_ppo.py). ``workers`` > 1 steps the training envs in that
    many processes (the same episodes; see :class:`~trackenv.envs.sharded.ShardedVectorEnv`).

    Checkpoints (:mod:`.checkpoint`): every ``checkpoint_every_s`` seconds of wall clock (default 300; 0: none)
    at the start of a roll-out, when training starts and when it ends, ``out_dir/checkpoint.zip`` holds the
    model, the VecNormalize statistics, the envs' states, the random generators, the step count and the
    best-model bookkeeping. ``resume``: the folder of a run (killed, or finished) to continue *in place* from
    its checkpoint, with the settings, config, seeds and held-out seeds it was started with (so algo, config,
    n_envs, seed, hyperparams and eval_freq must be None; ``eval_seeds`` is the run's own), up to its own total
    or to ``total_timesteps`` if given (a new total: a finished run goes on). A finished run with nothing left
    returns its model at once. With ``workers`` == 1 the resumed run takes the very steps the uninterrupted run
    would have; with ``workers`` > 1 the envs' episodes in progress are out of reach, so the resumed run starts
    new ones (seeded from ``seed`` and the step count). A new run refuses a folder that holds an unfinished run.
    """
    if resume is not None:
        refuse_on_resume(Path(resume), algo=algo, config=config, n_envs=n_envs, seed=seed, hyperparams=hyperparams,
                         eval_freq=eval_freq)
        run = _resumed_run(resume, out_dir, total_timesteps, checkpoint_every_s)
        assert run.checkpoint is not None
        info, total = run.checkpoint.info, run.settings.total_timesteps
        finished = finished_run(run.run_dir, info, total)
        if finished is not None:
            if verbose:
                print(f"[resume] {run.run_dir} is finished ({info['done']} of {total} timesteps): {finished}",
                      flush=True)
            return finished
        if total < info["done"]:
            raise ValueError(f"total_timesteps must be at least the {info['done']} timesteps {run.run_dir} has "
                             f"done, got {total}")
    else:
        settings = _new_run_settings(algo, total_timesteps, n_envs, hyperparams, checkpoint_every_s, eval_freq)
        run = _new_run(out_dir, settings, config, seed, eval_seeds)
    return _train_run(run, progress, verbose, on_evaluation, workers)


def _train_run(run: _Run, progress: bool, verbose: int, on_evaluation: Callable[[dict], None] | None,
               workers: int) -> Path:
    """Build the envs and the model (new, or from the run's checkpoint), train to the total with the held-out
    evaluation and the checkpoints, save the final artefacts (see :func:`train`)."""
    from stable_baselines3.common.callbacks import CallbackList
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    s, run_dir, ckpt = run.settings, run.run_dir, run.checkpoint
    single_torch_thread()  # the physics (numba) wants the cores; the small MLP does not
    raw = TampingSB3VecEnv(s.n_envs, run.config, action_type=s.action_type, keep_per_sleeper=s.keep_per_sleeper,
                           seed=None if ckpt is not None else run.seed, bootstrap_at_horizon=s.bootstrap_at_horizon,
                           workers=workers)
    env = VecNormalize(VecMonitor(raw), norm_obs=True, norm_reward=True, clip_obs=s.clip_obs, gamma=s.gamma)
    if ckpt is not None:
        model = _algo_class(s.algo).load(ckpt.model_file(), env=env, device="cpu", force_reset=False,
                                         tensorboard_log=str(run_dir), verbose=verbose)
        _restore_training_state(model, env, raw, ckpt, run.seed)
        warm = None
    else:
        model = _new_model(run, env, verbose)
        write_json_atomic(run_dir / META_FILE, run.meta)
        warm = _warm_start(model, env, run.config, s, run.seed, verbose)
        if warm is not None:
            write_json_atomic(run_dir / META_FILE, {**run.meta, "warm_start": warm})

    callbacks: list[Any] = []
    eval_cb = None
    meta = {"action_type": s.action_type, "config": run.config.to_dict()}  # what a scorer of a saved model checks
    if run.eval_seeds and s.eval_freq > 0:
        def make_policy(model) -> NormalizedPolicy:
            return NormalizedPolicy.from_vecnormalize(model, model.get_vec_normalize_env(), raw.obs_keys,
                                                      algo=s.algo, action_type=s.action_type)

        def save_best(model, policy: NormalizedPolicy, path: Path) -> Path:
            return _save_policy(model, policy, path, meta)

        eval_cb = _make_eval_callback(run.config, run.eval_seeds, s.eval_freq, run_dir, make_policy, save_best,
                                      s.action_type, verbose, evaluate_at_start=warm is not None,
                                      on_evaluation=on_evaluation)
        if ckpt is not None and ckpt.state["evaluation"] is not None:
            eval_cb.set_state(ckpt.state["evaluation"])
        callbacks.append(eval_cb)

    def save_checkpoint(model, finished: bool = False) -> None:
        state = {"random": capture_random_states(), "env": vec_env_state(env),
                 "evaluation": eval_cb.get_state() if eval_cb is not None else None}
        write_checkpoint(run_dir, {"trainer": "sb3", "unit": "timesteps", "done": int(model.num_timesteps),
                                   "total": s.total_timesteps, "finished": finished}, state, model)

    ckpt_cb = None
    if s.checkpoint_every_s > 0:
        ckpt_cb = make_checkpoint_callback(s.checkpoint_every_s, save_checkpoint, at_start=ckpt is None)
        callbacks.append(ckpt_cb)
    if progress:
        callbacks.append(make_progress_callback(f"train {s.algo}"))

    t0 = time.time()
    start_steps = int(model.num_timesteps)
    model.learn(total_timesteps=max(s.total_timesteps - start_steps, 0), callback=CallbackList(callbacks),
                tb_log_name=s.algo, reset_num_timesteps=ckpt is None)
    wall = time.time() - t0
    env.save(str(run_dir / "vecnormalize.pkl"))
    policy = NormalizedPolicy.from_vecnormalize(model, env, raw.obs_keys, algo=s.algo, action_type=s.action_type)
    path = _save_policy(model, policy, run_dir / "model.zip", meta)
    checkpoints = None
    if ckpt_cb is not None:
        t_final = time.monotonic()
        save_checkpoint(model, finished=True)  # last: a resume of this folder finds the run finished
        checkpoints = {"every_s": s.checkpoint_every_s, "count": ckpt_cb.count + 1,
                       "seconds": ckpt_cb.seconds + time.monotonic() - t_final,
                       "bytes": (run_dir / CHECKPOINT_FILE).stat().st_size}
    steps = int(model.num_timesteps)
    summary = {"timesteps": steps, "timesteps_this_run": steps - start_steps,
               "resumed_from_timesteps": start_steps if ckpt is not None else None, "wall_seconds": wall,
               "steps_per_second": (steps - start_steps) / max(wall, 1e-9),
               "warm_start": warm if ckpt is None else run.meta.get("warm_start"),
               "evaluations": eval_cb.history if eval_cb is not None else [], "checkpoints": checkpoints}
    write_json_atomic(run_dir / "summary.json", summary)
    env.close()
    return path


def _new_model(run: _Run, env, verbose: int):
    """A new run's model, seeded from the run's seed (and the global generators with it, as SB3 does)."""
    from stable_baselines3.common.utils import set_random_seed

    s = run.settings
    set_random_seed(run.seed)
    model = _algo_class(s.algo)("MultiInputPolicy", env, seed=run.seed, tensorboard_log=str(run.run_dir),
                                verbose=verbose, policy_kwargs={"net_arch": list(s.net_arch)}, device="cpu",
                                **s.algo_kwargs())
    if s.initial_tamp_logit is not None:
        _set_initial_tamp_logit(model, s.initial_tamp_logit, s.action_type)
    return model


def _warm_start(model, env, config: LineConfig, s: TampingSettings, seed: int, verbose: int) -> dict | None:
    """The behaviour-cloning warm start of a new run (:func:`~.imitation.warm_start`), if the settings ask for
    one; its summary with its wall time."""
    if not s.warm_start_rule:
        return None
    from .imitation import warm_start

    t_warm = time.time()
    warm = warm_start(model, env, config, s.action_type, s.warm_start_rule, n_episodes=s.warm_start_episodes,
                      epochs=s.warm_start_epochs, gamma=s.gamma, label_smoothing=s.warm_start_label_smoothing,
                      params=None if s.warm_start_params is None else dict(s.warm_start_params), seed=seed)
    warm["wall_seconds"] = time.time() - t_warm
    if verbose:
        print(f"[warm start] {warm}", flush=True)
    return warm


def _restore_training_state(model, env, raw: TampingSB3VecEnv, ckpt: Checkpoint, seed: int) -> None:
    """Put a checkpoint's envs, statistics and random generators back under a model loaded from it, so that the
    next roll-out starts where the checkpointed run's did. Where the envs' states were out of reach (workers >
    1), new episodes start instead, seeded from ``seed`` and the step count, apart from the run's first ones."""
    if not restore_vec_env_state(env, ckpt.state["env"]):
        raw.seed(seed + raw.num_envs + int(model.num_timesteps))
        model._last_obs = None  # learn() resets the envs, with these seeds
    restore_random_states(ckpt.state["random"])  # last: loading the model reseeded them


def _set_initial_tamp_logit(model, logit: float, action_type: str) -> None:
    """Start from a policy that rarely tamps: the action head's bias sets the initial log-odds of tamping a
    section (MultiBinary) or of choosing any section over "nothing" (Discrete). A random policy that tamps
    half the sections every quarter is ruinous, and exploring from there wastes most of a small budget."""
    import torch

    with torch.no_grad():
        bias = model.policy.action_net.bias
        if action_type in ("discrete", RANKED):
            bias.zero_()
            bias[0] = -logit
        else:
            bias.fill_(logit)


def export_policy(model_zip: str | Path, dest: str | Path = DEFAULT_PRETRAINED,
                  sidecar: Callable[[str | Path], Path] | None = None) -> Path:
    """Copy a trained ``model.zip`` and the file beside it that it needs (``sidecar(path)``; default its
    observation statistics, :func:`stats_path`) to ``dest`` (default the shipped path)."""
    side = sidecar or stats_path
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(model_zip, dest)
    shutil.copyfile(side(model_zip), side(dest))
    return dest


def load_trained(path: str | Path | None = None, name: str = "ppo") -> NormalizedPolicy:
    """The trained policy at ``path`` (default ``agents/learning/pretrained/ppo_tamping.zip``, the export path;
    none ships today) with its observation
    statistics (``<stem>_obs_stats.json`` beside it): ``predict(obs, state=None, episode_start=None,
    deterministic=True)`` on raw env observations (single or batched dict)."""
    path = Path(path) if path is not None else DEFAULT_PRETRAINED
    if not path.exists():
        raise FileNotFoundError(f"no trained model at {path}")
    stats = json.loads(stats_path(path).read_text())
    algo = stats.get("algo", "ppo")
    model = _algo_class(algo).load(str(path), device="cpu")
    return NormalizedPolicy(model, stats["obs_keys"], stats["mean"], stats["var"], stats["clip_obs"],
                            stats["epsilon"], name=name, algo=algo,
                            action_type=stats.get("action_type", "multibinary"), config=stats.get("config"),
                            raw_keys=stats.get("raw_keys", ()))
