"""The leaderboard: every policy on every scenario of the suite, on fixed held-out seeds, scored against the best
tuned rule and the per-section hindsight bound (``trackenv leaderboard``).

Per scenario (an env id of the suite, :data:`DEFAULT_SUITE`) and policy (the tuned rules, the shipped agent
``cpi-agent``, trained policies given by path: the baselines of the standard libraries,
:mod:`trackenv_agents.learning.baselines`, each on the line it was trained on) the harness runs one episode per
held-out seed (:func:`~.harness.evaluate_many`, the same seeds for every policy: common random numbers) and
reports the mean cost with its 95 % CI, the paired difference to the best tuned rule, the immediate-action count
and the tampings per section class (:func:`~.line_compare.class_breakdown`).

**The network** (``trackenv/TampingNetwork-v0``: lines that share one tamping machine) is scored with the policies
of its line, each run on every line by :class:`~trackenv_agents.rules.network.NetworkRule` (which keeps the machine
on its line while the line policy asks for work there): the tuned rules of the network's line, each with that
line's tuned parameters, and the agents that fit that line, dispatched by :data:`NETWORK_DISPATCH` and named
after it (``network-by-value(<policy>)``); a trained line agent plays eager where the machine stays
(:func:`~trackenv_agents.rules.network.eager_for`: ``network-by-value(<agent>, eager 0.15)``).

**The normalised score** is the share of the gap from the best tuned rule to the hindsight bound that a policy
closes, paired per episode e::

    score = Σ_e (rule_e − policy_e) / Σ_e (rule_e − bound_e)

0 is the rule, 1 is clairvoyance (the bound's cost), below 0 worse than the rule; above 1 is possible, since the
bound is a search (:mod:`.line_hindsight`), not the proven optimum. It is a ratio of paired means, not a mean of
per-episode ratios: an episode where the rule is already near the bound has a gap near zero, and its ratio would
swing the mean without bound. Its 95 % CI is a percentile bootstrap over episodes (the same episodes resampled in
numerator and denominator, its own seeded generator). The best tuned rule is the rule with the lowest mean cost on
the held-out seeds themselves: the score's zero is the strongest rule the suite has on these episodes.

**The bound** is :func:`~.line_hindsight.hindsight_bounds` per episode, from the best rule's schedule with every
scored rule's schedule as a candidate (:data:`BOUND_SEARCH`), never above the best rule's own cost (its schedule is
always a candidate). Where sections share a segment (the 60 m track) it is the whole-line search
(:mod:`.line_hindsight_whole`). The per-section search needs no annual budget and no machine shared between
lines: on the hard line (an annual budget) and on the network (one machine for three lines) the score is null, and
the bound entry says why. A search costs seconds per episode, so each episode's bound is kept
under ``DIR/bounds/`` keyed by (scenario, seed, a hash of the config and the search settings), and the saved
searches of ``experiments/searches/`` are reused for the seeds they cover once their schedules replay, in the env
as it is now, at the cost they were saved with.
"""

from __future__ import annotations

import functools
import hashlib
import json
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from trackenv.envs.network import NetworkConfig

from ..rules.network import NETWORK_DISPATCH
from .harness import EvaluationResult, add_note, as_policy, evaluate_many
from .line_compare import (
    ENGINE_FIELDS,
    SECTION_CLASSES,
    changes_note,
    class_breakdown,
    config_changes,
    engine_note,
    env_config,
    line_of,
    parse_seeds,
    policy_label,
    repeated,
    scenario_of,
)
from .reporting import ci_text, count_text
from .statistics import N_BOOTSTRAP, bootstrap_ci, paired_difference

__all__ = ["BOUND_SEARCH", "CHOICE_SEARCH", "DEFAULT_SEEDS", "DEFAULT_SUITE", "EVERY_TUNED_RULE", "NETWORK_DISPATCH",
           "NO_SUCH_RULE", "SAVED_SEARCHES", "bound_unavailable", "episode_bounds", "fitting_agents",
           "format_leaderboard", "normalised_score", "on_network", "policy_label", "run_leaderboard", "scored_rules"]

#: The scenarios of the default leaderboard: the three lines, the 60 m track, the three lines with every
#: choice (the default line, the wet line, the line of short defects) and the network of three default lines.
DEFAULT_SUITE: tuple[str, ...] = ("trackenv/TampingLineSmall-v0", "trackenv/TampingLine-v0",
                                  "trackenv/TampingLineHard-v0", "trackenv/Tamping-v1", "trackenv/TampingLine-v1",
                                  "trackenv/TampingLineWet-v0", "trackenv/TampingLineDefects-v0",
                                  "trackenv/TampingNetwork-v0")

