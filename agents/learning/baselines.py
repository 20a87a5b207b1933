"""Policies trained by the standard libraries, loaded for the evaluation harness: SB3's ``predict`` on raw
batched observations of the line, whatever library trained them.

Three kinds, told apart by what the path holds (:func:`baseline_kind`):

* ``sb3`` — a stable-baselines3 / sb3-contrib model (``.zip``) with its observation statistics beside it
  (``<stem>_obs_stats.json``), as :func:`~.tamping.train` writes it (``experiments/train_ppo.py``, e.g. the
  ranked MaskablePPO baseline): :func:`~.tamping.load_trained`.
* ``line`` — a per-section policy (``.zip``) with ``<stem>_meta.json`` beside it, as ``trackenv train --env ID``
  writes it: :func:`~.line.load_line_trained`.
* ``rllib`` — the folder that ``experiments/train_rllib.py --out DIR`` writes (``rllib_summary.json`` and the
  checkpoint): its RLModule, run forward in torch without a Ray runtime. On a flat id (ranked actions over the
  flattened section-level observation) :class:`RLlibRankedPolicy`; with ``--multi-agent`` (one shared module for
  every section's agent of the PettingZoo interface) :class:`RLlibSectionPolicy`.

A model trained with stable-baselines3 in one's own script (``model.learn`` on a trackenv env or one of the
learner wrappers of :mod:`trackenv.envs.wrappers`) becomes an ``sb3`` policy with :func:`save_sb3_policy`, which
writes the model and the sidecar the harness needs (what the env gave the model, its observation statistics, the
line it was trained on).

A policy of the ``sb3`` and ``rllib`` kinds sees the observation of the scenario it was trained on (its sizes are
those of the line: flattened section arrays, a count of sections to tamp), so it is wrapped in
:class:`TrainedPolicy`, whose :meth:`~TrainedPolicy.unfit_for` tells the leaderboard to score it on that
scenario only. A ``line`` policy reads per-section features and runs on any line, as before.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from trackenv.envs.line_config import LINE_FILE_FIELDS, LineConfig
from trackenv.envs.wrappers import ranked_to_sections

from ..evaluation.harness import takes_action_masks
from ..rules.base import as_batch
from .actions import decode_ranked_choices
from .line_policy import may_tamp

__all__ = ["BASELINE_KINDS", "RLLIB_SUMMARY", "SAVED_BASELINES", "RLlibRankedPolicy", "RLlibSectionPolicy",
           "TrainedPolicy", "baseline_kind", "load_baseline", "rllib_module_dir", "save_sb3_policy", "saved_baselines"]

#: The kinds :func:`load_baseline` reads.
BASELINE_KINDS = ("sb3", "line", "rllib")
#: The file that marks a folder of ``experiments/train_rllib.py``.
RLLIB_SUMMARY = "rllib_summary.json"
#: The committed baselines (``trackenv leaderboard --policies baselines``): their commands, budgets and curves are
#: on the documentation's leaderboard page.
SAVED_BASELINES = Path(__file__).resolve().parents[2] / "experiments" / "saved" / "baselines"
#: The RLModule ids of ``experiments/train_rllib.py``: one module (single agent), or the module every section's
#: agent shares (``--multi-agent``).
RLLIB_MODULE_IDS = {False: "default_policy", True: "shared"}


def saved_baselines(folder: str | Path = SAVED_BASELINES) -> list[Path]:
    """The trained policies in ``folder`` (default the committed baselines, :data:`SAVED_BASELINES`), by name:
    each ``.zip`` with a sidecar and each folder of ``experiments/train_rllib.py``; none if there is no folder."""
    root = Path(folder)
    if not root.is_dir():
        return []
    found = []
    for p in sorted(root.iterdir()):
        try:
            baseline_kind(p)
        except ValueError:
            continue  # a sidecar, the curves
        found.append(p)
    return found


def baseline_kind(path: str | Path) -> str:
    """The kind of trained policy at ``path`` (one of :data:`BASELINE_KINDS`), from the files there;
    FileNotFoundError if nothing is there, ValueError naming what a policy of each kind holds otherwise."""
    from .line import line_meta_path
    from .tamping import stats_path

    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"no trained policy at {p}")
    if p.is_dir():
        if (p / RLLIB_SUMMARY).is_file():
            return "rllib"
        models = [str(p / name) for name in ("model.zip", "best_model.zip") if (p / name).is_file()]
        if models:  # the folder of a run of trackenv train: its model is a file in it
            raise ValueError(f"{p}: a trained model is its .zip, not the run's folder: give {' or '.join(models)}")
        raise ValueError(f"{p}: a folder of a trained policy must hold {RLLIB_SUMMARY} (experiments/train_rllib.py "
                         "--out DIR)")
    if p.suffix == ".zip":
        if stats_path(p).is_file():
            return "sb3"
        if line_meta_path(p).is_file():
            return "line"
        raise ValueError(f"{p}: a trained .zip needs {stats_path(p).name} (experiments/train_ppo.py; a model "
                         f"trained with stable-baselines3 in a script of one's own: save it with "
                         f"trackenv_agents.learning.baselines.save_sb3_policy(model, env, path)) or "
                         f"{line_meta_path(p).name} (trackenv train --env ID) beside it")
    raise ValueError(f"{p}: a trained policy is a .zip (stable-baselines3) or a folder of "
                     f"experiments/train_rllib.py, got a {p.suffix or 'file without a suffix'}")


def load_baseline(path: str | Path, name: str | None = None) -> Any:
    """The trained policy at ``path`` (any kind of :func:`baseline_kind`) with SB3's ``predict`` on raw
    batched line observations, named ``name`` (default: the file or folder name)."""
    p = Path(path)
    kind = baseline_kind(p)
    label = name or p.stem
    if kind == "line":
        from .line import load_line_trained

        return load_line_trained(p, name=label)
    if kind == "sb3":
        from .tamping import load_trained, stats_path

        trained = json.loads(stats_path(p).read_text()).get("config")
        if trained is None:
            raise ValueError(f"{stats_path(p)}: no 'config' (the line it was trained on)")
        return TrainedPolicy(load_trained(p, name=label), LineConfig.coerce(trained), label, kind, p)
    return _load_rllib(p, label)


#: wrappers of a single env that change nothing a model sees or does (Gymnasium's own, SB3's Monitor)
_TRANSPARENT_WRAPPERS = ("TimeLimit", "OrderEnforcing", "PassiveEnvChecker", "RecordEpisodeStatistics", "Monitor",
                         "ActionMasker")  # (sb3-contrib's: the harness gives the env's own masks)
#: what :func:`save_sb3_policy` can describe to the harness: the wrappers between the model and the env, outermost
#: first (without the transparent ones) -> the sidecar's ``action_type`` (None: the env's own)
_SCORABLE_PIPELINES = {(): None, ("MultiDiscreteActions",): None, ("SectionObservation",): None,
                       ("SectionObservation", "MultiDiscreteActions"): None,
                       ("MultiDiscreteActions", "SectionObservation"): None, ("RankedActions",): "ranked",
                       ("SectionObservation", "RankedActions"): "ranked"}


def save_sb3_policy(model: Any, env: Any, path: str | Path, vec_normalize: Any = None) -> Path:
    """Save a stable-baselines3 / sb3-contrib ``model`` (PPO, MaskablePPO, A2C or DQN) trained on ``env`` so that
    the harness, ``trackenv evaluate --model PATH`` and ``trackenv leaderboard --policies PATH`` score it: the model
    at ``path`` (``.zip``) and beside it ``<stem>_obs_stats.json``: the observation keys the model reads, their
    statistics (``vec_normalize``'s, a ``VecNormalize`` the model was trained in; none: the observation as the env
    gives it), the algorithm, the action type and the line's config (the scenario it is scored on).

    ``env``: the env the model was trained on, or one built the same way: a trackenv env (``gym.make`` of an id,
    tamp-or-wait or with the choices), possibly in :class:`~trackenv.envs.wrappers.SectionObservation`,
    :class:`~trackenv.envs.wrappers.MultiDiscreteActions`, :class:`~trackenv.envs.wrappers.RankedActions` or
    :func:`~trackenv.envs.wrappers.make_ranked` (ranked counts of tamping, or of each choice), or an SB3
    ``DummyVecEnv`` / ``VecNormalize`` of one. Another pipeline (a flattened observation, a wrapper of one's own)
    is refused with ValueError naming it: the harness gives a policy the env's own observation and masks and takes
    the env's own actions, and can only undo these. A MaskablePPO is played with its masks (the env's, or those
    of its ranked counts), as in training."""
    import gymnasium as gym

    from .checkpoint import save_model_atomic, write_json_atomic
    from .tamping import SB3_ALGOS, stats_path

    algo = next((name for name, (_, cls) in SB3_ALGOS.items() if type(model).__name__ == cls), None)
    if algo is None:
        raise ValueError(f"model must be one of {sorted(cls for _, cls in SB3_ALGOS.values())} (stable-baselines3 "
                         f"or sb3-contrib), got {type(model).__name__}")
    if vec_normalize is None and type(env).__name__ == "VecNormalize":
        vec_normalize = env
    while hasattr(env, "venv"):  # SB3's vector wrappers
        env = env.venv
    if hasattr(env, "envs"):  # DummyVecEnv: its first env
        env = env.envs[0]
    if not isinstance(env, gym.Env):
        raise ValueError(f"env must be the Gymnasium env the model was trained on (or a DummyVecEnv of it), got "
                         f"{type(env).__name__}: give one env built the same way (for a vector env of ranked "
                         "actions, make_ranked(id, ...); the PettingZoo agents are scored as an RLlib run)")
    pipeline, inner = [], env
    while isinstance(inner, gym.Wrapper):
        if type(inner).__name__ not in _TRANSPARENT_WRAPPERS:
            pipeline.append(type(inner).__name__)
        inner = inner.env
    config = getattr(inner, "config", None)
    if config is None or not hasattr(config, "to_dict"):
        raise ValueError(f"env must be a trackenv env (gym.make of a trackenv id), got {type(inner).__name__}")
    choices = isinstance(inner.action_space, gym.spaces.MultiDiscrete)
    if tuple(pipeline) not in _SCORABLE_PIPELINES:
        raise ValueError(f"a model trained through {' > '.join(pipeline)} cannot be scored by the harness, which "
                         "gives a policy the env's own observation and masks and takes its own actions: "
                         "save_sb3_policy takes the env, SectionObservation, MultiDiscreteActions, RankedActions and "
                         "make_ranked (not a flattened observation, nor a wrapper of one's own)")
    space = env.observation_space
    if not isinstance(space, gym.spaces.Dict):
        raise ValueError(f"env's observation must be the trackenv Dict (or SectionObservation's), got {space}")
    if (getattr(model, "observation_space", space) != space
            or getattr(model, "action_space", env.action_space) != env.action_space):
        raise ValueError(f"the model's spaces are not env's: it was trained on another env or wrapper (model: "
                         f"{model.observation_space} -> {model.action_space}; env: {space} -> {env.action_space}); "
                         "give the env it was trained on")
    keys = list(space.spaces)
    normalised: list[str] = []
    if vec_normalize is not None and getattr(vec_normalize, "norm_obs", True):
        normalised = [k for k in (getattr(vec_normalize, "norm_obs_keys", None) or keys) if k in keys]
    shapes = {k: space[k].shape or () for k in keys}
    mean = {k: np.zeros(shapes[k]).tolist() for k in keys}  # unread for the raw keys (the env's own, as it gave them)
    var = {k: np.ones(shapes[k]).tolist() for k in keys}
    clip, eps = 10.0, 1e-8  # (VecNormalize's defaults; read only where it normalised)
    if normalised:
        rms = vec_normalize.obs_rms
        mean.update({k: rms[k].mean.tolist() for k in normalised})
        var.update({k: rms[k].var.tolist() for k in normalised})
        clip, eps = float(vec_normalize.clip_obs), float(vec_normalize.epsilon)
    ranked = _SCORABLE_PIPELINES[tuple(pipeline)] == "ranked"
    action_type = ("ranked_choices" if choices else "ranked") if ranked else ("choices" if choices else "multibinary")
    path = Path(path)
    if path.suffix != ".zip":
        raise ValueError(f"path must end in .zip (the model's file), got {str(path)!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    save_model_atomic(model, path)
    raw = [k for k in keys if k not in normalised]
    write_json_atomic(stats_path(path), {"obs_keys": keys, "mean": mean, "var": var, "clip_obs": clip,
                                         "epsilon": eps, "algo": algo, "action_type": action_type,
                                         "config": config.to_dict(), "raw_keys": raw, "saved_by": "save_sb3_policy"})
    return path


class TrainedPolicy:
    """A loaded policy scored only on the line it was trained on (``config``): its observation has that line's
    sizes. ``predict`` and ``reset`` are the policy's; :meth:`unfit_for` says why another config does not fit."""

    def __init__(self, policy: Any, config: LineConfig, name: str, kind: str, path: str | Path) -> None:
        self.policy = policy
        self.config = config
        self.name = name
        self.params: dict[str, Any] = {"kind": kind, "path": str(path)}
        self._takes_masks = takes_action_masks(policy)  # asked once: predict runs every step

    def predict(self, observation: Mapping[str, Any], state: Any = None, episode_start: Any = None,
                deterministic: bool = True, action_masks: Any = None) -> tuple[np.ndarray, Any]:
        """The policy's ``predict``; the env's ``action_masks`` go on to a policy that takes them (an SB3 model's:
        MaskablePPO's masks, the decoding of ranked counts of the choices)."""
        extra = {} if action_masks is None or not self._takes_masks else {"action_masks": action_masks}
        return self.policy.predict(observation, state=state, episode_start=episode_start,
                                   deterministic=deterministic, **extra)

    def reset(self) -> None:
        reset = getattr(self.policy, "reset", None)
        if callable(reset):
            reset()

    def unfit_for(self, config: LineConfig) -> str | None:
        """None where ``config`` is the line this policy was trained on; else which of its fields differ (another
        line file first, named by its path, without the fields the files set) and, where it was trained on a line
        file, how to score it there."""
        here = LineConfig.coerce(config)
        mine, theirs = self.config.to_dict(), here.to_dict()
        mine["line"], theirs["line"] = self.config.line, here.line  # compared as lines, not by the file's path
        differ = [k for k in sorted(set(mine) | set(theirs)) if mine.get(k) != theirs.get(k)]
        if not differ:
            return None
        if "line" in differ:
            differ = ["line", *(k for k in differ if k != "line" and k not in LINE_FILE_FIELDS)]
        shown = ", ".join(f"{k} {_shown(self.config, k)} (here {_shown(here, k)})" for k in differ[:3])
        more = f" and {len(differ) - 3} more" if len(differ) > 3 else ""
        hint = _line_hint(self.config.line) if "line" in differ else ""
        return f"trained on another line: {shown}{more}{hint}"


