"""One harness to score tamping policies: heuristics (:mod:`agents.heuristics`) and trained agents alike.

A policy is anything with SB3's ``predict(obs, state=None, episode_start=None, deterministic=True)
-> (action, state)`` that accepts a batched observation dict. Each episode is identified by its seed: the
envs of :class:`~trackenv.envs.vector.TampingVectorEnv` are reset with one seed each, so the same seed gives
every policy the same track, ballast, initial level and (as long as the actions agree) tamping residuals:
policies are compared on common random numbers and differences are paired (:func:`paired_difference`).

Per episode we collect the life-cycle cost (k€, the sum of ``info["costs"]`` = minus the sum of rewards),
its parts, the number of section tampings, the immediate-action exceedances (section-steps in class 3) and
the mean section SD at the end. **Tampings per km-year** is the tamped length per length of track per year:
``section_tampings · section_length_km / (track_length_km · horizon_years) = section_tampings /
(n_sections · horizon_years)``; 1.0 means the whole track is tamped once a year.

Many (policy, seed) pairs run in one vector env (``batch_size`` envs at a time), so the physics of a batch is
one call per step whatever mix of policies it holds; :func:`tune` uses that to search grids. Each batch is one
call of :func:`run_episodes`; an ``executor`` (anything with ``map(fn, items)`` in order, e.g.
:class:`trackenv_agents.distributed.RayExecutor`) runs the batches elsewhere, with the same results.
"""

from __future__ import annotations

import copy
import functools
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode

from trackenv.envs.config import TampingEnvConfig
from trackenv.envs.episode import COST_KEYS
from trackenv.envs.vector import TampingVectorEnv

__all__ = [
    "TEST_SEEDS", "TRAIN_SEEDS", "EvaluationResult", "bootstrap_ci", "compare", "compare_results",
    "evaluate_many", "evaluate_one", "format_markdown", "format_table", "paired_difference", "tune_many",
    "plot_comparison", "plot_episode", "policy_name", "policy_params", "run_episodes", "tune",
]

TRAIN_SEEDS: tuple[int, ...] = tuple(range(1000, 1100))
TEST_SEEDS: tuple[int, ...] = tuple(range(0, 200))
N_BOOTSTRAP = 2000


def policy_name(policy: Any) -> str:
    """The policy's ``name`` attribute, else its class name."""
    return str(getattr(policy, "name", None) or type(policy).__name__)


def policy_params(policy: Any) -> dict[str, Any]:
    params = getattr(policy, "params", None)
    return dict(params) if isinstance(params, Mapping) else {}