#: The default held-out seeds per scenario (none of them a training or tuning seed, which start at 1000): as many
#: as the whole default command scores in about a quarter of an hour on 2 cores (an episode of the hard line costs
#: six of the 60 m track; a new bound search about 7 s per episode of the small line). The default line's seeds
#: are among those whose hindsight searches ship in ``experiments/searches/`` (0-99).
DEFAULT_SEEDS: dict[str, tuple[int, ...]] = {
    "trackenv/TampingLineSmall-v0": tuple(range(0, 16)),
    "trackenv/TampingLine-v0": tuple(range(0, 32)),
    "trackenv/TampingLineHard-v0": tuple(range(0, 12)),
    "trackenv/Tamping-v1": tuple(range(0, 48)),
    # the ids with every choice: the episodes whose bounds ship (a search with the choices costs about a minute an
    # episode on a quiet machine)
    "trackenv/TampingLine-v1": tuple(range(0, 16)),
    "trackenv/TampingLineWet-v0": tuple(range(0, 12)),
    "trackenv/TampingLineDefects-v0": tuple(range(0, 12)),
    # an episode of the network (three default lines) costs about 3.5 s a policy: with the five tuned rules and
    # the shipped agent, some 3 minutes
    "trackenv/TampingNetwork-v0": tuple(range(0, 8)),
}

#: The settings of the hindsight search behind the bound (:func:`~.line_hindsight.hindsight_bounds`): one round of
#: local search from the closed-loop candidates at true SD 2 and 3 mm, a few seconds per episode.
BOUND_SEARCH: dict[str, Any] = {"rounds": 1, "sd_thresholds_mm": (2.0, 3.0)}

#: The choices' candidates of the search on a config with choices besides tamping (the keyword arguments of
#: :func:`~.line_hindsight.choice_rules`): drainage of a wet section at the first step or at the spot's onset,
#: spot tamping from 60 % of the intervention limit, renewal from the fifth tamping since the last.
CHOICE_SEARCH: dict[str, Any] = {"drainage": ("first", "onset"), "spot_peak_fractions": (0.6,), "renew_counts": (5,)}

#: Episodes searched together (one batch of the search, one task under Ray).
BOUND_CHUNK = 8

#: The saved hindsight searches (``experiments/line_room.py`` results) reused for the seeds they cover.
SAVED_SEARCHES = Path(__file__).resolve().parents[2] / "experiments" / "searches"

#: The bound cache of the documented leaderboard (its ``--out experiments/saved/leaderboard``), read after the
#: output folder's own: the bounds of the same configs and search settings, and the schedules that a config whose
#: passes run otherwise than the presets' (``--engine fast``, pass reuse) replays.
SHIPPED_BOUNDS = Path(__file__).resolve().parents[2] / "experiments" / "saved" / "leaderboard" / "bounds"


def normalised_score(rule_cost: np.ndarray, policy_cost: np.ndarray, bound_cost: np.ndarray,
                     n_resamples: int = N_BOOTSTRAP, level: float = 0.95, seed: int = 0) -> dict[str, Any]:
    """The share of the rule-to-bound gap a policy closes, Σ(rule − policy) / Σ(rule − bound) over paired
    episodes (arrays aligned by episode), with its percentile bootstrap CI over episodes. ``score`` and ``ci`` are
    None where the bound closes no gap (Σ(rule − bound) <= 0: nothing to share)."""
    rule, pol, bound = (np.asarray(x, dtype=float) for x in (rule_cost, policy_cost, bound_cost))
    if not rule.shape == pol.shape == bound.shape or rule.ndim != 1 or rule.size == 0:
        raise ValueError(f"the costs must be three equal, non-empty 1-d arrays, got shapes {rule.shape}, "
                         f"{pol.shape}, {bound.shape}")
    gain, gap = rule - pol, rule - bound
    if gap.sum() <= 0:
        return {"score": None, "ci": None, "gap_mean": float(gap.mean())}
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, rule.size, size=(n_resamples, rule.size))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratios = gain[idx].sum(axis=1) / gap[idx].sum(axis=1)
    ratios = ratios[np.isfinite(ratios) & (gap[idx].sum(axis=1) > 0)]
    a = (1.0 - level) / 2
    ci = [float(v) for v in np.quantile(ratios, [a, 1.0 - a])] if ratios.size else None
    return {"score": float(gain.sum() / gap.sum()), "ci": ci, "gap_mean": float(gap.mean())}


