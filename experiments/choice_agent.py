"""Score the line agent on the lines with every choice against the best tuned rule, on held-out episodes, paired.

Each run scores some policies on one scenario and saves each policy's cost per episode in its own file,
``DIR/<scenario>__<policy>.json`` (so scenarios and policies can run in separate processes); ``--report`` pairs
every policy with the scenario's reference rule (``choice-threshold`` with the id's tuned parameters on the
lines with every choice, ``grouped-threshold`` on the tamping-only ones) on their common seeds: mean cost and
the paired difference, each with a 95 % bootstrap CI, and the choices applied per episode.

Examples::

    python experiments/choice_agent.py --env trackenv/TampingLineWet-v0 --seeds 0:200 \\
        --policies choice-threshold,cpi-choice-agent
    python experiments/choice_agent.py --report

Policies: a rule name (with the scenario's tuned parameters), ``cpi-agent`` (the shipped tamp-or-wait agent),
``cpi-choice-agent`` (the shipped agent of the lines with every choice) or the path of a saved line policy;
``AGENT@RULE`` is AGENT's network with RULE as its advisor (``cpi-agent@choice-threshold``: the shipped
tamp-or-wait network deciding the tamping, the scenario's tuned choice rule the other choices).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from trackenv_agents.shipped import SHIPPED_AGENTS

OUT = Path(__file__).resolve().parent / "saved" / "choice_agent"


def _policy(name: str, config):
    from trackenv_agents.learning.line import load_line_trained
    from trackenv_agents.learning.line_policy import LineAgent
    from trackenv_agents.rules import rules_for, tuned_rule

    rules = rules_for(config)
    if name in rules:
        return tuned_rule(config, name)
    agent, _, advisor = name.partition("@")  # AGENT@RULE: the agent's network with another advisor
    path = SHIPPED_AGENTS.get(agent, Path(agent))
    loaded = load_line_trained(path, name=agent if agent in SHIPPED_AGENTS else path.stem)
    if advisor:
        return LineAgent(loaded.policy, name=name, advisor=rules[advisor](), horizon_years=loaded.horizon_years)
    return loaded


def score(env_id: str, policies: list[str], seeds: list[int], out: Path, batch_size: int) -> None:
    from trackenv.envs.problems import problem_config
    from trackenv_agents.evaluation.harness import evaluate_many
    from trackenv_agents.evaluation.line_compare import scenario_of

    scenario = scenario_of(env_id)
    config = problem_config(scenario)
    t0, c0 = time.time(), time.process_time()
    results = evaluate_many([_policy(p, config) for p in policies], config, seeds, batch_size=batch_size)
    wall, cpu = time.time() - t0, time.process_time() - c0
    out.mkdir(parents=True, exist_ok=True)
    for name, r in zip(policies, results):
        label = name if name in SHIPPED_AGENTS or "/" not in name else Path(name).stem
        payload = {"env": env_id, "scenario": scenario, "policy": label, "params": r.params,
                   "seeds": r.seeds.tolist(), "cost": r.cost.tolist(),
                   "choices": {k: float(np.mean(v)) for k, v in r.choices.items()},
                   "run": {"policies": policies, "wall_s": wall, "cpu_s": cpu}}
        path = out / f"{scenario}__{label}.json"
        path.write_text(json.dumps(payload, indent=1))
        print(f"{path}: {np.mean(r.cost):.1f} k€ over {len(r.cost)} episodes ({wall:.0f} s wall, {cpu:.0f} s CPU "
              "for the run)", flush=True)


REFERENCE = {"default": "grouped-threshold"}  # else choice-threshold


def report(out: Path) -> dict:
    from trackenv_agents.evaluation.statistics import bootstrap_ci

    runs: dict[str, dict[str, dict]] = {}
    for path in sorted(out.glob("*__*.json")):
        d = json.loads(path.read_text())
        runs.setdefault(d["scenario"], {})[d["policy"]] = d
    table = []
    for scenario, by_policy in runs.items():
        ref_name = REFERENCE.get(scenario, "choice-threshold")
        ref = by_policy.get(ref_name)
        for name, d in by_policy.items():
            cost = np.asarray(d["cost"])
            row = {"env": d["env"], "policy": name, "episodes": len(cost), "mean_cost": float(cost.mean()),
                   "ci": bootstrap_ci(cost), "choices": d["choices"], "reference": ref_name}
            if ref is not None and name != ref_name:
                common, ia, ib = np.intersect1d(d["seeds"], ref["seeds"], return_indices=True)
                diff = cost[ia] - np.asarray(ref["cost"])[ib]
                ref_mean = float(np.asarray(ref["cost"])[ib].mean())
                lo, hi = bootstrap_ci(diff)
                row |= {"paired_episodes": int(common.size), "vs_reference": float(diff.mean()),
                        "vs_reference_ci": [lo, hi], "vs_reference_pct": 100 * float(diff.mean()) / ref_mean,
                        "vs_reference_pct_ci": [100 * lo / ref_mean, 100 * hi / ref_mean],
                        "better_fraction": float(np.mean(diff < -1e-6))}  # ties: the same actions
            table.append(row)
    print("| id | policy | episodes | mean cost k€ [95 % CI] | vs reference rule, paired k€ [95 % CI] | relative "
          "| tamp / spot / drain / renew / inspect / survey per episode |")
    print("|---|---|---:|---|---|---:|---|")
    for r in table:
        c = r["choices"]
        counts = " / ".join(f"{c.get(k, 0.0):.1f}" for k in ("tamp", "spot_tamp", "drainage", "renew", "inspect",
                                                             "survey"))
        vs = ("—" if "vs_reference" not in r else
              f"{r['vs_reference']:+.1f} [{r['vs_reference_ci'][0]:+.1f}, {r['vs_reference_ci'][1]:+.1f}]")
        pct = "" if "vs_reference" not in r else f"{r['vs_reference_pct']:+.1f} %"
        print(f"| `{r['env']}` | {r['policy']} | {r['episodes']} | {r['mean_cost']:.1f} [{r['ci'][0]:.1f}, "
              f"{r['ci'][1]:.1f}] | {vs} | {pct} | {counts} |")
    summary = {"rows": table}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", default="trackenv/TampingLineWet-v0", metavar="ID")
    p.add_argument("--policies", default="choice-threshold,cpi-choice-agent", metavar="NAMES")
    p.add_argument("--seeds", default="0:200", metavar="A:B")
    p.add_argument("--batch-size", type=int, default=50)
    p.add_argument("--out", default=str(OUT))
    p.add_argument("--report", action="store_true", help="pair the saved runs and print the table")
    a = p.parse_args(argv)
    if a.report:
        report(Path(a.out))
        return
    from trackenv_agents.evaluation.line_compare import parse_seeds

    score(a.env, [x.strip() for x in a.policies.split(",")], parse_seeds(a.seeds), Path(a.out), a.batch_size)


if __name__ == "__main__":
    main()
