"""One harness to score tamping policies: rules (:mod:`trackenv_agents.rules`) and trained agents alike.

A policy is anything with SB3's ``predict(obs, state=None, episode_start=None, deterministic=True)
-> (action, state)`` that accepts a batched observation dict, or a plain function of that dict returning the
actions (:class:`CallablePolicy`). Each episode is identified by its seed: the
envs of :class:`~trackenv.envs.vector.TampingVectorEnv` are reset with one seed each, so the same seed gives
every policy the same track, ballast, initial level and (as long as the actions agree) tamping residuals:
policies are compared on common random numbers and differences are paired
(:func:`trackenv_agents.evaluation.statistics.paired_difference`).

Per episode we collect the life-cycle cost (k€, the sum of ``info["costs"]`` = minus the sum of rewards),
its parts, the number of section tampings, each section's applied choice in each step (``info["section_choices"]``,
counted per name by :attr:`EvaluationResult.choices`: on the tamping-only problems ``tamp`` counts the tamped
sections and the others stay 0),
the immediate-action exceedances (section-steps in class 3) and the mean section SD at the end; on a network
(``info["moved"]``), what the shared tamping machine did each step (:attr:`EvaluationResult.machine_steps`:
working, moving to another line, or idle).
**Tampings per km-year** is the tamped length per length of track per year:
``section_tampings · section_length_km / (track_length_km · horizon_years) = section_tampings /
(n_sections · horizon_years)``; 1.0 means the whole track is tamped once a year.

Many (policy, seed) pairs run in one vector env (``batch_size`` envs at a time), so the physics of a batch is
one call per step whatever mix of policies it holds; :mod:`trackenv_agents.evaluation.tuning` uses that to search grids.
Each batch is one call of :func:`run_episodes`; an ``executor`` (anything with ``map(fn, items)`` in order, e.g.
:class:`trackenv_agents.evaluation.distributed.RayExecutor`) runs the batches elsewhere, with the same results.

The neighbours: :mod:`trackenv_agents.evaluation.statistics` (bootstrap CIs, paired differences),
:mod:`trackenv_agents.evaluation.tuning` (grid search of the heuristics),
:mod:`trackenv_agents.evaluation.line_compare` (tune or load, then score on held-out seeds) and
:mod:`trackenv_agents.evaluation.reporting` (figures).
"""

from __future__ import annotations

import copy
import functools
import inspect
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode

from trackenv.envs.choices import CHOICES, INTERVENTIONS, IS_TRACK_WORK, action_type_for, code
from trackenv.envs.env import TrackVectorEnv
from trackenv.envs.problems import ProblemConfig, make_vector_env, problem_config

from ..rules.base import policy_params
from .statistics import bootstrap_ci

__all__ = [
    "CHOICE_NAMES", "MACHINE_STEPS", "TEST_SEEDS", "TRAIN_SEEDS", "CallablePolicy", "EvaluationResult", "as_policy",
    "bind_policy", "evaluate_many",
    "evaluate_one", "machine_activity", "policy_name", "policy_params", "record_episode", "run_episodes",
]

TRAIN_SEEDS: tuple[int, ...] = tuple(range(1000, 1100))
TEST_SEEDS: tuple[int, ...] = tuple(range(0, 200))
#: the choices counted per episode (``EvaluationResult.choices``), by their names in ``info["choices"]``
CHOICE_NAMES: tuple[str, ...] = INTERVENTIONS
#: what a network's tamping machine does in a step (``EvaluationResult.machine_steps``): track work on its line,
#: a move to another line (nothing worked anywhere), or neither
MACHINE_STEPS: tuple[str, ...] = ("work", "move", "idle")


def machine_activity(moved: np.ndarray, section_choices: np.ndarray) -> dict[str, np.ndarray]:
    """Per name of :data:`MACHINE_STEPS`, whether a network's machine did that in each step: ``moved`` (..., steps)
    ``info["moved"]`` and ``section_choices`` (..., steps, sections) the applied codes; it works where some
    section got track work and it did not move."""
    moved = np.asarray(moved, dtype=bool)
    worked = IS_TRACK_WORK[np.asarray(section_choices, dtype=np.int64)].any(axis=-1) & ~moved
    return {"work": worked, "move": moved, "idle": ~worked & ~moved}