def bound_unavailable(config: Any) -> str | None:
    """Why the hindsight bound cannot be computed for ``config`` (None where it can): the per-section search prices
    each section apart, which needs no annual budget and a machine of the line's own; where sections share a
    segment the whole-line search prices whole lines (:mod:`.line_hindsight_whole`)."""
    if isinstance(config, NetworkConfig):
        return (f"{config.n_lines} lines share one tamping machine (its line each step, its moves between lines): "
                "the per-section hindsight search prices each section apart, not the shared machine")
    if config.annual_budget > 0 and config.sections_per_segment == 1:
        return (f"an annual budget ({config.annual_budget:g} k€) couples the sections' schedules, which the "
                "per-section hindsight search prices apart")
    return None


def _with_choices(config: Any) -> bool:
    """Whether ``config`` enables choices besides tamping (the search then offers them)."""
    return tuple(getattr(config, "choices", ("tamp",))) != ("tamp",)


def _search_settings(config: Any) -> dict[str, Any]:
    """The search's keyword arguments for ``config``: :data:`BOUND_SEARCH`, and :data:`CHOICE_SEARCH` where it has
    choices besides tamping."""
    return {**BOUND_SEARCH, "choice_search": CHOICE_SEARCH} if _with_choices(config) else dict(BOUND_SEARCH)


def _config_key(config: Any, scenario_name: str) -> str:
    """A short hash of the config and the search settings: a cached bound is reused only for the same ones."""
    text = json.dumps({"config": config.to_dict(), "search": _search_settings(config)}, sort_keys=True, default=str)
    return f"{scenario_name}_{hashlib.sha256(text.encode()).hexdigest()[:12]}"


def _cache_path(config: Any, scenario_name: str, folder: Path) -> Path:
    """The bound cache of ``config`` under ``folder``: the file of its key (:func:`_config_key`), else a file of
    the scenario written with the same search settings for a config that, read by today's config class, is this
    one (a cache written before the config gained fields, at their defaults, stays valid), else the key's (new)
    file."""
    path = folder / f"{_config_key(config, scenario_name)}.json"
    if path.exists() or not folder.is_dir():
        return path
    settings = json.loads(json.dumps(_search_settings(config), default=str))
    for other in sorted(folder.glob(f"{scenario_name}_*.json")):
        saved = json.loads(other.read_text())
        if saved.get("search") != settings:
            continue
        try:
            if type(config).from_dict(saved["config"]) == config:
                return other
        except (ValueError, TypeError, KeyError):  # another config class or a field since removed: not this one
            continue
    return path


def _search_chunk(config: Any, episodes: list[tuple[int, np.ndarray, tuple]]) -> list[dict[str, Any]]:
    """One batch of the hindsight search (the unit an executor runs): per episode its seed, cost and schedule,
    and the seconds the batch took per episode."""
    from .line_hindsight import hindsight_bounds, schedule_rows

    t0 = time.perf_counter()
    found = hindsight_bounds(config, episodes, **_search_settings(config))
    per_episode = (time.perf_counter() - t0) / len(episodes)
    return [{"seed": int(h["seed"]), "cost": float(h["replayed_cost"]), "schedule": schedule_rows(h["schedule"]),
             "source": "search", "search_seconds": per_episode} for h in found]


def _saved_bounds(config: Any, scenario_name: str, seeds: list[int], searches: Path) -> dict[int, dict[str, Any]]:
    """The saved searches' schedules for ``seeds`` (files of ``scenario_name`` only) that still replay at the cost
    they were saved with; a search of another engine version is left out, not trusted."""
    from .line_hindsight import replay_schedules, saved_schedules, schedule_rows

    paths: list[str | Path] = [p for p in sorted(searches.glob("*.json"))
                               if json.loads(p.read_text()).get("scenario") == scenario_name]
    if not paths:
        return {}
    try:
        saved_seeds, plans, costs = saved_schedules(paths, config)
    except ValueError:  # another horizon or section count: not this config's
        return {}
    keep = [k for k, s in enumerate(saved_seeds) if s in set(seeds)]
    if not keep:
        return {}
    replayed = replay_schedules(config, [saved_seeds[k] for k in keep], [plans[k] for k in keep])
    return {saved_seeds[k]: {"seed": saved_seeds[k], "cost": float(c), "schedule": schedule_rows(plans[k]),
                             "source": "saved"}
            for k, c in zip(keep, replayed, strict=True) if abs(c - costs[k]) <= 1e-6 * abs(costs[k])}


