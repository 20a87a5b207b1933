"""What the leaderboard's rows would become if the line's faster options were the defaults: the tuned rule, the
shipped agent and the saved hindsight bounds on the leaderboard's episodes, under the classic engine (today's
default) and under ``engine="fast"`` with ``pass_reuse_tolerance_m=1e-3``.

    python experiments/engine_switch.py                                  # every scenario whose bound ships
    python experiments/engine_switch.py --scenario default --out results/engine_switch.json

Per scenario (a preset whose bound ships in ``experiments/saved/leaderboard/bounds/``): its seeds and bound
schedules are the cached ones; the tuned rule (the grouped threshold, or the choice rule on the lines with every
choice, with the preset's tuned parameters) and the shipped agent (``cpi-agent``, or ``cpi-choice-agent`` on the
lines with every choice) run on those episodes under each engine, and each saved schedule is replayed under each
engine, capped at the rule's cost there (as the leaderboard caps it). Reported per engine: the mean costs, the
agent's and the bound's change against the rule and the agent's normalised score (the share of the rule-to-bound
gap it closes, paired sums, as the leaderboard computes it); across the engines: each policy's per-episode cost
change (mean and largest |Δ|), the episodes where a replayed schedule costs more than the rule under the fast
engine (where a bound would need a new search rather than a replay), and the wall time of the two evaluations.
The classic replays must reproduce the cached costs (checked). The schedules were searched under the classic
engine: under the fast one they are found schedules, not a fresh search's.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "experiments" / "saved" / "engine_switch.json"
SCENARIOS = ("default", "small", "track60", "choices", "wet", "defects")
FAST = {"engine": "fast", "pass_reuse_tolerance_m": 1e-3}


def bound_file(scenario_name: str) -> Path:
    """The leaderboard's bound cache of a scenario (one file per scenario ships)."""
    from trackenv_agents.evaluation.leaderboard import SHIPPED_BOUNDS

    found = sorted(SHIPPED_BOUNDS.glob(f"{scenario_name}_*.json"))
    if len(found) != 1:
        raise SystemExit(f"expected one bound file of {scenario_name!r} in {SHIPPED_BOUNDS}, found {len(found)}")
    return found[0]


def engine_rows(config, seeds: list[int], plans: list[np.ndarray], policies: list) -> dict:
    """The rule's, the agent's and the capped replayed bounds' costs per episode under ``config`` (k€), and the
    seconds the two policies' evaluation took."""
    from trackenv_agents.evaluation.harness import evaluate_many
    from trackenv_agents.evaluation.line_hindsight import replay_schedules

    t0 = time.perf_counter()
    rule, agent = evaluate_many(policies, config, seeds)
    seconds = time.perf_counter() - t0
    replayed = replay_schedules(config, seeds, plans)
    return {"rule": rule.cost, "agent": agent.cost, "replayed": replayed, "bound": np.minimum(replayed, rule.cost),
            "evaluation_s": seconds}


def summary(rows: dict) -> dict:
    """Means, the agent's and the bound's relative change against the rule, and the agent's normalised score."""
    rule, agent, bound = rows["rule"], rows["agent"], rows["bound"]
    return {"rule_keur": float(rule.mean()), "agent_keur": float(agent.mean()), "bound_keur": float(bound.mean()),
            "agent_vs_rule": float(agent.mean() / rule.mean() - 1),
            "bound_vs_rule": float(bound.mean() / rule.mean() - 1),
            "normalised_score": float((rule - agent).sum() / (rule - bound).sum()),
            "evaluation_s": float(rows["evaluation_s"])}


def reference_policies(config) -> list:
    """The main rule (:func:`~trackenv_agents.rules.problems.main_rule`) with its tuned parameters and the shipped
    agent of ``config``: ``cpi-choice-agent`` where it enables more than tamping, else ``cpi-agent``."""
    from trackenv_agents.learning.line import load_line_trained
    from trackenv_agents.rules.problems import main_rule, tuned_rule
    from trackenv_agents.shipped import CHOICE_AGENT_NAME, LINE_AGENT_NAME, SHIPPED_AGENTS

    rule = main_rule(config)
    agent = LINE_AGENT_NAME if rule == "grouped-threshold" else CHOICE_AGENT_NAME
    return [tuned_rule(config, rule, require_tuned=True),
            load_line_trained(SHIPPED_AGENTS[agent], name=agent)]


def compare(scenario_name: str) -> dict:
    """Both engines on a scenario's leaderboard episodes (see the module docstring)."""
    from trackenv.envs.line_config import scenario
    from trackenv_agents.evaluation.line_hindsight import schedule_from_rows

    path = bound_file(scenario_name)
    episodes = json.loads(path.read_text())["episodes"]
    seeds = sorted(int(s) for s in episodes)
    plans = [schedule_from_rows(episodes[str(s)]["schedule"]) for s in seeds]
    cached = np.array([episodes[str(s)]["cost"] for s in seeds])
    classic = scenario(scenario_name)
    policies = reference_policies(classic)
    rows = {"classic": engine_rows(classic, seeds, plans, policies),
            "fast+reuse": engine_rows(classic.replace(**FAST), seeds, plans, policies)}
    if not np.allclose(rows["classic"]["replayed"], cached, rtol=1e-6, atol=0.0):
        raise SystemExit(f"{path.name}: the classic replays do not reproduce the cached bounds")
    change = {}
    for key in ("rule", "agent", "bound"):
        rel = rows["fast+reuse"][key] / rows["classic"][key] - 1
        change[key] = {"mean": float(rel.mean()), "max_abs": float(np.abs(rel).max())}
    above = rows["fast+reuse"]["replayed"] > rows["fast+reuse"]["rule"] + 1e-9
    return {"scenario": scenario_name, "bound_file": path.name, "seeds": seeds, "policies": [repr(p) for p in policies],
            "engines": {name: summary(r) for name, r in rows.items()}, "per_episode_change": change,
            "replays_above_the_fast_rule": int(above.sum()),
            "costs": {name: {k: np.asarray(v).tolist() for k, v in r.items() if k != "evaluation_s"}
                      for name, r in rows.items()}}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", action="append", choices=SCENARIOS,
                        help="a scenario with a shipped bound (repeatable; default: all of them)")
    parser.add_argument("--out", default=str(OUT))
    args = parser.parse_args(argv)
    results = []
    for name in args.scenario or SCENARIOS:
        r = compare(name)
        results.append(r)
        for engine, s in r["engines"].items():
            print(f"{name:8s} {engine:11s} rule {s['rule_keur']:7.1f}  agent {s['agent_keur']:7.1f} "
                  f"({100 * s['agent_vs_rule']:+.2f} %)  bound {s['bound_keur']:7.1f} "
                  f"({100 * s['bound_vs_rule']:+.2f} %)  normalised {s['normalised_score']:.3f}  "
                  f"evaluation {s['evaluation_s']:.0f} s")
        for key, c in r["per_episode_change"].items():
            print(f"{name:8s} {key:5s} fast+reuse vs classic per episode: mean {100 * c['mean']:+.3f} %, "
                  f"largest |change| {100 * c['max_abs']:.3f} %")
        print(f"{name:8s} replayed schedules above the fast rule: {r['replays_above_the_fast_rule']} of "
              f"{len(r['seeds'])}")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"fast_options": FAST, "scenarios": results}, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