def bootstrap_ci(x: np.ndarray, n_resamples: int = N_BOOTSTRAP, level: float = 0.95,
                 seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap CI of the mean of ``x`` (its own generator: reproducible)."""
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return math.nan, math.nan
    rng = np.random.default_rng(seed)
    means = x[rng.integers(0, x.size, size=(n_resamples, x.size))].mean(axis=1)
    a = (1.0 - level) / 2
    lo, hi = np.quantile(means, [a, 1.0 - a])
    return float(lo), float(hi)


@dataclass
class EvaluationResult:
    """Per-episode outcomes of one policy (arrays aligned with ``seeds``)."""

    policy: str
    params: dict[str, Any]
    config: TampingEnvConfig
    seeds: np.ndarray
    cost: np.ndarray  # life-cycle cost per episode [k€]
    cost_parts: dict[str, np.ndarray]  # per COST_KEYS [k€]
    section_tampings: np.ndarray  # number of section tampings per episode
    immediate_action_exceedances: np.ndarray  # section-steps in class 3 per episode
    final_mean_sd_mm: np.ndarray  # mean section SD at the end [mm]
    sum_rewards: np.ndarray  # sum of rewards per episode (= -cost)
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def n_episodes(self) -> int:
        return int(self.cost.size)

    @property
    def tampings_per_km_year(self) -> np.ndarray:
        """Tamped length per length of track per year, per episode (see the module docstring)."""
        c = self.config
        return self.section_tampings / (c.n_sections * c.horizon_years)

    def summary(self) -> dict[str, Any]:
        lo, hi = bootstrap_ci(self.cost)
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
        }



def _bound(policy: Any, config: TampingEnvConfig) -> Any:
    bind = getattr(policy, "bind", None)
    return bind(config) if callable(bind) else policy


def _take(obs: dict[str, np.ndarray], idx: np.ndarray) -> dict[str, np.ndarray]:
    return {k: v[idx] for k, v in obs.items()}


def _run_chunk(env: TampingVectorEnv, slots: list[tuple[int, int]], policies: Sequence[Any],
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
    parts = {k: np.zeros(n) for k in COST_KEYS}
    rewards = np.zeros(n)
    tampings = np.zeros(n)
    exceed = np.zeros(n)
    final_sd = np.zeros(n)
    traces: dict[str, list] = {"section_sd_mm": [], "tamped": [], "cost": [], "year": []}
    if record:
        traces["section_sd_mm"].append(obs["section_sd"].copy())
    if action_type == "discrete":
        actions = np.zeros(n, dtype=np.int64)
    else:
        actions = np.zeros((n, cfg.n_sections), dtype=np.int8)
    for t in range(cfg.horizon_steps):
        for p, idx in groups.items():
            a, states[p] = policies[p].predict(_take(obs, idx), state=states[p],
                                               episode_start=np.full(idx.size, t == 0), deterministic=True)
            actions[idx] = np.asarray(a).reshape(actions[idx].shape)
        obs, r, _, trunc, info = env.step(actions)
        rewards += r
        for k in COST_KEYS:
            parts[k] += info["costs"][k]
        tampings += info["tamped_sections"].sum(axis=1)
        exceed += info["immediate_action_exceedances"]
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
    return {"parts": parts, "rewards": rewards, "tampings": tampings, "exceed": exceed, "final_sd": final_sd,
            "traces": traces}


def run_episodes(config: TampingEnvConfig, slots: Sequence[tuple[int, int]], policies: Sequence[Any],
                 action_type: str = "multibinary") -> dict[str, Any]:
    """One batch: an episode per slot ``(policy index, seed)`` to the horizon in one native vector env
    (NEXT_STEP autoreset: no episode is started past the horizon); per-episode totals as arrays in slot order
    (``parts`` by cost key, ``rewards``, ``tampings``, ``exceed``, ``final_sd``). The unit of work that
    :func:`evaluate_many` runs in turn, or an executor runs in parallel."""
    env = TampingVectorEnv(len(slots), config, action_type=action_type, autoreset_mode=AutoresetMode.NEXT_STEP)
    out = _run_chunk(env, list(slots), policies, action_type)
    out.pop("traces")
    return out


def evaluate_many(policies: Sequence[Any], config: TampingEnvConfig | dict | None = None,
                  seeds: Iterable[int] = TEST_SEEDS, action_type: str = "multibinary", batch_size: int = 32,
                  progress: bool = False, desc: str = "evaluate", executor: Any = None) -> list[EvaluationResult]:
    """Evaluate every policy on every seed, all (policy, seed) pairs batched ``batch_size`` at a time.

    Results are independent of the batching: each env draws only from its own seed's generator. ``executor``:
    runs the batches (:func:`run_episodes`) through its ``map`` (e.g. on Ray workers); None: here, in turn.
    """
    cfg = TampingEnvConfig.coerce(config)
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("seeds must not be empty")
    if batch_size < 1:
        raise ValueError(f"batch_size must be >= 1, got {batch_size!r}")
    bound = [_bound(p, cfg) for p in policies]
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
                env = TampingVectorEnv(len(chunk), cfg, action_type=action_type,
                                       autoreset_mode=AutoresetMode.NEXT_STEP)
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
    parts_all = {k: np.concatenate([o["parts"][k] for o in outs]) for k in COST_KEYS}
    rewards, tampings, exceed, final_sd = cat("rewards"), cat("tampings"), cat("exceed"), cat("final_sd")
    results = []
    for p, pol in enumerate(bound):
        m = pol_of == p
        parts = {k: v[m] for k, v in parts_all.items()}
        results.append(EvaluationResult(
            policy=policy_name(pol), params=policy_params(pol), config=cfg, seeds=seed_arr[m],
            cost=sum(parts.values()), cost_parts=parts, section_tampings=tampings[m],
            immediate_action_exceedances=exceed[m], final_mean_sd_mm=final_sd[m], sum_rewards=rewards[m]))
    return results


def evaluate_one(policy: Any, config: TampingEnvConfig | dict | None = None,
                 seeds: Iterable[int] = TEST_SEEDS, action_type: str = "multibinary", batch_size: int = 32,
                 progress: bool = False) -> EvaluationResult:
    """One policy, one episode per seed through :class:`TampingVectorEnv` (``batch_size`` envs at a time):
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


def paired_difference(a: EvaluationResult, b: EvaluationResult, n_resamples: int = N_BOOTSTRAP) -> dict:
    """Mean of the per-episode cost differences a − b on common seeds, with a 95 % bootstrap CI."""
    common, ia, ib = np.intersect1d(a.seeds, b.seeds, return_indices=True)
    if common.size == 0:
        raise ValueError("the two results share no seeds")
    d = a.cost[ia] - b.cost[ib]
    lo, hi = bootstrap_ci(d, n_resamples)
    return {"a": a.policy, "b": b.policy, "n_episodes": int(common.size), "mean_difference": float(d.mean()),
            "ci_low": lo, "ci_high": hi, "a_better_fraction": float(np.mean(d < 0))}


def tune(policy_cls: type, config: TampingEnvConfig | dict | None = None,
         train_seeds: Iterable[int] = TRAIN_SEEDS, grid: Sequence[dict] | None = None, batch_size: int = 32,
         progress: bool = False, executor: Any = None) -> dict[str, Any]:
    """Grid search of ``policy_cls`` over ``grid`` (default ``policy_cls.param_grid()``) on ``train_seeds``.

    Returns ``{"policy", "best_params", "best_mean_cost", "table"}``; ``table`` lists every candidate's
    params, mean cost and per-episode costs on the training seeds, sorted by cost (ties: grid order).
    """
    grid = list(policy_cls.param_grid() if grid is None else grid)
    if not grid:
        raise ValueError("empty parameter grid")
    return tune_many([policy_cls], TampingEnvConfig.coerce(config), list(train_seeds), batch_size, progress,
                     grids=[grid], executor=executor)[0]


def tune_many(classes: Sequence[type], cfg: TampingEnvConfig, train_seeds: Sequence[int], batch_size: int,
              progress: bool, grids: Sequence[Sequence[dict]] | None = None, executor: Any = None) -> dict[int, dict]:
    """:func:`tune` for several classes in one batched run, each over its grid (default its
    ``param_grid()``); table rows also hold the per-episode costs, in ``train_seeds`` order."""
    if grids is None:
        grids = [cls.param_grid() for cls in classes]
    cands = [(i, g) for i, grid in enumerate(grids) for g in grid]
    desc = f"tune {getattr(classes[0], 'name', classes[0].__name__)}" if len(classes) == 1 else "tune"
    results = evaluate_many([classes[i](**g) for i, g in cands], cfg, train_seeds, batch_size=batch_size,
                            progress=progress, desc=desc, executor=executor)
    out: dict[int, dict] = {}
    for i, cls in enumerate(classes):
        rows = sorted(({"params": dict(g), "mean_cost": float(r.cost.mean()),
                        "tampings_per_km_year": float(r.tampings_per_km_year.mean()),
                        "episode_costs": r.cost.tolist()}
                       for (j, g), r in zip(cands, results, strict=True) if j == i),
                      key=lambda row: row["mean_cost"])
        out[i] = {"policy": getattr(cls, "name", cls.__name__), "best_params": rows[0]["params"],
                  "best_mean_cost": rows[0]["mean_cost"], "table": rows}
    return out


def compare_results(policies: Sequence[Any] | Mapping[str, Any],
                    config: TampingEnvConfig | dict | None = None,
                    test_seeds: Iterable[int] = TEST_SEEDS, train_seeds: Iterable[int] | None = None,
                    tune_heuristics: bool = True, batch_size: int = 32, progress: bool = False,
                    executor: Any = None) -> tuple[list[EvaluationResult], dict[str, dict]]:
    """Tune (classes with a ``param_grid``, on ``train_seeds``) and evaluate on ``test_seeds``.

    ``policies``: heuristic classes (tuned if ``tune_heuristics`` and ``train_seeds`` are given, else default
    parameters), registry names (as classes), or ready policy objects (used as they are); or a mapping
    name -> any of these (the name labels the result). Returns the results sorted by mean cost and the tuning
    tables by policy name.
    """
    from .heuristics import HEURISTICS

    cfg = TampingEnvConfig.coerce(config)
    items = list(policies.items()) if isinstance(policies, Mapping) else [(None, p) for p in policies]
    items = [(label, HEURISTICS[p] if isinstance(p, str) else p) for label, p in items]
    tunable = [i for i, (_, p) in enumerate(items) if isinstance(p, type) and hasattr(p, "param_grid")]
    tuning: dict[str, dict] = {}
    chosen: list[Any] = []
    tuned = {}
    if tune_heuristics and train_seeds is not None and tunable:
        tuned = tune_many([items[i][1] for i in tunable], cfg, list(train_seeds), batch_size, progress,
                          executor=executor)
    for i, (label, p) in enumerate(items):
        if isinstance(p, type):
            if i in tunable and tunable.index(i) in tuned:
                t = tuned[tunable.index(i)]
                tuning[label or t["policy"]] = t
                obj = p(**t["best_params"])
            else:
                obj = p()
        else:
            obj = p
        chosen.append(obj)
    results = evaluate_many(chosen, cfg, test_seeds, batch_size=batch_size, progress=progress, desc="test",
                            executor=executor)
    for (label, _), r in zip(items, results, strict=True):
        if label is not None:
            r.policy = label
    results.sort(key=lambda r: float(r.cost.mean()))
    return results, tuning


def compare(policies: Sequence[Any] | Mapping[str, Any], config: TampingEnvConfig | dict | None = None,
            test_seeds: Iterable[int] = TEST_SEEDS, train_seeds: Iterable[int] | None = None,
            tune_heuristics: bool = True, batch_size: int = 32, progress: bool = False,
            executor: Any = None) -> list[dict]:
    """Summaries (:meth:`EvaluationResult.summary`) of :func:`compare_results`, sorted by mean cost."""
    results, _ = compare_results(policies, config, test_seeds, train_seeds, tune_heuristics, batch_size,
                                 progress, executor)
    return [r.summary() for r in results]


_COLUMNS = (("policy", "policy", "{}"), ("params", "params", "{}"), ("n", "n_episodes", "{:d}"),
            ("cost k€", "mean_cost", "{:.1f}"), ("95% CI", None, None),
            ("tamp/km·yr", "tampings_per_km_year", "{:.3f}"),
            ("IAL exc.", "immediate_action_exceedances", "{:d}"),
            ("final SD mm", "mean_final_sd_mm", "{:.2f}"))


def _fmt_params(params: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in params.items()) or "-"


def _cells(rows: Sequence[Mapping[str, Any]]) -> list[list[str]]:
    out = []
    for r in rows:
        cells = []
        for _, key, fmt in _COLUMNS:
            if key is None:
                cells.append(f"[{r['ci_low']:.1f}, {r['ci_high']:.1f}]")
            elif key == "params":
                cells.append(_fmt_params(r.get("params", {})))
            else:
                cells.append(fmt.format(r[key]))
        out.append(cells)
    return out


def format_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """A fixed-width text table of summaries."""
    head = [c[0] for c in _COLUMNS]
    body = _cells(rows)
    widths = [max(len(h), *(len(b[i]) for b in body)) if body else len(h) for i, h in enumerate(head)]
    num = [i >= 2 for i in range(len(head))]

    def line(cells):
        padded = (c.rjust(w) if n else c.ljust(w) for c, w, n in zip(cells, widths, num, strict=True))
        return "  ".join(padded).rstrip()

    return "\n".join([line(head), "  ".join("-" * w for w in widths), *(line(b) for b in body)])


def format_markdown(rows: Sequence[Mapping[str, Any]]) -> str:
    """A Markdown table of summaries."""
    head = [c[0] for c in _COLUMNS]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * 2 + ["---:"] * (len(head) - 2)) + "|"]
    lines += ["| " + " | ".join(c.replace("|", "\\|") for c in b) + " |" for b in _cells(rows)]
    return "\n".join(lines)