def _cached_episodes(path: Path) -> dict[int, dict[str, Any]]:
    """The episodes of a bound cache file by seed ({} where there is no such file)."""
    if not path.exists():
        return {}
    return {int(k): v for k, v in json.loads(path.read_text())["episodes"].items()}


def _replayed_bounds(config: Any, scenario_name: str, seeds: list[int],
                     folders: Sequence[Path]) -> dict[int, dict[str, Any]]:
    """For a config whose passes run otherwise than the presets' (the fast engine, pass reuse): the bounds of the
    same line computed as the presets compute it (:func:`~..rules.problems.computed_as_presets`) found in the
    bound caches of ``folders`` (the first that has a seed), their schedules replayed under ``config`` (source
    "replayed"). A bound is the cost of a schedule a search found, not a proven optimum; a schedule found under
    the classic engine and replayed under this one is such a schedule, at a fraction of a new search's cost
    (a minute an episode on the lines with every choice). {} for a config computed as the presets'."""
    from ..rules.problems import computed_as_presets
    from .line_hindsight import replay_schedules, schedule_from_rows

    twin = computed_as_presets(config) if hasattr(config, "engine") else config
    if twin == config:
        return {}
    rows: dict[int, list] = {}
    for folder in folders:
        episodes = _cached_episodes(_cache_path(twin, scenario_name, Path(folder)))
        rows.update({s: episodes[s]["schedule"] for s in seeds if s not in rows and s in episodes})
    if not rows:
        return {}
    have = sorted(rows)
    costs = replay_schedules(config, have, [schedule_from_rows(rows[s]) for s in have])
    return {s: {"seed": s, "cost": float(c), "schedule": rows[s], "source": "replayed"}
            for s, c in zip(have, costs, strict=True)}


def episode_bounds(config: Any, scenario_name: str, rules: Sequence[EvaluationResult], cache_dir: str | Path,
                   executor: Any = None, searches: Path | None = SAVED_SEARCHES,
                   shipped: Path | None = SHIPPED_BOUNDS) -> dict[str, Any]:
    """The hindsight bound of each episode of ``rules`` (the scored rules' results on common seeds, the best
    first): from the cache under ``cache_dir`` or, for the same config and search settings, under ``shipped``
    (the committed one), else a saved search that replays (``searches``), else, for a config whose passes run
    otherwise than the presets', the presets' bound replayed (:func:`_replayed_bounds`, from the cache under
    ``cache_dir`` or ``shipped``), else a new search (:data:`BOUND_SEARCH`, from the best
    rule's schedule with the others' as candidates, :data:`BOUND_CHUNK` episodes a batch, through ``executor.map``
    if given). Each bound is capped at the best rule's own cost. Returns {"cost" (per seed, in ``rules[0].seeds``
    order), "sources" (counts), "search_seconds_per_episode" (the new searches' mean, None if none ran)}."""
    best = rules[0]
    seeds = [int(s) for s in best.seeds]
    path = _cache_path(config, scenario_name, Path(cache_dir))
    cached = _cached_episodes(path)
    committed = {} if shipped is None else _cached_episodes(_cache_path(config, scenario_name, shipped))
    known = {**committed, **cached}  # the output folder's own first (the same file where it is the committed one)
    found = {s: {**known[s], "source": "cache"} for s in seeds if s in known}
    if searches is not None and searches.is_dir():
        todo = [s for s in seeds if s not in found]
        found.update(_saved_bounds(config, scenario_name, todo, searches) if todo else {})
    todo = [s for s in seeds if s not in found]
    if todo:
        folders = [Path(cache_dir)] + ([shipped] if shipped is not None else [])
        found.update(_replayed_bounds(config, scenario_name, todo, folders))
    todo = [s for s in seeds if s not in found]
    seconds: list[float] = []
    if todo:
        if any(r.tamped is None and r.section_choices is None for r in rules):
            raise ValueError("the bound's search starts from the rules' schedules: results without them (tamped)")
        # (episodes, H, S) each, the best rule's first: the choices the rules made (their tampings where a result
        # has no codes)
        plans = [np.asarray(r.section_choices if r.section_choices is not None else r.tamped) for r in rules]
        row = {s: k for k, s in enumerate(seeds)}
        episodes = [(s, plans[0][row[s]], tuple(p[row[s]] for p in plans[1:])) for s in todo]
        chunks = [episodes[i:i + BOUND_CHUNK] for i in range(0, len(episodes), BOUND_CHUNK)]
        run: Callable = functools.partial(_search_chunk, config)
        for out in (executor.map(run, chunks) if executor is not None else map(run, chunks)):
            for h in out:
                seconds.append(h.pop("search_seconds"))
                found[h["seed"]] = h
    if todo or any(v["source"] in ("saved", "replayed") for v in found.values()):
        path.parent.mkdir(parents=True, exist_ok=True)
        keep = {**cached, **{s: {k: v for k, v in found[s].items() if k != "source"} for s in seeds}}
        path.write_text(json.dumps({"scenario": scenario_name, "config": config.to_dict(),
                                    "search": _search_settings(config),
                                    "episodes": {str(s): keep[s] for s in sorted(keep)}}, default=str) + "\n")
    cost = np.minimum([found[s]["cost"] for s in seeds], best.cost)
    sources = {k: sum(found[s]["source"] == k for s in seeds) for k in ("cache", "saved", "replayed", "search")}
    return {"cost": cost, "sources": sources,
            "search_seconds_per_episode": float(np.mean(seconds)) if seconds else None}