def policy_name(policy: Any) -> str:
    """The policy's ``name`` attribute, else its class name."""
    return str(getattr(policy, "name", None) or type(policy).__name__)


def distinct_names(names: Sequence[str]) -> list[str]:
    """``names`` with a repeated one numbered from its second use ("<lambda>", "<lambda> (2)"): two plain
    functions, or the same rule given twice, stay two rows that tables and paired comparisons can tell apart."""
    seen: dict[str, int] = {}
    out = []
    for name in names:
        seen[name] = seen.get(name, 0) + 1
        out.append(name if seen[name] == 1 else f"{name} ({seen[name]})")
    return out


@dataclass
class EvaluationResult:
    """Per-episode outcomes of one policy (arrays aligned with ``seeds``)."""

    policy: str
    params: dict[str, Any]
    config: ProblemConfig
    seeds: np.ndarray
    cost: np.ndarray  # life-cycle cost per episode [k€]
    cost_parts: dict[str, np.ndarray]  # per COST_KEYS [k€]
    section_tampings: np.ndarray  # number of section tampings per episode
    immediate_action_exceedances: np.ndarray  # section-steps in class 3 per episode
    final_mean_sd_mm: np.ndarray  # mean section SD at the end [mm]
    sum_rewards: np.ndarray  # sum of rewards per episode (= -cost)
    # TampingLine: per episode and section its own costs ("section_cost", k€, possession excluded), its register
    # class ("register": 0 plain, 1 transition, 2 switch or crossing) and whether a hidden wet spot started in it
    # ("wet_spot"), each (episodes, sections)
    extra: dict[str, Any] = field(default_factory=dict)
    tamped: np.ndarray | None = None  # the sections tamped in each step of each episode (episodes, steps, sections)
    # the choice code each section got in each step of each episode (episodes, steps, sections), int8
    section_choices: np.ndarray | None = None
    # on a network: whether the machine moved to another line in each step of each episode (episodes, steps)
    machine_moved: np.ndarray | None = None
    # whether a section left the model's validity in some step of each episode (info["beyond_validity"]): its
    # costs from there on are not physical (episodes,)
    beyond_validity: np.ndarray | None = None

    @property
    def choices(self) -> dict[str, np.ndarray]:
        """Per name of :data:`CHOICE_NAMES`, how many sections got that choice in each episode (from
        ``section_choices``; {} where the result has none)."""
        if self.section_choices is None:
            return {}
        codes = np.asarray(self.section_choices)
        return {name: (codes == code(name)).sum(axis=(1, 2)) for name in CHOICE_NAMES}

    @property
    def machine_steps(self) -> dict[str, np.ndarray]:
        """On a network, per name of :data:`MACHINE_STEPS`, the steps of each episode in which the shared machine
        did track work on its line, moved to another line, or did neither ({} where the result has no machine:
        a line, the 60 m track)."""
        if self.machine_moved is None or self.section_choices is None:
            return {}
        return {k: v.sum(axis=1) for k, v in machine_activity(self.machine_moved, self.section_choices).items()}

    @property
    def n_episodes(self) -> int:
        return int(self.cost.size)

    @property
    def episodes_beyond_validity(self) -> int:
        """How many episodes had a section beyond the model's validity in some step (0 where not recorded)."""
        return 0 if self.beyond_validity is None else int(self.beyond_validity.sum())

    @property
    def tampings_per_km_year(self) -> np.ndarray:
        """Tamped length per length of track per year, per episode (see the module docstring)."""
        c = self.config
        return self.section_tampings / (c.n_sections * c.horizon_years)

    def summary(self) -> dict[str, Any]:
        lo, hi = bootstrap_ci(self.cost)
        counts = self.choices
        machine = {"machine_steps": {k: float(v.mean()) for k, v in self.machine_steps.items()}} \
            if self.machine_moved is not None else {}
        return {
            "policy": self.policy,
            "params": dict(self.params),
            "n_episodes": self.n_episodes,
            "mean_cost": float(self.cost.mean()),
            "ci_low": lo,
            "ci_high": hi,
            "std_cost": float(self.cost.std(ddof=1)) if self.n_episodes > 1 else 0.0,
            "cost_parts": {k: float(v.mean()) for k, v in self.cost_parts.items()},
            "section_tampings": float(self.section_tampings.mean()),
            "tampings_per_km_year": float(self.tampings_per_km_year.mean()),
            "immediate_action_exceedances": int(self.immediate_action_exceedances.sum()),
            "immediate_action_exceedances_mean": float(self.immediate_action_exceedances.mean()),
            "mean_final_sd_mm": float(self.final_mean_sd_mm.mean()),
            "choices": {name: float(np.mean(counts[name])) if name in counts else 0.0 for name in CHOICE_NAMES},
            "episodes_beyond_validity": self.episodes_beyond_validity,
            **machine,
        }