def plot_comparison(results: Sequence[EvaluationResult], out_png: str) -> str:
    """Box plot (with the episodes as dots) of the per-episode life-cycle cost of each policy."""
    from matplotlib.figure import Figure  # pyplot-free: no global state, the user's backend untouched

    fig = Figure(figsize=(max(5.0, 1.4 * len(results) + 2), 4.5))
    ax = fig.subplots()
    data = [r.cost for r in results]
    ax.boxplot(data, showmeans=True, showfliers=False)
    rng = np.random.default_rng(0)
    for i, d in enumerate(data, start=1):
        ax.plot(i + rng.uniform(-0.15, 0.15, d.size), d, ".", alpha=0.35, color="C0", ms=4)
    ax.set_xticks(range(1, len(results) + 1), [r.policy for r in results], rotation=20, ha="right")
    ax.set_ylabel("life-cycle cost per episode [k€]")
    n = results[0].n_episodes if results else 0
    ax.set_title(f"Tamping policies on {n} held-out episodes (mean ▲)")
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_png, dpi=120)
    return out_png


def record_episode(policy: Any, config: TampingEnvConfig | dict | None = None, seed: int = 0,
                   action_type: str = "multibinary") -> dict[str, np.ndarray]:
    """One episode's traces: section SD [mm] (steps+1, n_sections), tamped (steps, n_sections), cost and year
    per step."""
    cfg = TampingEnvConfig.coerce(config)
    pol = _bound(copy.deepcopy(policy) if hasattr(policy, "_rng") else policy, cfg)
    env = TampingVectorEnv(1, cfg, action_type=action_type, autoreset_mode=AutoresetMode.NEXT_STEP)
    out = _run_chunk(env, [(0, int(seed))], [pol], action_type, record=True)
    tr = out["traces"]
    return {"section_sd_mm": np.array([x[0] for x in tr["section_sd_mm"]]),
            "tamped": np.array([x[0] for x in tr["tamped"]]), "cost": np.array([x[0] for x in tr["cost"]]),
            "year": np.array([x[0] for x in tr["year"]])}