#: why a rule named in ``rules`` is not scored on a scenario whose family has no such rule (:func:`scored_rules`)
NO_SUCH_RULE = "no such rule on this scenario"

#: the name in ``rules`` of every tuned rule of each scenario (``--policies rules``; ``rules=None`` is it alone)
EVERY_TUNED_RULE = "rules"


def scored_rules(env_id: str, line: Any, rules: Sequence[str] | None) -> tuple[list[str], dict[str, str]]:
    """The rules scored on ``env_id`` (whose line config is ``line``): those of ``rules`` in its family
    (:func:`~trackenv_agents.rules.problems.rules_for`: the rules of the choices apply only where a config enables
    them; :data:`EVERY_TUNED_RULE` or None: its tuned rules); and each rule named there of another family with why
    it is not scored there (:data:`NO_SUCH_RULE`), as an agent that does not fit is listed. A scenario where none of
    ``rules`` applies is refused, naming it: the normalised score's zero is the best rule scored there."""
    from ..rules.problems import rules_for, tuned_params_for

    family = sorted(rules_for(line))
    named = list(rules) if rules is not None else [EVERY_TUNED_RULE]
    tuned = list(tuned_params_for(line))
    wanted = list(dict.fromkeys(n for name in named for n in (tuned if name == EVERY_TUNED_RULE else [name])
                                if n in family))
    if not wanted:
        raise ValueError(f"rules must name some of {env_id}'s rules {family}, got {named}")
    why = f"{NO_SUCH_RULE}: its rules are {', '.join(family)}"
    return wanted, {n: why for n in named if n != EVERY_TUNED_RULE and n not in family}


def fitting_agents(agents: dict[str, Any], config: Any) -> tuple[dict[str, Any], dict[str, str]]:
    """The ``agents`` that can be scored on ``config``, and why each other one cannot: a policy with
    ``unfit_for(config)`` (a baseline that sees the observation of the line it was trained on,
    :class:`~trackenv_agents.learning.baselines.TrainedPolicy`) is scored where that returns None only. On a
    network the question is asked of its line (each agent runs on every line, :func:`on_network`)."""
    line = line_of(config)
    here: dict[str, Any] = {}
    unfit: dict[str, str] = {}
    for label, agent in agents.items():
        check = getattr(agent, "unfit_for", None)
        reason = check(line) if callable(check) else None
        if reason is None:
            here[label] = agent
        else:
            unfit[label] = reason
    return here, unfit


def on_network(policy: Any, config: Any, dispatch: str = NETWORK_DISPATCH) -> Any:
    """``policy`` as it plays ``config``: on a network, a line policy run on every line by a
    :class:`~trackenv_agents.rules.network.NetworkRule` of ``dispatch`` (a trained line agent eager where the
    machine stays: :func:`~trackenv_agents.rules.network.eager_for`); on a line, itself."""
    from ..rules.network import network_play

    return network_play(policy, dispatch) if isinstance(config, NetworkConfig) else policy