def _vector_env(n: int, cfg: Any, action_type: str) -> TrackVectorEnv:
    """The native vector env of ``cfg``'s problem, in NEXT_STEP autoreset: no episode is started past the
    horizon and the last step's info stays in place (every problem follows the same conventions)."""
    return make_vector_env(cfg, n, action_type=action_type, autoreset_mode=AutoresetMode.NEXT_STEP)


class CallablePolicy:
    """A plain function of the batched observation, ``fn(obs) -> actions`` (one row per env), as a policy with
    stable-baselines3's ``predict``: no memory, the same actions whether deterministic or not. Named by ``name``,
    else the function's own name."""

    def __init__(self, fn: Any, name: str | None = None) -> None:
        if isinstance(fn, type) or not callable(fn):
            raise ValueError(f"fn must be a function of the observation returning the actions, got {fn!r}")
        self.fn = fn
        self.name = name or getattr(fn, "__name__", None) or type(fn).__name__

    def predict(self, obs: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        return np.asarray(self.fn(obs)), None


def as_policy(policy: Any, name: str | None = None) -> Any:
    """``policy`` as the harness plays it: an object with ``predict`` as it is, a plain function of the batched
    observation (not a class) as a :class:`CallablePolicy` named ``name``; anything else as it is (refused where
    it is played, with the reason)."""
    if callable(getattr(policy, "predict", None)) or isinstance(policy, type) or not callable(policy):
        return policy
    return CallablePolicy(policy, name)


def bind_policy(policy: Any, config: ProblemConfig) -> Any:
    """``policy`` as it plays ``config``: a rule that reads the problem's calendar or capacity (it has ``bind``)
    bound to it, a plain function as a :class:`CallablePolicy`, any other policy (a trained agent, any object with
    SB3's ``predict``) as it is."""
    policy = as_policy(policy)
    bind = getattr(policy, "bind", None)
    return bind(config) if callable(bind) else policy


def _checked_actions(policy: Any, action: Any, shape: tuple[int, ...], top: int) -> np.ndarray:
    """The actions a policy returned for a batch of envs, as the vector env takes them (one row per env), before
    the cast to integers could turn 0.7 or NaN into "wait": ValueError naming the policy for another shape (a
    transposed or flattened batch would be read row by row as other envs' actions), for values that are not
    whole numbers, or for whole numbers outside [0, ``top``] (1: tamp or wait; the number of sections: one
    section's number; the last choice code)."""
    a = np.asarray(action)
    if a.shape != shape:
        raise ValueError(f"policy {policy_name(policy)!r}: predict returned actions of shape {a.shape} for a batch "
                         f"of {shape[0]} envs; it is given a batch of observations (one row per env) and must "
                         f"return one action per row, shape {shape}")
    try:
        values = a.astype(float)
    except (TypeError, ValueError):
        raise ValueError(f"policy {policy_name(policy)!r}: predict returned actions that are not numbers: "
                         f"{a.ravel()[:8].tolist()}") from None
    bad = ~np.isfinite(values) | (values != np.round(values))
    if bad.any():
        raise ValueError(f"policy {policy_name(policy)!r}: predict returned actions that are not whole numbers "
                         f"(0 wait, 1 tamp, or a choice code): {a.ravel()[bad.ravel()][:8].tolist()}")
    out = (values < 0) | (values > top)
    if out.any():
        raise ValueError(f"policy {policy_name(policy)!r}: predict returned actions outside [0, {top}]: "
                         f"{a.ravel()[out.ravel()][:8].tolist()}")
    return values


def add_note(error: BaseException, note: str) -> None:
    """``error.add_note(note)`` (Python 3.11: the traceback shows it under the message); on 3.10 the note is kept
    in ``__notes__`` alone."""
    if hasattr(error, "add_note"):
        error.add_note(note)
    else:  # pragma: no cover - Python 3.10
        error.__notes__ = [*getattr(error, "__notes__", []), note]  # type: ignore[attr-defined]


def takes_action_masks(policy: Any) -> bool:
    """Whether ``policy.predict`` has an ``action_masks`` argument (sb3-contrib's MaskablePPO, a loaded SB3
    policy): the harness then gives it the env's masks, one row per env."""
    predict = getattr(policy, "predict", None)
    if not callable(predict):  # (no predict at all: the harness refuses it where it plays)
        return False
    try:
        return "action_masks" in inspect.signature(predict).parameters
    except (TypeError, ValueError):  # pragma: no cover - a predict without a signature
        return False


def _predict(policy: Any, obs: dict[str, np.ndarray], state: Any, episode_start: np.ndarray,
             masks: np.ndarray | None = None) -> tuple[Any, Any]:
    """``policy.predict`` on a batch (with the env's ``masks`` where given), checked to return SB3's pair
    (actions, state): a bare array would unpack into its first two rows."""
    extra = {} if masks is None else {"action_masks": masks}
    try:
        out = policy.predict(obs, state=state, episode_start=episode_start, deterministic=True, **extra)
    except Exception as error:  # e.g. a network fed another line's sizes: say whose predict it was
        add_note(error, f"raised by predict of policy {policy_name(policy)!r} on a batch of {len(episode_start)} "
                       "observations")
        raise
    if not (isinstance(out, tuple) and len(out) == 2):
        raise ValueError(f"policy {policy_name(policy)!r}: predict must return a pair (actions, state) as "
                         f"stable-baselines3's does (state None for a policy without memory), got "
                         f"{type(out).__name__}")
    return out


def _checked_policies(policies: Sequence[Any]) -> None:
    """ValueError naming the first entry of ``policies`` without SB3's ``predict`` (a class instead of an
    instance, a path instead of a loaded model)."""
    for p in policies:
        if isinstance(p, type) or not callable(getattr(p, "predict", None)):
            hint = (" (load a saved model first)" if isinstance(p, (str, Path))
                    else " (a class: give an instance of it)" if isinstance(p, type) else "")
            raise ValueError(f"policy {p!r} has no predict(observation, state, episode_start, deterministic): a "
                             f"policy is an object with stable-baselines3's predict, or a function of the batched "
                             f"observation returning the actions{hint}")


def _take(obs: dict[str, np.ndarray], idx: np.ndarray) -> dict[str, np.ndarray]:
    return {k: v[idx] for k, v in obs.items()}


def _run_chunk(env: TrackVectorEnv, slots: list[tuple[int, int]], policies: Sequence[Any],
               action_type: str, record: bool = False, pbar: Any = None) -> dict[str, Any]:
    """Run one episode per slot (policy index, seed) to the horizon; per-env totals (and traces if record)."""
    cfg = env.config
    n = len(slots)
    obs, _ = env.reset(seed=[s for _, s in slots])
    pol_of = np.array([p for p, _ in slots])
    groups = {p: np.flatnonzero(pol_of == p) for p in np.unique(pol_of)}
    states: dict[int, Any] = dict.fromkeys(groups)
    for p in groups:
        reset = getattr(policies[p], "reset", None)
        if callable(reset):
            reset()
    keys = type(cfg).cost_keys()
    parts = {k: np.zeros(n) for k in keys}
    rewards = np.zeros(n)
    tampings = np.zeros(n)
    exceed = np.zeros(n)
    beyond = np.zeros(n, dtype=bool)
    final_sd = np.zeros(n)
    tamped = np.zeros((n, cfg.horizon_steps, cfg.n_sections), dtype=bool)
    chosen = np.zeros((n, cfg.horizon_steps, cfg.n_sections), dtype=np.int8)
    moved = np.zeros((n, cfg.horizon_steps), dtype=bool)
    has_machine = False
    section_cost = np.zeros((n, cfg.n_sections))  # each section's own costs (info["section_costs"])
    register = np.asarray(obs.get("register", np.zeros((n, cfg.n_sections))), dtype=np.int64)
    traces: dict[str, list] = {"section_sd_mm": [], "tamped": [], "cost": [], "year": []}
    if record:
        traces["section_sd_mm"].append(obs["section_sd"].copy())
    if action_type == "discrete":
        actions = np.zeros(n, dtype=np.int64)
    else:
        actions = np.zeros((n, cfg.n_sections), dtype=np.int8)
    top = {"discrete": cfg.n_sections, "choices": len(CHOICES) - 1}.get(action_type, 1)
    masked = {p for p in groups if takes_action_masks(policies[p])}
    for t in range(cfg.horizon_steps):
        masks = np.asarray(env.action_masks()) if masked else None
        for p, idx in groups.items():
            a, states[p] = _predict(policies[p], _take(obs, idx), states[p], np.full(idx.size, t == 0),
                                    None if masks is None or p not in masked else masks[idx])
            actions[idx] = _checked_actions(policies[p], a, actions[idx].shape, top)
        obs, r, _, trunc, info = env.step(actions)
        rewards += r
        for k in keys:
            parts[k] += info["costs"][k]
        tampings += info["tamped_sections"].sum(axis=1)
        tamped[:, t] = info["tamped_sections"]
        chosen[:, t] = info["section_choices"]
        if "moved" in info:  # a network: its machine's move
            moved[:, t] = info["moved"]
            has_machine = True
        section_cost += info["section_costs"]
        exceed += info["immediate_action_exceedances"]
        beyond |= info["beyond_validity"]
        if record:
            traces["section_sd_mm"].append(info["section_sd_mm"])
            traces["tamped"].append(info["tamped_sections"].copy())
            traces["cost"].append(info["cost"].copy())
            traces["year"].append(info["year"].copy())
        if pbar is not None:
            pbar.update(1)
        if t == cfg.horizon_steps - 1:
            if not trunc.all():  # pragma: no cover - guards a change of the env's horizon rule
                raise RuntimeError("episodes did not end at the configured horizon")
            final_sd = info["section_sd_mm"].mean(axis=1)
            wet = np.asarray(info.get("wet_spot_active", np.zeros((n, cfg.n_sections))), dtype=bool)
    return {"parts": parts, "rewards": rewards, "tampings": tampings, "exceed": exceed, "beyond_validity": beyond,
            "final_sd": final_sd, "tamped": tamped, "section_choices": chosen,
            "machine_moved": moved if has_machine else None, "section_cost": section_cost,
            "register": register, "wet_spot": wet, "traces": traces}


def run_episodes(config: ProblemConfig, slots: Sequence[tuple[int, int]], policies: Sequence[Any],
                 action_type: str = "multibinary") -> dict[str, Any]:
    """One batch: an episode per slot ``(policy index, seed)`` to the horizon in one native vector env
    (NEXT_STEP autoreset: no episode is started past the horizon); per-episode totals as arrays in slot order
    (``parts`` by cost key, ``rewards``, ``tampings``, ``exceed``, ``final_sd``, ``tamped``). The unit of work that
    :func:`evaluate_many` runs in turn, or an executor runs in parallel."""
    env = _vector_env(len(slots), config, action_type)
    out = _run_chunk(env, list(slots), policies, action_type)
    out.pop("traces")
    return out


def evaluate_many(policies: Sequence[Any], config: ProblemConfig | dict | str | None = None,
                  seeds: Iterable[int] = TEST_SEEDS, action_type: str | None = None, batch_size: int = 32,
                  progress: bool = False, desc: str = "evaluate", executor: Any = None) -> list[EvaluationResult]:
    """Evaluate every policy on every seed, all (policy, seed) pairs batched ``batch_size`` at a time.

    ``action_type``: the env's (None: the config's own, :func:`~trackenv.envs.choices.action_type_for`: the
    choice codes where it enables more than tamping, else tamp or wait).

    Results are independent of the batching: each env draws only from its own seed's generator. ``executor``:
    runs the batches (:func:`run_episodes`) through its ``map`` (e.g. on Ray workers); None: here, in turn.
    """
    cfg = problem_config(config)
    action_type = action_type or action_type_for(cfg)
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("seeds must not be empty")
    if batch_size < 1:
        raise ValueError(f"batch_size must be >= 1, got {batch_size!r}")
    policies = [as_policy(p) for p in policies]
    _checked_policies(policies)
    bound = [bind_policy(p, cfg) for p in policies]
    slots = [(p, s) for p in range(len(bound)) for s in seeds]
    chunks = [slots[i:i + batch_size] for i in range(0, len(slots), batch_size)]
    pbar = None
    if progress:
        from tqdm.auto import tqdm

        pbar = tqdm(total=len(chunks) * cfg.horizon_steps, desc=desc, unit="step")
    outs = []
    try:
        if executor is None:
            for chunk in chunks:
                env = _vector_env(len(chunk), cfg, action_type)
                outs.append(_run_chunk(env, chunk, bound, action_type, pbar=pbar))
        else:
            for out in executor.map(functools.partial(run_episodes, cfg, policies=bound, action_type=action_type),
                                    chunks):
                outs.append(out)
                if pbar is not None:
                    pbar.update(cfg.horizon_steps)
    finally:
        if pbar is not None:
            pbar.close()

    def cat(key: str) -> np.ndarray:
        return np.concatenate([o[key] for o in outs])

    pol_of = np.array([p for p, _ in slots])
    seed_arr = np.array([s for _, s in slots])
    parts_all = {k: np.concatenate([o["parts"][k] for o in outs]) for k in type(cfg).cost_keys()}
    rewards, tampings, exceed, final_sd = cat("rewards"), cat("tampings"), cat("exceed"), cat("final_sd")
    beyond = cat("beyond_validity")
    tamped, chosen = cat("tamped"), cat("section_choices")
    moved = cat("machine_moved") if outs[0]["machine_moved"] is not None else None
    sections = {k: cat(k) for k in ("section_cost", "register", "wet_spot")}
    results = []
    for p, (pol, name) in enumerate(zip(bound, distinct_names([policy_name(b) for b in bound]), strict=True)):
        m = pol_of == p
        parts = {k: v[m] for k, v in parts_all.items()}
        results.append(EvaluationResult(
            policy=name, params=policy_params(pol), config=cfg, seeds=seed_arr[m],
            cost=sum(parts.values()), cost_parts=parts, section_tampings=tampings[m],
            immediate_action_exceedances=exceed[m], final_mean_sd_mm=final_sd[m], sum_rewards=rewards[m],
            tamped=tamped[m], section_choices=chosen[m], machine_moved=None if moved is None else moved[m],
            beyond_validity=beyond[m], extra={k: v[m] for k, v in sections.items()}))
    return results


def evaluate_one(policy: Any, config: ProblemConfig | dict | str | None = None,
                 seeds: Iterable[int] = TEST_SEEDS, action_type: str | None = None, batch_size: int = 32,
                 progress: bool = False) -> EvaluationResult:
    """One policy, one episode per seed through the problem's native vector env (``batch_size`` envs at a time):
    :func:`evaluate_many` for a single policy. The episode returns are ``.sum_rewards``."""
    return evaluate_many([policy], config, seeds, action_type, batch_size, progress,
                         desc=policy_name(policy))[0]


def evaluate_policy(*args: Any, **kwargs: Any) -> EvaluationResult:
    """Deprecated name of :func:`evaluate_one` (it shadowed stable-baselines3's ``evaluate_policy``, which takes
    an env and returns a mean and a standard deviation)."""
    import warnings

    warnings.warn("trackenv_agents.evaluation.evaluate_policy is now evaluate_one", DeprecationWarning,
                  stacklevel=2)
    return evaluate_one(*args, **kwargs)


def record_episode(policy: Any, config: ProblemConfig | dict | str | None = None, seed: int = 0,
                   action_type: str = "multibinary") -> dict[str, np.ndarray]:
    """One episode's traces: section SD [mm] (steps+1, n_sections), tamped (steps, n_sections), cost and year
    per step."""
    cfg = problem_config(config)
    pol = bind_policy(copy.deepcopy(policy) if hasattr(policy, "_rng") else policy, cfg)
    env = _vector_env(1, cfg, action_type)
    out = _run_chunk(env, [(0, int(seed))], [pol], action_type, record=True)
    tr = out["traces"]
    return {"section_sd_mm": np.array([x[0] for x in tr["section_sd_mm"]]),
            "tamped": np.array([x[0] for x in tr["tamped"]]), "cost": np.array([x[0] for x in tr["cost"]]),
            "year": np.array([x[0] for x in tr["year"]])}