def _shown(config: LineConfig, field: str) -> str:
    """A field of ``config`` in :meth:`TrainedPolicy.unfit_for`'s message: its line by the file it was read from
    (the whole line would be kilobytes), any other field as Python writes it."""
    if field != "line":
        return repr(config.to_dict().get(field))
    return "none" if config.line is None else config.line.label


def _line_hint(line: Any) -> str:
    """How to score a policy trained on ``line`` (a line description, or None) on that line: ``--set line=PATH``
    with the path of its file where it was read from one; "" without a line."""
    if line is None:
        return ""
    return f"; score it on its line with --set line={line.path or 'PATH (the file of ' + line.label + ')'}"


def rllib_module_dir(run_dir: str | Path, multi_agent: bool) -> Path:
    """Where the RLModule of a run of ``experiments/train_rllib.py`` lies in its checkpoint."""
    return Path(run_dir) / "checkpoint" / "learner_group" / "learner" / "rl_module" / RLLIB_MODULE_IDS[multi_agent]


def _load_rllib(run_dir: Path, name: str) -> TrainedPolicy:
    from ray.rllib.core.rl_module.rl_module import RLModule

    env_config = dict(json.loads((run_dir / RLLIB_SUMMARY).read_text())["env_config"])
    env_id = env_config.pop("env_id")
    multi_agent = bool(env_config.pop("multi_agent", False))
    env_config.pop("num_envs", None)
    module_dir = rllib_module_dir(run_dir, multi_agent)
    if not module_dir.is_dir():
        raise FileNotFoundError(f"{run_dir}: no RLModule at {module_dir}")
    module = RLModule.from_checkpoint(str(module_dir.resolve()))  # pyarrow reads a relative path as a URI
    policy: RLlibRankedPolicy | RLlibSectionPolicy
    if multi_agent:
        from trackenv.envs.multiagent import line_parallel_env

        penv = line_parallel_env(env_id, **env_config)
        config = penv.env.get_wrapper_attr("config")
        policy = RLlibSectionPolicy(module, penv, config, name)
    else:
        from trackenv.envs.wrappers import make_ranked

        env = make_ranked(env_id, **env_config)
        config = env.unwrapped.config  # type: ignore[attr-defined]
        policy = RLlibRankedPolicy(module, list(env.observation_space.spaces), name,  # type: ignore[attr-defined]
                                   heads=env.get_wrapper_attr("heads"))
        env.close()
    return TrainedPolicy(policy, config, name, "rllib", run_dir)