def _row(env_id: str, result: EvaluationResult, best: EvaluationResult, bound: np.ndarray | None) -> dict[str, Any]:
    """One leaderboard row: ``result`` against the best rule ``best`` and, where there is one, the bound."""
    lo, hi = bootstrap_ci(result.cost)
    diff = paired_difference(result, best)
    score = normalised_score(best.cost, result.cost, bound) if bound is not None else None
    classes = class_breakdown(result)
    return {"env": env_id, "policy": result.policy, "params": dict(result.params), "n_episodes": result.n_episodes,
            "mean_cost": float(result.cost.mean()), "ci": [lo, hi],
            "vs_best_rule": {k: diff[k] for k in ("mean_difference", "ci_low", "ci_high")},
            "relative_to_best_rule": diff["mean_difference"] / float(best.cost.mean()),
            "normalised_score": None if score is None else score["score"],
            "normalised_score_ci": None if score is None else score["ci"],
            "immediate_action": int(result.immediate_action_exceedances.sum()),
            "interventions_per_class": {c: classes[c]["tampings_per_section"] for c in SECTION_CLASSES},
            "sections_per_class": {c: classes[c]["sections_per_episode"] for c in SECTION_CLASSES},
            "campaigns_per_episode": classes["line"]["campaigns_per_episode"],
            "tampings_per_km_year": float(result.tampings_per_km_year.mean()),
            "episodes_beyond_validity": result.episodes_beyond_validity,
            "episode_costs": result.cost.tolist()}


def run_leaderboard(envs: Sequence[str] = DEFAULT_SUITE, rules: Sequence[str] | None = None,
                    agents: dict[str, Any] | None = None, seeds: Sequence[int] | None = None, bound: bool = True,
                    out_dir: str | Path = "results/leaderboard", executor: Any = None, batch_size: int = 32,
                    progress: bool = False, searches: Path | None = SAVED_SEARCHES,
                    shipped_bounds: Path | None = SHIPPED_BOUNDS, write: bool = True,
                    **overrides: Any) -> dict[str, Any]:
    """Score ``rules`` (names of the rule family, with each preset's shipped tuned parameters; on each scenario
    those of its family, :func:`scored_rules`; default, or :data:`EVERY_TUNED_RULE` among them, all tuned rules) and
    ``agents`` (name -> a policy with SB3's ``predict``, or a function of the batched observation returning the
    actions) on every scenario of ``envs``, on ``seeds`` (default
    :data:`DEFAULT_SEEDS` of each), and the bound where it applies (``bound``; saved searches read from
    ``searches``, the committed bound cache from ``shipped_bounds``; None: none). ``overrides`` change every
    scenario's config (e.g. a short ``horizon_years`` for tests, or the engine's options). An agent that does not
    fit a scenario (:func:`fitting_agents`) is left out there. The payload of the module docstring: "results" (one
    row per scenario and policy, the best rule first, then by mean cost), "bound" (per scenario), "seeds",
    "best_rule" (per scenario), "not_scored" (per scenario, the agents left out and the named rules of another
    family, :func:`scored_rules`, and why), "config_overrides",
    "wall_time_s", and with ``write`` (default) "files": ``leaderboard.json`` and the page ``leaderboard.md``
    (:func:`format_leaderboard`) written into ``out_dir``, which also keeps the bound's cache (``bounds/``), as
    ``trackenv leaderboard --out`` does. ``envs``: ids (one id alone is taken as a list of one); ``seeds``: whole
    numbers or an ``"A:B"`` text."""
    from ..rules.problems import every_rule, tuned_rule

    t0 = time.perf_counter()
    envs = [envs] if isinstance(envs, str) else list(envs)
    if isinstance(seeds, str):
        seeds = parse_seeds(seeds)
    elif seeds is not None and not isinstance(seeds, Iterable):
        raise ValueError(f"seeds must be whole numbers (e.g. range(16), [0, 1]) or 'A:B', got {seeds!r}")

    twice = repeated(envs)
    if twice:
        raise ValueError(f"envs name {', '.join(twice)} more than once: each scenario is scored once")
    unknown = [n for n in rules or () if n not in every_rule() and n != EVERY_TUNED_RULE]
    if unknown:
        raise ValueError(f"rules must be among {sorted(every_rule())}, got unknown {unknown}")
    names = {env_id: scenario_of(env_id) for env_id in envs}
    configs = {env_id: env_config(env_id, **overrides) for env_id in envs}
    lines = {env_id: line_of(cfg) for env_id, cfg in configs.items()}
    scored = {env_id: scored_rules(env_id, line, rules) for env_id, line in lines.items()}
    payload: dict[str, Any] = {"results": [], "bound": {}, "seeds": {}, "best_rule": {},
                               "config_overrides": dict(overrides)}
    if agents is not None and not isinstance(agents, Mapping):
        raise ValueError(f"agents must be a dict of name -> policy, got {type(agents).__name__}")
    agents = {label: as_policy(agent, label) for label, agent in (agents or {}).items()}
    for env_id in envs:  # a policy named as a rule scored there would take the rule's row: before anything runs
        taken = [label for label in agents
                 if policy_label(label, configs[env_id], policy=agents[label]) in scored[env_id][0]]
        if taken:
            raise ValueError(f"agents name {', '.join(taken)} as a rule scored on {env_id}: give each policy a name "
                             "of its own")
    for env_id in envs:
        name, cfg, line, (wanted, no_such) = names[env_id], configs[env_id], lines[env_id], scored[env_id]
        here, unfit = fitting_agents(agents, cfg)
        pols = [on_network(p, cfg) for p in [tuned_rule(line, n) for n in wanted] + list(here.values())]
        env_seeds = [int(s) for s in (seeds if seeds is not None else DEFAULT_SEEDS.get(env_id, range(16)))]
        try:
            results = evaluate_many(pols, cfg, env_seeds, batch_size=batch_size, progress=progress, desc=name,
                                    executor=executor)
        except Exception as error:  # which scenario, and which agents played there (a policy's error names it)
            add_note(error, f"while scoring {env_id} (the rules {', '.join(wanted)} and the agents "
                           f"{', '.join(here) or 'none'}); a policy that cannot play a scenario says so in "
                           "unfit_for(config), and is left out there")
            raise
        for r, label in zip(results[len(wanted):], here, strict=True):
            r.policy = policy_label(label, cfg, policy=here[label])
        rule_results = sorted(results[:len(wanted)], key=lambda r: float(r.cost.mean()))
        best = rule_results[0]
        reason = None if bound else "not computed (--no-bound)"
        reason = reason or bound_unavailable(cfg)
        bound_cost = None
        entry: dict[str, Any] = {"available": reason is None, "reason": reason}
        if reason is None:
            t0 = time.perf_counter()
            b = episode_bounds(cfg, name, rule_results, Path(out_dir) / "bounds", executor, searches,
                               shipped_bounds)
            bound_cost = b["cost"]
            lo, hi = bootstrap_ci(bound_cost)
            gap = paired_difference(_as_result(best, bound_cost, "bound"), best)
            entry.update({"mean_cost": float(bound_cost.mean()), "ci": [lo, hi],
                          "vs_best_rule": {k: gap[k] for k in ("mean_difference", "ci_low", "ci_high")},
                          "sources": b["sources"], "search_seconds_per_episode": b["search_seconds_per_episode"],
                          "seconds": time.perf_counter() - t0, "search": _search_settings(cfg),
                          "episode_costs": bound_cost.tolist()})
        others = sorted((r for r in results if r not in rule_results), key=lambda r: float(r.cost.mean()))
        ordered = sorted([*rule_results, *others], key=lambda r: (r is not best, float(r.cost.mean())))
        payload["results"] += [_row(env_id, r, best, bound_cost) for r in ordered]
        payload["bound"][env_id] = entry
        payload["seeds"][env_id] = env_seeds
        payload["best_rule"][env_id] = best.policy
        payload.setdefault("not_scored", {})[env_id] = {**no_such, **unfit}
        payload.setdefault("scenarios", {})[env_id] = name
        payload.setdefault("config_changes", {})[env_id] = config_changes(env_id, cfg)
    payload["wall_time_s"] = time.perf_counter() - t0
    if write:
        payload["files"] = write_leaderboard(payload, out_dir)
    return payload


