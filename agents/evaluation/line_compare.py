"""`trackenv evaluate --env trackenv/TampingLine-v0` and `trackenv calibrate`: the line's comparison and
calibration, written as JSON and PNG (the logic of the env and the calibration lives in the library)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from trackenv.envs.line_config import LINE_FILE_FIELDS, LineConfig, scenario
from trackenv.envs.network import NetworkConfig

from ..rules.line import LINE_HEURISTICS
from ..rules.network import NETWORK_DISPATCH, network_play
from ..rules.problems import rules_for, tuned_file_for, tuned_params_for
from .harness import (
    CHOICE_NAMES,
    MACHINE_STEPS,
    _predict,
    as_policy,
    bind_policy,
    distinct_names,
    evaluate_many,
    machine_activity,
    policy_name,
    takes_action_masks,
)
from .reporting import ci_text, count_text, plot_comparison
from .statistics import bootstrap_ci, paired_difference
from .tuning import tune_many


def scenario_of(env_id: str) -> str:
    """The preset registered for an id of the one environment with the MultiBinary action (the TampingLine
    ids, ``trackenv/Tamping-v1``: the 60 m track, ``"track60"``, and the network ``trackenv/TampingNetwork-v0``:
    ``"network"``)."""
    import gymnasium as gym

    import trackenv  # noqa: F401

    refusal = file_as_env_refusal(env_id)
    if refusal is not None:
        raise ValueError(refusal)
    try:
        spec = gym.spec(env_id)
    except gym.error.Error as exc:  # an unknown name or version: the user's input, not a crash
        hint = f"; did you mean 'trackenv/{env_id}'?" if f"trackenv/{env_id}" in gym.registry else ""
        raise ValueError(f"{env_id!r} is not a registered env id ({exc}){hint}") from None
    entry, kwargs = str(spec.entry_point), dict(spec.kwargs)
    if entry.endswith(":TampingNetwork"):
        return "network"
    if entry.endswith(":TampingEnv") and kwargs.get("action_type", "multibinary") == "multibinary":
        return "track60"
    if not entry.endswith(":TampingLine"):
        raise ValueError(f"{env_id} is not an id of a preset with per-section actions (the TampingLine ids, "
                         "trackenv/Tamping-v1, trackenv/TampingNetwork-v0)")
    return kwargs["scenario"]


#: what to do with a network of lines of their own, which the comparisons do not score (:func:`line_of`)
NETWORK_ROUTES = ("plan it with trackenv plan {path}, compare policies on its futures with trackenv plan {path} "
                  "--compare A,B, or play NetworkRule(...).bind(config) on it in Python")


def file_as_env_refusal(env_id: str) -> str | None:
    """What to give instead where ``env_id`` is the path of a line or network file (a YAML file that exists):
    an env id is a registered name, and a line file is a field of a line's config (``--set line=PATH``); None
    for anything else (an id, or a name that is no file, which Gymnasium then refuses)."""
    from trackenv.envs.network_file import is_network_file

    path = Path(env_id)
    if path.suffix.lower() not in (".yaml", ".yml") or not path.is_file():
        return None
    if is_network_file(path):
        return (f"{env_id!r} is a network file, not an env id: a network of lines of their own is not scored by "
                f"evaluate or the leaderboard (their rules are tuned per preset); "
                f"{NETWORK_ROUTES.format(path=env_id)}; train a line's policy on one of its lines with --env "
                f"trackenv/TampingLine-v0 --set line=LINE.yaml")
    return (f"{env_id!r} is a line file, not an env id: give --env trackenv/TampingLine-v0 --set line={env_id} "
            f"(or plan the line with trackenv plan {env_id})")


def env_config(env_id: str, **overrides: Any) -> LineConfig | NetworkConfig:
    """The config ``gym.make(env_id, **overrides)`` runs: the id's preset with the id's own registered arguments
    (an id registered with ``gym.register`` over a preset keeps its changes) and ``overrides`` (fields of the line
    config, and on the network its own fields; an unknown one is the env's ValueError naming the known ones)."""
    import gymnasium as gym

    scenario_of(env_id)  # a clear error for an id that is no preset with per-section actions
    env = gym.make(env_id, disable_env_checker=True, **overrides)
    try:
        config: LineConfig | NetworkConfig = env.unwrapped.config  # type: ignore[attr-defined]
        return config
    finally:
        env.close()


def action_type_of(env_id: str) -> str:
    """The action type registered for ``env_id`` ("choices" on the ids with every choice, else "multibinary")."""
    import gymnasium as gym

    import trackenv  # noqa: F401

    scenario_of(env_id)  # a clear error for an id that is no preset with per-section actions
    return str(gym.spec(env_id).kwargs.get("action_type", "multibinary"))


#: The most episodes ``--seeds`` may give (:func:`parse_seeds`): 100 000 episodes of the small line take days on
#: 2 cores, and a range of billions would fill the memory before anything runs.
MAX_EPISODES = 100_000

#: The largest seed :func:`parse_seeds` takes: the harness keeps the seeds in a numpy int64 array.
MAX_SEED = 2**63 - 1


def parse_seeds(text: str) -> list[int]:
    """'A:B' -> A..B-1; 'a,b,c' -> those. Whole numbers in [0, :data:`MAX_SEED`] (Gymnasium's seeds are >= 0), at
    least one and at most :data:`MAX_EPISODES` (counted before the list is built), each once (an episode listed
    twice would count twice in the paired statistics); anything else is a ValueError naming ``--seeds``."""
    form = f"--seeds must be A:B with B > A, or a,b,c: whole numbers >= 0, each once; got {text!r}"
    parts = text.split(":") if ":" in text else [v for v in text.split(",") if v.strip()]
    try:
        values = [int(v) for v in parts]
    except ValueError:
        raise ValueError(form) from None
    if ":" in text and len(values) != 2:
        raise ValueError(form)
    if values and min(values) < 0:
        raise ValueError(f"--seeds must be whole numbers >= 0 (Gymnasium's seeds), got {text!r}")
    if values and max(values) > MAX_SEED + (":" in text):  # (B is one past the last seed)
        raise ValueError(f"--seeds must be at most {MAX_SEED} (the harness keeps seeds as int64), got {text!r}")
    if ":" in text and values[1] <= values[0]:
        raise ValueError(f"--seeds A:B needs B > A, got {text!r}")
    count = values[1] - values[0] if ":" in text else len(values)
    if count > MAX_EPISODES:
        raise ValueError(f"--seeds gives {count} episodes: at most {MAX_EPISODES} are allowed")
    if ":" in text:
        values = list(range(*values))
    if not values or len(set(values)) != len(values):
        raise ValueError(form)
    return values


def repeated(items: Sequence[str]) -> list[str]:
    """The items that ``items`` holds more than once, sorted: what a list of ids, policies or rules to score is
    refused for (each would be scored, or compared, twice)."""
    items = list(items)
    return sorted({x for x in items if items.count(x) > 1})


def policy_label(label: str, config: Any, dispatch: str = NETWORK_DISPATCH, policy: Any = None) -> str:
    """The name of the policy ``label`` (``policy`` itself where given) on ``config``'s rows: on a network the
    name of its :class:`~trackenv_agents.rules.network.NetworkRule` of ``dispatch`` (``network(<label>)`` by
    requests; a trained line agent's with its eager probability, as :func:`~..rules.network.network_play` plays it),
    else ``label``."""
    from ..rules.network import eager_for, network_label

    if not isinstance(config, NetworkConfig):
        return label
    return network_label(label, dispatch, None if policy is None else eager_for(policy))


def line_comparison(env_id: str = "trackenv/TampingLine-v0", seeds: list[int] | None = None,
                    rules: list[str] | None = None, n_train: int = 2, retune: bool = False, batch_size: int = 24,
                    progress: bool = True, out_dir: str = "results/line_compare", extra: dict[str, Any] | None = None,
                    executor: Any = None, **overrides: Any) -> dict[str, Any]:
    """Tuned line heuristics (shipped parameters, or tuned now on ``n_train`` training seeds 1000+) and the
    ``extra`` policies (name -> policy, e.g. the trained line policy; each row is named by its key, as
    :func:`~.leaderboard.run_leaderboard` names its ``agents``; on the network the key inside its NetworkRule's
    name, :func:`policy_label`; a key that names a scored rule is refused) scored on ``seeds`` (any sequence of
    whole numbers; default 0-7) with 95 % CIs, and the paired difference of each against the cheapest policy of
    the table (``vs_best``; the payload's ``best_rule`` names the cheapest rule, which :func:`agent_headline` pairs
    the agents with). ``rules``: the rule families to score (names of :data:`LINE_HEURISTICS`, and on the ids with
    every choice those of :data:`~trackenv_agents.rules.choices.CHOICE_RULES`; default all, no-maintenance
    included). ``executor``: runs the batches of episodes (e.g.
    :class:`~trackenv_agents.evaluation.distributed.RayExecutor`), with the same results as here."""
    name = scenario_of(env_id)
    network = name == "network"
    action_type = "multibinary" if network else action_type_of(env_id)
    cfg = env_config(env_id, **overrides)
    line_cfg = line_of(cfg)
    if network and retune:
        raise ValueError("--retune: the network's rules take the tuned parameters of its line (NetworkRule); "
                         "they are not tuned on the network")
    family = rules_for(line_cfg)
    unknown = sorted(set(rules or ()) - set(family))
    if unknown or (rules is not None and not rules):
        raise ValueError(f"rules must name line rules among {sorted(family)}, got {rules!r}")
    wanted = set(rules or family)
    classes = [c for n, c in family.items() if n != "no-maintenance" and n in wanted]
    params = {} if retune else {n: p for n, p in tuned_params_for(line_cfg).items() if n in wanted}
    tuned_from = (f"shipped (agents/rules/{tuned_file_for(line_cfg).name})" if params
                  else f"tuned now on {n_train} seeds")
    if not params and classes:
        t = tune_many(classes, line_cfg, list(range(1000, 1000 + n_train)), batch_size, progress, executor=executor,
                      action_type=action_type)
        params = {classes[i].name: v["best_params"] for i, v in t.items()}
    pols: list[Any] = [LINE_HEURISTICS["no-maintenance"]()] if "no-maintenance" in wanted else []
    pols += [family[n](**p) for n, p in params.items()]
    n_rules = len(pols)
    extra = {key: as_policy(p, key) for key, p in (extra or {}).items()}  # a plain function too
    pols += list(extra.values())
    if network:  # each line policy on every line, the one machine sent where the requests are
        pols = [network_play(p) for p in pols]
    rule_names = [policy_name(p) for p in pols[:n_rules]]
    labels = [policy_label(key, cfg, policy=p) for key, p in extra.items()]
    taken = [key for key, label in zip(extra, labels, strict=True) if label in rule_names]
    if taken:
        raise ValueError(f"extra names {', '.join(taken)} as a rule scored here: give each policy a name of its own")
    seeds = [int(s) for s in seeds] if seeds is not None and len(seeds) else list(range(8))  # any sequence
    res = evaluate_many(pols, cfg, seeds, action_type=action_type, batch_size=batch_size, progress=progress,
                        desc="test", executor=executor)
    for r, label in zip(res[n_rules:], labels, strict=True):  # (evaluate_many keeps the order of the policies)
        r.policy = label
    by_name = {r.policy: p for r, p in zip(res, pols, strict=True)}
    res.sort(key=lambda r: float(r.cost.mean()))
    best = res[0]
    rows = []
    for r in res:
        s = r.summary()
        s["vs_best"] = None if r is best else paired_difference(r, best)
        s["episode_costs"] = r.cost.tolist()  # in the order of "seeds": for paired analyses afterwards
        s["classes"] = class_breakdown(r)
        rows.append(s)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    best_rule = next((r.policy for r in res if r.policy in rule_names), None)
    payload = {"env": env_id, "scenario": name, "action_type": action_type, "config": cfg.to_dict(), "seeds": seeds,
               "config_changes": config_changes(env_id, cfg), "tuned_from": tuned_from,
               "best_rule": best_rule, "extra": labels, "results": rows}
    (out / "line_compare.json").write_text(json.dumps(payload, indent=1, default=float))
    payload["plot"] = plot_comparison(res, str(out / "line_compare.png"))
    # the best rule and the trained policy, side by side
    names = ([best_rule] if best_rule else []) + labels
    shown = [by_name[name] for name in names]
    payload["episode_plot"] = (plot_network_episode(shown, cfg, seeds[0], str(out / "network_episode.png"), names)
                               if isinstance(cfg, NetworkConfig) else
                               plot_line_episode(shown, line_cfg, seeds[0], str(out / "line_episode.png"), action_type,
                                                 names))
    return payload


#: The section classes of :func:`class_breakdown`: the register's three, and hidden wet spots (a section whose
#: wet spot started within the horizon, whatever its register; in no register, so no rule sees it coming)
SECTION_CLASSES = ("plain", "transition", "switch_or_crossing", "hidden_wet_spot")


def class_breakdown(result: Any) -> dict[str, dict[str, float | None]]:
    """Where a TampingLine policy's costs fall, per section class (:data:`SECTION_CLASSES`), from an
    :class:`~trackenv_agents.evaluation.harness.EvaluationResult` (its per-section costs, registers and wet spots):
    sections per episode, own cost (k€) and tampings per section and episode (None for a class with no section);
    and for the line, campaigns and possession (k€) per episode."""
    x = result.extra
    if "section_cost" not in x:
        raise ValueError("class_breakdown needs a TampingLine evaluation (per-section costs)")
    reg, wet, cost = np.asarray(x["register"]), np.asarray(x["wet_spot"], bool), np.asarray(x["section_cost"])
    tampings = np.asarray(result.tamped).sum(axis=1)  # (episodes, sections)
    cls = np.where(wet, 3, reg)
    n = len(cost)
    out: dict[str, dict[str, float | None]] = {}
    for k, name in enumerate(SECTION_CLASSES):
        m = cls == k
        out[name] = {"sections_per_episode": float(m.sum() / n),
                     "cost_per_section": float(cost[m].mean()) if m.any() else None,
                     "tampings_per_section": float(tampings[m].mean()) if m.any() else None}
    campaigns = np.asarray(result.tamped).any(axis=2).sum(axis=1)
    out["line"] = {"campaigns_per_episode": float(campaigns.mean()),
                   "possession_per_episode": float(np.mean(result.cost_parts["possession"]))}
    return out


def agent_headline(payload: dict[str, Any], name: str) -> str | None:
    """One line: the policy ``name`` against the best tuned rule, paired per episode (mean difference, its 95 %
    CI and the relative change), from each episode's costs in a :func:`line_comparison` payload (whichever policy
    is the best of the table); None where either row lacks them."""
    by = {r["policy"]: r for r in payload["results"]}
    rule = payload.get("best_rule")
    if name not in by or rule not in by or name == rule:
        return None
    if "episode_costs" not in by[name] or "episode_costs" not in by[rule]:
        return None
    d = np.asarray(by[name]["episode_costs"], dtype=float) - np.asarray(by[rule]["episode_costs"], dtype=float)
    diff, (low, high) = float(d.mean()), bootstrap_ci(d)
    pct = 100.0 * diff / by[rule]["mean_cost"]
    n = len(payload["seeds"])
    return (f"{name} vs the best tuned rule ({rule}), paired over {count_text(n, 'episode')}: {diff:+.1f} k€ "
            f"{ci_text(low, high, n, signed=True)} per episode, {pct:+.1f} %")


#: the column heads of the choice counts in :func:`format_line_table`
CHOICE_COLUMNS = {"tamp": "tamp", "spot_tamp": "spot", "drainage": "drain", "renew": "renew", "inspect": "insp",
                  "survey": "surv"}


#: The config fields of how the passes run (named by :func:`engine_note`, not among a table's changed fields).
ENGINE_FIELDS = ("engine", "pass_reuse_tolerance_m")


def without_engine(fields: dict[str, Any]) -> dict[str, Any]:
    """``fields`` but the engine's options (:data:`ENGINE_FIELDS`)."""
    return {k: v for k, v in fields.items() if k not in ENGINE_FIELDS}


def line_of(config: Any) -> LineConfig:
    """The line config a comparison plays: ``config`` itself, or a network's one line config; ValueError for a
    network of lines of their own, which the comparisons (tuned per preset) do not score."""
    if not isinstance(config, NetworkConfig):
        return config
    if config.mixed:
        raise ValueError("line_config: a network of lines of their own is not scored by evaluate or the leaderboard "
                         f"(their rules are tuned per preset); {NETWORK_ROUTES.format(path='NETWORK.yaml')}")
    return config.line_config


def engine_note(config: dict[str, Any]) -> str:
    """", engine fast, pass reuse 1 mm" for a config (its ``to_dict``; a network's line inside it) whose passes run
    otherwise than every preset's (the classic engine, every pass computed); "" for those."""
    line = config.get("line_config", config)
    notes = []
    if line.get("engine", "classic") != "classic":
        notes.append(f"engine {line['engine']}")
    if line.get("pass_reuse_tolerance_m", 0.0):
        notes.append(f"pass reuse {line['pass_reuse_tolerance_m'] * 1e3:g} mm")
    return "".join(f", {n}" for n in notes)


def config_changes(env_id: str, config: Any) -> dict[str, Any]:
    """The fields in which ``config`` differs from the registered ``env_id``'s own (:func:`env_config`), the
    engine's options left to :func:`engine_note` (a network's line fields prefixed ``line_config.``), as plain
    data: what a table must say it was scored on. A line file is named by its path, not by the fields it sets (the
    JSON's ``config`` holds the whole line)."""
    base, got = env_config(env_id).to_dict(), config.to_dict()
    out = {k: v for k, v in got.items() if k != "line_config" and v != base.get(k)}
    if "line_config" in got:
        out.update({f"line_config.{k}": v for k, v in got["line_config"].items()
                    if v != base["line_config"].get(k)})
    return line_named(config, {k: v for k, v in out.items() if k.rpartition(".")[2] not in ENGINE_FIELDS})


def line_named(config: Any, changes: dict[str, Any]) -> dict[str, Any]:
    """``changes`` (of :func:`config_changes`) with the line of ``config`` (or of its network) named by its
    :attr:`~trackenv.envs.line_file.LineDescription.label` and without the fields its file sets: the whole line
    and its sections' values would fill a table's header."""
    line = getattr(getattr(config, "line_config", config), "line", None)  # (a network of lines of their own: none)
    if line is None:
        return changes
    return {k: line.label if k.rpartition(".")[2] == "line" else v for k, v in changes.items()
            if k.rpartition(".")[2] not in LINE_FILE_FIELDS}


def changes_note(changes: dict[str, Any]) -> str:
    """"; changed: annual_mgt=30, horizon_years=2" for :func:`config_changes`, "" for none."""
    return "; changed: " + ", ".join(f"{k}={v}" for k, v in changes.items()) if changes else ""


def format_line_table(payload: dict[str, Any]) -> str:
    w = max([27] + [len(r["policy"]) for r in payload["results"]])  # the network's names are longer
    n = len(payload["seeds"])
    lines = [f"{payload['env']} ({payload['scenario']}), {count_text(n, 'held-out episode')}, parameters "
             f"{payload['tuned_from']}{engine_note(payload.get('config', {}))}"
             f"{changes_note(payload.get('config_changes') or {})}",
             f"{'policy':{w}s} {'cost k€':>8s} {'95% CI':>16s} {'vs cheapest (paired, 95% CI)':>30s} "
             f"{'IA':>4s} " + " ".join(f"{CHOICE_COLUMNS[c]:>5s}" for c in CHOICE_NAMES) + "  params"]
    for r in payload["results"]:
        d = r["vs_best"]
        diff = "-" if d is None else f"{d['mean_difference']:+.1f} {ci_text(d['ci_low'], d['ci_high'], n, True)}"
        ps = ", ".join(f"{k}={v}" for k, v in r["params"].items() if k not in
                       ("steps_per_year", "horizon_steps", "capacity"))
        counts = r.get("choices", {})
        lines.append(f"{r['policy']:{w}s} {r['mean_cost']:8.1f} {ci_text(r['ci_low'], r['ci_high'], n):>16s} "
                     f"{diff:>30s} {r.get('immediate_action_exceedances', 0):4d} "
                     + " ".join(f"{counts.get(c, 0.0):5.1f}" for c in CHOICE_NAMES) + f"  {ps}")
    shown = [r for r in payload["results"] if r["policy"] in (payload.get("best_rule"), *payload.get("extra", []))]
    if len(shown) > 1 and all("classes" in r for r in shown):  # where the trained policy's costs differ
        lines.append("own cost per section and episode, k€ (tampings per section and episode):")
        lines.append(f"{'policy':{w}s} " + " ".join(f"{c:>20s}" for c in SECTION_CLASSES) + "  campaigns")
        for r in shown:
            cl = r["classes"]
            cells = ["-" if cl[c]["cost_per_section"] is None else
                     f"{cl[c]['cost_per_section']:.1f} ({cl[c]['tampings_per_section']:.2f})" for c in SECTION_CLASSES]
            lines.append(f"{r['policy']:{w}s} " + " ".join(f"{c:>20s}" for c in cells)
                         + f"  {cl['line']['campaigns_per_episode']:9.1f}")
    lines.append("vs cheapest: the paired difference to the table's cheapest policy (a trained policy's line below "
                 "pairs it with the best tuned rule); IA: section-steps at the immediate-action limit, all episodes "
                 "together; tamp ... survey: applied choices per episode (tamp, spot tamp, drainage, renewal, "
                 "inspection, survey)")
    beyond = [f"{r['policy']} ({r['episodes_beyond_validity']} of {r['n_episodes']})" for r in payload["results"]
              if r.get("episodes_beyond_validity")]
    if beyond:  # the engine's warning scrolls past with the progress bars; the table keeps it
        lines.append("warning: a section left the model's validity (its settlement ran away) in some episodes of "
                     + ", ".join(beyond) + ": their costs from there on are not physical")
    machine = [r for r in payload["results"] if r.get("machine_steps")]
    if machine:  # a network: what its one tamping machine did
        lines.append("the machine's steps per episode: working on its line / moving to another / idle")
        lines += [f"{r['policy']:{w}s} " + " / ".join(f"{r['machine_steps'][k]:4.1f}" for k in MACHINE_STEPS)
                  for r in machine]
    lines += [headline for name in payload.get("extra", []) if (headline := agent_headline(payload, name))]
    if payload.get("episode_plot"):
        lines.append(f"plots: {payload['plot']}, {payload['episode_plot']} (episode {payload['seeds'][0]} under "
                     f"{payload.get('best_rule', 'the best rule')} and any trained policy)")
    return "\n".join(lines)


def _batch_of_one(obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """One env's observation as a batch of one (a leading axis of 1 on every key): what the harness hands every
    policy's ``predict``, and what a policy written for it expects."""
    return {k: np.asarray(v)[None] for k, v in obs.items()}


def _predict_one(policy: Any, obs: dict[str, np.ndarray], state: Any, first: bool, env: Any) -> tuple[np.ndarray, Any]:
    """``policy``'s action for one env's ``obs``, called as the harness calls it (:func:`harness._predict` on a batch
    of one; the env's masks where ``predict`` takes them: a MaskablePPO, ranked counts of the choices), and its
    state."""
    masks = np.asarray(env.get_wrapper_attr("action_masks")())[None] if takes_action_masks(policy) else None
    action, state = _predict(policy, _batch_of_one(obs), state, np.array([first]), masks)
    return np.asarray(action)[0], state


def _panels(policies: Any, cfg: Any, names: Sequence[str] | None) -> tuple[list[Any], list[str]]:
    """An episode plot's policies (one or a list) bound to ``cfg``, and its panel titles: ``names`` (the rows'
    names), else the policies' own, told apart as the harness names its rows (:func:`distinct_names`)."""
    pols = [bind_policy(p, cfg) for p in (policies if isinstance(policies, (list, tuple)) else [policies])]
    return pols, list(names) if names is not None else distinct_names([policy_name(p) for p in pols])


def plot_line_episode(policies: Any, cfg: LineConfig, seed: int, out_png: str,
                      action_type: str = "multibinary", names: Sequence[str] | None = None) -> str:
    """One episode under each of ``policies`` (one policy or a list, SB3-style ``predict``), side by side on
    shared axes: the true SD of every section over time (dotted: as last measured), tamping marked, each
    panel's cost in its title, which names the policy by ``names`` (its row's name; default its own)."""
    from matplotlib.figure import Figure

    from trackenv.envs.line import TampingLine

    pols, titles = _panels(policies, cfg, names)
    fig = Figure(figsize=(10 * len(pols), 4.5))
    axes = fig.subplots(1, len(pols), sharey=True, squeeze=False)[0]
    years = np.arange(cfg.horizon_steps + 1) / cfg.steps_per_year
    for ax, pol, title in zip(axes, pols, titles, strict=True):
        env = TampingLine(cfg, action_type=action_type)
        obs, info = env.reset(seed=seed)
        sd, tam, meas, cost = [info["section_sd_m"] * 1e3], [], [obs["section_sd"].copy()], 0.0
        state = None
        for t in range(cfg.horizon_steps):  # predict on a batch of one, as the harness calls every policy
            a, state = _predict_one(pol, obs, state, t == 0, env)
            obs, r, _, _, info = env.step(a)
            sd.append(info["section_sd_m"] * 1e3)
            meas.append(obs["section_sd"].copy())
            tam.append(info["tamped_sections"])
            cost -= r
        sd_, tam_, meas_ = np.array(sd), np.array(tam), np.array(meas)
        batch = env.batch
        assert batch is not None  # made by the reset
        reg = batch.register
        for j in range(cfg.n_sections):
            col = f"C{j % 10}"
            ax.plot(years, sd_[:, j], color=col, lw=1.2 if reg[j] else 0.8,
                    label=f"s{j}" + {0: "", 1: " (transition)", 2: " (switch)"}[int(reg[j])])
            ax.plot(years, meas_[:, j], color=col, lw=0.5, ls=":")
            for step in np.flatnonzero(tam_[:, j]):
                ax.plot(years[step], sd_[step, j], "v", color=col, ms=6)
        ax.axhline(batch.limits.sd_alert_m * 1e3, color="k", ls="--", lw=0.8, label="SD alert")
        ax.set_xlabel("year")
        ax.set_title(f"{title} on {cfg.n_sections} sections, seed {seed}: {cost:.0f} k€, "
                     f"{int(tam_.sum())} tampings in {int(tam_.any(axis=1).sum())} campaigns", fontsize=9)
    axes[0].set_ylabel("SD of D1 level [mm] (solid true, dotted measured; ▼ tamping)")
    axes[0].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    return out_png


def plot_network_episode(policies: Any, cfg: NetworkConfig, seed: int, out_png: str,
                         names: Sequence[str] | None = None) -> str:
    """One network episode under each of ``policies`` (network policies with SB3-style ``predict``), a column
    each: on top the shared machine's line in every step (● worked there, ▶ moved there, · idle), below it one
    panel per line with the true SD of its sections (▼ tamped, at the SD it was tamped from); each column's cost
    in its title, which names the policy by ``names`` (its row's name; default its own)."""
    import gymnasium as gym
    from matplotlib.figure import Figure

    pols, titles = _panels(policies, cfg, names)
    n_lines, offsets = cfg.n_lines, cfg.line_offsets
    fig = Figure(figsize=(8 * len(pols), 1.6 + 2.2 * n_lines))
    axes = fig.subplots(n_lines + 1, len(pols), sharex=True, sharey="row", squeeze=False,
                        gridspec_kw={"height_ratios": [0.6] + [1.0] * n_lines})
    years = np.arange(cfg.horizon_steps + 1) / cfg.steps_per_year
    for col, (pol, title) in enumerate(zip(pols, titles, strict=True)):
        env = gym.make("trackenv/TampingNetwork-v0", config=cfg)
        obs, info = env.reset(seed=seed)
        sd, tamped, machine, moved, chosen, cost = [info["section_sd_m"] * 1e3], [], [], [], [], 0.0
        state = None
        for t in range(cfg.horizon_steps):
            a, state = _predict_one(pol, obs, state, t == 0, env)
            obs, r, _, _, info = env.step(a)
            sd.append(info["section_sd_m"] * 1e3)
            tamped.append(info["tamped_sections"])
            machine.append(info["machine_line"])
            moved.append(info["moved"])
            chosen.append(info["section_choices"])
            cost -= float(r)
        env.close()
        sd_, tamped_ = np.array(sd), np.array(tamped)
        top = axes[0, col]
        start = years[:-1]  # step t runs from years[t]: the machine's line in it (a move's destination)
        top.step(start, machine, where="post", color="0.6", lw=0.8)
        activity = machine_activity(np.array(moved), np.array(chosen))
        for name, marker in zip(MACHINE_STEPS, ("o", ">", "."), strict=True):
            at = activity[name]
            top.plot(start[at], np.asarray(machine)[at], marker, color="k", ms=4, ls="none",
                     label=f"{name} ({int(at.sum())} steps)")
        top.set_yticks(range(n_lines))
        top.set_ylim(-0.5, n_lines + 0.4)  # room for the legend above the top line
        top.set_title(f"{title}, seed {seed}: {cost:.0f} k€, {int(tamped_.sum())} tampings", fontsize=9)
        top.legend(fontsize=6, ncol=3, loc="upper right")
        for line in range(n_lines):
            ax = axes[line + 1, col]
            for j, entry in enumerate(range(offsets[line], offsets[line + 1])):
                colour = f"C{j % 10}"
                ax.plot(years, sd_[:, entry], color=colour, lw=0.8)
                steps = np.flatnonzero(tamped_[:, entry])
                ax.plot(years[steps], sd_[steps, entry], "v", color=colour, ms=4, ls="none")
        axes[-1, col].set_xlabel("year")
    axes[0, 0].set_ylabel("machine's line")
    for line in range(n_lines):
        axes[line + 1, 0].set_ylabel(f"line {line}: SD [mm]")
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    return out_png


def run_calibration(scenario_name: str = "default", seeds: list[int] | None = None, threshold_mm: float = 2.0,
                    out_dir: str = "results/line_calibration", progress: bool = True, **overrides: Any) -> dict:
    from trackenv_studies.calibration import calibrate, plot_calibration

    cfg = scenario(scenario_name, **overrides)
    seeds = seeds or [2000, 2001]
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=2 * cfg.horizon_steps, desc="calibrate", unit="step")
    try:
        result = calibrate(cfg, seeds, threshold_mm, progress=bar.update if bar is not None else None)
    finally:
        if bar is not None:
            bar.close()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    result["plot"] = plot_calibration(result, str(out / "line_calibration.png"))
    (out / "line_calibration.json").write_text(json.dumps(result, indent=1, default=float))
    return result