def _logits(module: Any, x: np.ndarray) -> np.ndarray:
    """The action logits of an RLModule (its inference pass in torch) for the rows of ``x``."""
    import torch

    with torch.no_grad():
        out = module.forward_inference({"obs": torch.as_tensor(x, dtype=torch.float32)})
    return out["action_dist_inputs"].cpu().numpy()


def _choose(logits: np.ndarray, deterministic: bool, rng: np.random.Generator | None) -> np.ndarray:
    """Per row, the most likely action (deterministic) or one drawn from the softmax of ``logits``."""
    if deterministic:
        return logits.argmax(axis=-1)
    p = np.exp(logits - logits.max(axis=-1, keepdims=True))
    p /= p.sum(axis=-1, keepdims=True)
    u = (rng or np.random.default_rng()).random(p.shape[:-1] + (1,))
    return np.minimum((p.cumsum(axis=-1) < u).sum(axis=-1), p.shape[-1] - 1)


class RLlibRankedPolicy:
    """An RLModule trained on the flat ranked view of a line (:func:`trackenv.envs.wrappers.make_ranked` with
    ``flat=True``): the section-level observation, its keys in ``obs_keys`` order flattened to one row, gives
    logits over ``Discrete(n_sections + 1)``; the count ``k`` tamps the ``k`` sections of largest measured SD
    (:func:`~trackenv.envs.wrappers.ranked_to_sections`). On a line with the choices (``heads``: the enabled
    interventions, :attr:`~trackenv.envs.wrappers.RankedActions.heads`) the logits are one block of
    ``n_sections + 1`` per head, each head's count chosen in its block (as RLlib's MultiDiscrete distribution
    does) and decoded on the env's ``action_masks`` (:func:`~trackenv.envs.wrappers.ranked_to_choices`, as the
    wrapper decoded them in training); it was scored as one tamping count before. ``rng``: the draws of
    ``deterministic=False``."""

    def __init__(self, module: Any, obs_keys: list[str], name: str = "rllib-ppo",
                 rng: np.random.Generator | None = None, heads: tuple[str, ...] | None = None) -> None:
        self.module = module
        self.obs_keys = list(obs_keys)
        self.name = name
        self._rng = rng
        self.heads = None if heads is None else tuple(heads)

    def predict(self, observation: Mapping[str, Any], state: Any = None, episode_start: Any = None,
                deterministic: bool = True, action_masks: Any = None) -> tuple[np.ndarray, Any]:
        b, batched = as_batch(dict(observation))
        n, s = b["section_sd"].shape
        x = np.concatenate([np.asarray(b[k], dtype=np.float32).reshape(n, -1) for k in self.obs_keys], axis=1)
        logits = _logits(self.module, x)
        if self.heads is None:
            act = ranked_to_sections(_choose(logits, deterministic, self._rng), b["section_sd"])
        else:
            counts = _choose(logits.reshape(n, len(self.heads), s + 1), deterministic, self._rng)
            masks = None if action_masks is None else np.asarray(action_masks).reshape(n, -1)
            act = decode_ranked_choices(self.name, counts, b, masks, self.heads)
        return (act if batched else act[0]), state