def write_leaderboard(payload: dict[str, Any], out_dir: str | Path) -> list[str]:
    """Write ``payload`` (:func:`run_leaderboard`'s) as ``leaderboard.json`` and its page ``leaderboard.md``
    (:func:`format_leaderboard`) into ``out_dir`` (made if missing); returns the two paths."""
    from trackenv._json import json_default

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = [out / "leaderboard.json", out / "leaderboard.md"]
    body = {k: v for k, v in payload.items() if k != "files"}
    files[0].write_text(json.dumps({**body, "files": [str(f) for f in files]}, indent=1, default=json_default)
                        + "\n")
    files[1].write_text(format_leaderboard(payload))
    return [str(f) for f in files]


def _as_result(like: EvaluationResult, cost: np.ndarray, name: str) -> EvaluationResult:
    """An :class:`EvaluationResult` of per-episode costs only (on ``like``'s seeds), for paired differences."""
    return EvaluationResult(policy=name, params={}, config=like.config, seeds=like.seeds, cost=np.asarray(cost),
                            cost_parts={}, section_tampings=np.zeros_like(cost),
                            immediate_action_exceedances=np.zeros_like(cost), final_mean_sd_mm=np.zeros_like(cost),
                            sum_rewards=-np.asarray(cost))


def _seed_text(seeds: Sequence[int]) -> str:
    s = list(seeds)
    return f"{s[0]}–{s[-1]}" if s == list(range(s[0], s[0] + len(s))) and len(s) > 1 else ", ".join(map(str, s))


