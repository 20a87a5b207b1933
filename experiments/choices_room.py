"""Room to learn with the choices: the per-section hindsight bound (every choice: tamping, spot tamping, drainage,
renewal) against the best tamping-only rule, or against any policy's per-episode costs, per scenario.

Per env id (default the three scenarios with choices) the rule ``--rule`` (default grouped-threshold, with the
shipped tuned parameters of the scenario: ``tuned_params_for``) runs on the held-out seeds; each episode's bound
comes from the leaderboard's cache (``--cache``, default the committed ``experiments/saved/leaderboard/bounds``),
and an episode not cached yet is searched from the rule's schedule and cached
(:func:`trackenv_agents.evaluation.leaderboard.episode_bounds`, the leaderboard's search settings). The bound of an
episode is capped at that rule's cost (its schedule is a candidate). ``--costs FILE`` compares the bound with
another policy's costs on the one env id given: a JSON {"seed": cost, ...} (k€), or a leaderboard's
``leaderboard.json`` with ``--policy NAME`` (that policy's row of the env id), e.g. a rule with choices.
``--old LEADERBOARD.json`` adds the scenarios of a saved leaderboard (its best rule against its bound, or why it
has none).

Per scenario: the rule's and the bound's mean cost with 95 % bootstrap CIs, their paired difference (bound − rule)
with its CI, absolute and relative to the rule's mean, and the search's seconds per episode. Writes JSON
(``--out``) and prints a Markdown table.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import evaluate_many
from trackenv_agents.evaluation.leaderboard import episode_bounds
from trackenv_agents.evaluation.line_compare import parse_seeds, scenario_of
from trackenv_agents.evaluation.statistics import bootstrap_ci
from trackenv_agents.rules.problems import rules_for, tuned_params_for

NEW_IDS = ("trackenv/TampingLineWet-v0", "trackenv/TampingLineDefects-v0", "trackenv/TampingLine-v1")
CACHE = Path(__file__).resolve().parent / "saved" / "leaderboard" / "bounds"


def room(rule_cost: np.ndarray, bound_cost: np.ndarray) -> dict[str, Any]:
    """The bound against a policy on paired episodes: both means with 95 % CIs, the mean of bound − policy with
    its CI, and that relative to the policy's mean cost (negative: the bound is cheaper)."""
    rule, bound = np.asarray(rule_cost, dtype=float), np.asarray(bound_cost, dtype=float)
    diff = bound - rule
    lo, hi = bootstrap_ci(diff)
    mean = float(rule.mean())
    return {"n_episodes": int(rule.size), "rule_mean": mean, "rule_ci": list(bootstrap_ci(rule)),
            "bound_mean": float(bound.mean()), "bound_ci": list(bootstrap_ci(bound)),
            "difference": float(diff.mean()), "difference_ci": [lo, hi], "relative": float(diff.mean()) / mean,
            "relative_ci": [lo / mean, hi / mean]}


def scenario_room(env_id: str, seeds: list[int], rule: str, cache: Path,
                  costs: dict[int, float] | None = None) -> dict[str, Any]:
    """One scenario: the rule's episodes, their bounds (cached or searched), and :func:`room` of the two (or of
    the bound against ``costs``, seed -> k€, where given)."""
    name = scenario_of(env_id)
    cfg = scenario(name)
    params = tuned_params_for(cfg).get(rule, {})
    t0 = time.perf_counter()
    (result,) = evaluate_many([rules_for(cfg)[rule](**params)], cfg, seeds)
    rule_seconds = time.perf_counter() - t0
    t0 = time.perf_counter()
    b = episode_bounds(cfg, name, [result], cache)
    out: dict[str, Any] = {"env": env_id, "scenario": name, "seeds": seeds, "rule": rule, "params": params,
                           "rule_seconds": rule_seconds, "bound_seconds": time.perf_counter() - t0,
                           "search_seconds_per_episode": b["search_seconds_per_episode"], "sources": b["sources"],
                           "rule_costs": result.cost.tolist(), "bound_costs": b["cost"].tolist()}
    if costs is not None:
        missing = [s for s in seeds if s not in costs]
        if missing:
            raise ValueError(f"--costs has no cost for seeds {missing}")
        out.update(compared_with="given costs", given_costs=[costs[s] for s in seeds])
        return {**out, **room(np.array([costs[s] for s in seeds]), b["cost"])}
    return {**out, **room(result.cost, b["cost"])}