class RLlibSectionPolicy:
    """The RLModule every section's agent shares (``experiments/train_rllib.py --multi-agent``), run for every
    section of a batched line observation: each agent's observation of the PettingZoo interface
    (:class:`~trackenv.envs.parallel.LineParallelEnv`: its features, its action mask [may wait, may tamp]),
    flattened in its Dict space's key order as RLlib's ``FlattenObservations`` does, gives logits over wait / tamp.
    The mask is read from the observation (:func:`~.line_policy.may_tamp`) and a masked section is never asked
    for; the line env resolves the campaign's capacity as it does for the agents in training."""

    def __init__(self, module: Any, parallel_env: Any, config: LineConfig, name: str = "rllib-shared-ppo",
                 rng: np.random.Generator | None = None) -> None:
        self.module = module
        self.parallel_env = parallel_env
        self.config = config
        self.name = name
        self._rng = rng
        agent = parallel_env.possible_agents[0]
        self._order = list(parallel_env.observation_space(agent).spaces)  # the Dict's keys, as flattened
        if parallel_env.action_space(agent).n != 2:  # its masks and actions would be read as tamp or wait
            raise ValueError(f"{name}: an RLlib run of the PettingZoo agents on a line with the choices (each agent "
                             f"acts in {parallel_env.action_space(agent)}) cannot be scored yet: the scorer reads "
                             "tamp or wait only")

    def predict(self, observation: Mapping[str, Any], state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        b, batched = as_batch(dict(observation))
        n, s = b["section_sd"].shape
        may = may_tamp(b, self.config)
        features = np.stack([self.parallel_env.agent_features({k: v[i] for k, v in b.items()}) for i in range(n)])
        parts = {"observation": features, "action_mask": np.stack([np.ones_like(may), may], axis=-1)}
        x = np.concatenate([parts[k].astype(np.float32) for k in self._order], axis=-1).reshape(n * s, -1)
        want = _choose(_logits(self.module, x), deterministic, self._rng).reshape(n, s).astype(bool) & may
        act = want.astype(np.int8)
        return (act if batched else act[0]), state