#: how the tables say why a policy is not scored on a scenario, by the head of its ``unfit_for`` reason
_UNFIT_HEADS = {"trained on another line": "each sees the observation of the line it was trained on"}


def format_leaderboard(payload: dict[str, Any]) -> str:
    """The leaderboard as Markdown: per scenario a table of its policies (the best rule first), the bound's line,
    and the command that wrote it."""
    out = []
    overrides = payload.get("config_overrides") or {}
    note = engine_note({k: overrides[k] for k in ENGINE_FIELDS if k in overrides})
    if note:
        out += [f"Passes computed otherwise than the presets' ({note[2:]}): costs differ from the classic engine's "
                "by about a tenth of a percent; a bound marked *replayed* is the schedule the classic engine's "
                "search found, replayed under these options.", ""]
    short = {"plain": "plain", "transition": "trans.", "switch_or_crossing": "switch", "hidden_wet_spot": "wet"}
    for env_id, seeds in payload["seeds"].items():
        rows = [r for r in payload["results"] if r["env"] == env_id]
        b = payload["bound"][env_id]
        changed = changes_note((payload.get("config_changes") or {}).get(env_id) or {})
        n = len(seeds)
        out += [f"### {env_id}", "",
                f"{count_text(n, 'held-out episode')} (seeds {_seed_text(seeds)}); best tuned rule: "
                f"{payload['best_rule'][env_id]}{changed}.", "",
                "| policy | mean cost, k€ [95 % CI] | vs best rule, k€ (paired) [95 % CI] | normalised score [95 % CI] "
                "| IA | tampings per section: " + " / ".join(short.values()) + " |",
                "|---|---|---|---|---|---|"]
        for r in rows:
            d = r["vs_best_rule"]
            vs = "—" if r["policy"] == payload["best_rule"][env_id] else (
                f"{d['mean_difference']:+.1f} {ci_text(d['ci_low'], d['ci_high'], n, signed=True)} "
                f"({100 * r['relative_to_best_rule']:+.1f} %)")
            sc = "n/a" if r["normalised_score"] is None else f"{r['normalised_score']:.2f}"
            if r["normalised_score_ci"] and n >= 2:
                sc += " " + ci_text(r["normalised_score_ci"][0], r["normalised_score_ci"][1], n, digits=2)
            per = " / ".join("–" if r["interventions_per_class"][c] is None else
                             f"{r['interventions_per_class'][c]:.2f}" for c in short)
            out.append(f"| {r['policy']} | {r['mean_cost']:.1f} {ci_text(r['ci'][0], r['ci'][1], n)} | {vs} | {sc} | "
                       f"{r['immediate_action']} | {per} |")
        if b["available"]:
            d = b["vs_best_rule"]
            src = ", ".join(f"{n} {k}" for k, n in b["sources"].items() if n)
            out += ["", f"Hindsight bound: {b['mean_cost']:.1f} k€ {ci_text(b['ci'][0], b['ci'][1], n)}, "
                        f"{d['mean_difference']:+.1f} k€ {ci_text(d['ci_low'], d['ci_high'], n, signed=True)} "
                        "against the best rule "
                        f"(episodes: {src})."]
        else:
            out += ["", f"No normalised score: {b['reason']}."]
        beyond = [f"{r['policy']} ({r['episodes_beyond_validity']} of {r['n_episodes']})" for r in rows
                  if r.get("episodes_beyond_validity")]
        if beyond:
            out += ["", "**Beyond the model's validity** (a section's settlement ran away) in some episodes of "
                    + ", ".join(beyond) + ": their costs from there on are not physical."]
        unfit = payload.get("not_scored", {}).get(env_id) or {}
        by_reason: dict[str, list[str]] = {}
        for name, why in sorted(unfit.items()):  # grouped by the reason's head, the text before its colon
            head = why.split(":")[0]
            by_reason.setdefault(_UNFIT_HEADS.get(head, head), []).append(name)
        for head, names in sorted(by_reason.items()):
            out += ["", f"Not scored here ({head}): " + ", ".join(names) + "."]
        out.append("")
    out += ["IA: section-steps at the immediate-action limit, all episodes together. Normalised score: "
            "Σ(rule − policy) / Σ(rule − bound) over the paired episodes (0 = the best tuned rule, 1 = the "
            "hindsight bound).", ""]
    if payload.get("command"):
        out += [f"Written by `{payload['command']}`."]
    return "\n".join(out) + "\n"