def given_costs(path: Path, env_id: str, policy: str | None) -> dict[int, float]:
    """Per seed the costs of ``path``: a JSON {"seed": cost}, or a leaderboard payload's row of ``env_id`` and
    ``policy``."""
    payload = json.loads(path.read_text())
    if "results" not in payload:
        return {int(k): float(v) for k, v in payload.items()}
    rows = [r for r in payload["results"] if r["env"] == env_id and r["policy"] == policy]
    if not rows:
        raise SystemExit(f"{path} has no row of policy {policy!r} on {env_id} (give --policy)")
    return dict(zip(payload["seeds"][env_id], rows[0]["episode_costs"], strict=True))


def saved_room(path: Path) -> list[dict[str, Any]]:
    """The scenarios of a saved leaderboard: its best rule against its bound (or the reason it has none)."""
    board = json.loads(path.read_text())
    out = []
    for env_id, bound in board["bound"].items():
        best = board["best_rule"][env_id]
        row = next(r for r in board["results"] if r["env"] == env_id and r["policy"] == best)
        entry: dict[str, Any] = {"env": env_id, "scenario": board["scenarios"][env_id], "seeds": board["seeds"][env_id],
                                 "rule": best, "params": row["params"], "source": str(path)}
        if bound["available"]:
            entry.update(room(np.array(row["episode_costs"]), np.array(bound["episode_costs"])))
        else:
            entry.update(n_episodes=row["n_episodes"], rule_mean=row["mean_cost"], rule_ci=row["ci"],
                         bound_unavailable=bound["reason"])
        out.append(entry)
    return out


def table(rows: list[dict[str, Any]]) -> str:
    """The rows as Markdown: per scenario the rule, the bound and their paired difference with 95 % CIs."""
    lines = ["| scenario | episodes | rule | rule, k€ [95 % CI] | bound, k€ [95 % CI] | bound − rule, k€ [95 % CI] "
             "| relative [95 % CI] |", "|---|---:|---|---|---|---|---|"]
    for r in rows:
        rule = f"{r['rule_mean']:.1f} [{r['rule_ci'][0]:.1f}, {r['rule_ci'][1]:.1f}]"
        if "bound_mean" not in r:
            lines.append(f"| {r['env']} | {r['n_episodes']} | {r['rule']} | {rule} | — ({r['bound_unavailable']}) "
                         "| — | — |")
            continue
        lines.append(
            f"| {r['env']} | {r['n_episodes']} | {r['rule']} | {rule} | {r['bound_mean']:.1f} "
            f"[{r['bound_ci'][0]:.1f}, {r['bound_ci'][1]:.1f}] | {r['difference']:+.1f} "
            f"[{r['difference_ci'][0]:+.1f}, {r['difference_ci'][1]:+.1f}] | {100 * r['relative']:+.1f} % "
            f"[{100 * r['relative_ci'][0]:+.1f}, {100 * r['relative_ci'][1]:+.1f}] |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--env", default=",".join(NEW_IDS), help="comma-separated env ids")
    ap.add_argument("--seeds", default="0:32", help="held-out seeds, 'A:B' or 'a,b,c'")
    ap.add_argument("--rule", default="grouped-threshold", help="the rule the bound is compared with")
    ap.add_argument("--costs", help="JSON {seed: cost} or a leaderboard.json (with --policy) of one env id: compare "
                    "the bound with these costs")
    ap.add_argument("--policy", help="the policy of --costs' leaderboard.json")
    ap.add_argument("--old", help="a saved leaderboard.json whose scenarios join the table")
    ap.add_argument("--cache", default=str(CACHE), help="the bound cache (the leaderboard's DIR/bounds)")
    ap.add_argument("--out", default="results/choices_room.json")
    args = ap.parse_args(argv)
    envs, seeds = [e.strip() for e in args.env.split(",") if e.strip()], parse_seeds(args.seeds)
    costs = None
    if args.costs:
        if len(envs) != 1:
            raise SystemExit("--costs compares one scenario: give one --env")
        costs = given_costs(Path(args.costs), envs[0], args.policy)
    t0 = time.perf_counter()
    rows = [scenario_room(e, seeds, args.rule, Path(args.cache), costs) for e in envs]
    if args.old:
        rows += saved_room(Path(args.old))
    payload = {"command": " ".join(["python experiments/choices_room.py", *(argv or [])]), "rows": rows,
               "wall_time_s": time.perf_counter() - t0}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(payload, indent=1) + "\n")
    print(table(rows))
    return payload


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