def plot_episode(policy: Any, config: TampingEnvConfig | dict | None, seed: int, out_png: str) -> str:
    """One episode under ``policy``: section SD over time with tamping marks (top), cost per step (bottom)."""
    from matplotlib.figure import Figure  # pyplot-free: no global state, the user's backend untouched

    cfg = TampingEnvConfig.coerce(config)
    tr = record_episode(policy, cfg, seed)
    years = np.concatenate([[0.0], tr["year"]])
    lim = cfg.quality_limits.for_speed(cfg.speed)
    fig = Figure(figsize=(8, 6))
    ax1, ax2 = fig.subplots(2, 1, sharex=True, height_ratios=(2, 1))
    for s in range(cfg.n_sections):
        color = f"C{s % 10}"
        ax1.plot(years, tr["section_sd_mm"][:, s], color=color, label=f"section {s + 1}")
        steps = np.flatnonzero(tr["tamped"][:, s])
        # a tamping happens at the start of step k, i.e. at year k / steps_per_year
        ax1.plot(steps / cfg.steps_per_year, tr["section_sd_mm"][steps, s], "v", color=color, ms=7)
    ax1.axhline(lim.sd_alert_m * 1e3, color="k", ls="--", lw=1, label="SD alert limit")
    ax1.set_ylabel("section SD of D1 level [mm]")
    ax1.legend(fontsize=7, ncol=2)
    label = " ".join(x for x in (policy_name(policy), _fmt_params(policy_params(policy))) if x != "-")
    ax1.set_title(f"{label}, seed {seed} "
                  f"(▼ tamping); total {tr['cost'].sum():.1f} k€")
    ax2.bar(tr["year"] - 0.5 / cfg.steps_per_year, tr["cost"], width=0.8 / cfg.steps_per_year, color="C3")
    ax2.set_xlabel("year")
    ax2.set_ylabel("cost per step [k€]")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_png, dpi=120)
    return out_png
