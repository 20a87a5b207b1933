"""Score the shipped line agent on the network of lines that share one tamping machine, paired against the
network's best tuned rule, on held-out episodes.

Every policy is a line policy run on every line of ``trackenv/TampingNetwork-v0`` (the default network: three
default lines, one machine) through :class:`~trackenv_agents.rules.network.NetworkRule`, which keeps the machine
on its line while the line policy asks for work there: a rule name (with the tuned parameters of the network's
line), ``cpi-agent`` or ``cpi-choice-agent`` (the shipped agents). The seeds run in chunks (``--chunk``), each
chunk's costs merged into ``DIR/<policy>.json`` as it ends, so a long run keeps what it has done; ``--report``
pairs every policy with the best rule among those scored (the lowest mean cost on the seeds every policy has):
mean cost and the paired difference, each with a 95 % bootstrap CI, into ``DIR/report.json``.

Examples::

    nice -n 5 python experiments/network_agent.py --seeds 0:200 \\
        --policies grouped-threshold,section-threshold,cpi-agent
    python experiments/network_agent.py --report
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent / "saved" / "network_agent"


def network_policies(config, names: list[str]) -> dict:
    """``names`` as network policies by their labels: each rule (the tuned parameters of ``config``'s line) or
    shipped agent run on every line by a :class:`~trackenv_agents.rules.network.NetworkRule`."""
    from trackenv_agents.learning.line import load_line_trained
    from trackenv_agents.rules import rules_for, tuned_params_for
    from trackenv_agents.rules.network import NetworkRule
    from trackenv_agents.shipped import SHIPPED_AGENTS

    rules, tuned = rules_for(config.line_config), tuned_params_for(config.line_config)
    unknown = [n for n in names if n not in rules and n not in SHIPPED_AGENTS]
    if unknown:
        raise SystemExit(f"--policies: unknown {unknown}; give rules of {sorted(rules)} or {sorted(SHIPPED_AGENTS)}")
    built = [NetworkRule(rules[n](**tuned.get(n, {})) if n in rules else load_line_trained(SHIPPED_AGENTS[n], name=n))
             for n in names]
    return {p.name: p for p in built}


def score(policies: list[str], seeds: list[int], out: Path, chunk: int, batch_size: int) -> None:
    """Each chunk of ``seeds``: every policy on the default network, its costs merged into ``out``."""
    from trackenv.envs.network import NetworkConfig
    from trackenv_agents.evaluation.harness import evaluate_many

    config = NetworkConfig()
    built = network_policies(config, policies)
    out.mkdir(parents=True, exist_ok=True)
    for start in range(0, len(seeds), chunk):
        part = seeds[start:start + chunk]
        t0, c0 = time.time(), time.process_time()
        results = evaluate_many(list(built.values()), config, part, batch_size=batch_size)
        wall, cpu = time.time() - t0, time.process_time() - c0
        for label, r in zip(built, results, strict=True):
            path = out / f"{label}.json"
            saved = json.loads(path.read_text()) if path.exists() else {"policy": label, "params": r.params,
                                                                          "config": config.to_dict(), "costs": {},
                                                                          "runs": []}
            saved["costs"].update({str(s): float(c) for s, c in zip(r.seeds, r.cost, strict=True)})
            saved["runs"].append({"policies": list(built), "seeds": [part[0], part[-1]], "wall_s": wall,
                                  "cpu_s": cpu})
            path.write_text(json.dumps(saved, indent=1) + "\n")
        print(f"seeds {part[0]}-{part[-1]}: {wall:.0f} s wall, {cpu:.0f} s CPU; "
              + ", ".join(f"{r.policy} {r.cost.mean():.1f}" for r in results), flush=True)


def report(out: Path) -> dict:
    """Every policy of ``out`` against the best rule on the seeds they all have, paired."""
    from trackenv_agents.evaluation.statistics import bootstrap_ci
    from trackenv_agents.shipped import SHIPPED_AGENTS

    runs = {json.loads(p.read_text())["policy"]: json.loads(p.read_text())
            for p in sorted(out.glob("*.json")) if p.name != "report.json"}
    if not runs:
        raise SystemExit(f"no scored policy in {out}")
    seeds = sorted(set.intersection(*(set(map(int, r["costs"])) for r in runs.values())))
    cost = {name: np.array([r["costs"][str(s)] for s in seeds]) for name, r in runs.items()}
    agents = {f"network({a})" for a in SHIPPED_AGENTS}
    rules = [name for name in cost if name not in agents]
    if not rules:
        raise SystemExit("--report needs a rule among the scored policies")
    best = min(rules, key=lambda name: float(cost[name].mean()))
    rows = []
    for name, c in sorted(cost.items(), key=lambda kv: float(kv[1].mean())):
        d = c - cost[best]
        lo, hi = bootstrap_ci(c)
        dlo, dhi = bootstrap_ci(d)
        rows.append({"policy": name, "mean_cost": float(c.mean()), "ci": [lo, hi],
                     "vs_best_rule": {"mean_difference": float(d.mean()), "ci_low": dlo, "ci_high": dhi},
                     "relative_to_best_rule": float(d.mean() / cost[best].mean()),
                     "relative_ci": [dlo / float(cost[best].mean()), dhi / float(cost[best].mean())],
                     "better_fraction": float(np.mean(d < 0))})
    # each chunk's run is kept in the file of every policy it scored: once each here
    chunks = list({json.dumps(run, sort_keys=True): run for r in runs.values() for run in r["runs"]}.values())
    payload = {"env": "trackenv/TampingNetwork-v0", "n_episodes": len(seeds), "seeds": [seeds[0], seeds[-1]],
               "best_rule": best, "results": rows, "runs": chunks,
               "wall_s": sum(run["wall_s"] for run in chunks), "cpu_s": sum(run["cpu_s"] for run in chunks)}
    (out / "report.json").write_text(json.dumps(payload, indent=1) + "\n")
    return payload


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0:200", help="held-out episodes A:B (seeds A..B-1)")
    parser.add_argument("--policies", default="grouped-threshold,section-threshold,cpi-agent",
                        help="comma-separated rule names and shipped agents, each run on every line")
    parser.add_argument("--chunk", type=int, default=40, help="seeds per chunk (saved as each chunk ends)")
    parser.add_argument("--batch-size", type=int, default=32, help="network episodes per vector env")
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--report", action="store_true", help="pair the saved costs; run nothing")
    args = parser.parse_args()
    if not args.report:
        a, b = (int(v) for v in args.seeds.split(":"))
        score([p.strip() for p in args.policies.split(",")], list(range(a, b)), args.out, args.chunk,
              args.batch_size)
    payload = report(args.out)
    print(f"{payload['n_episodes']} episodes, best rule {payload['best_rule']}; the runs took "
          f"{payload['wall_s']:.0f} s wall, {payload['cpu_s']:.0f} s CPU")
    for r in payload["results"]:
        d = r["vs_best_rule"]
        print(f"{r['policy']:32s} {r['mean_cost']:8.1f} [{r['ci'][0]:.1f}, {r['ci'][1]:.1f}]  "
              f"{d['mean_difference']:+8.1f} [{d['ci_low']:+.1f}, {d['ci_high']:+.1f}]  "
              f"{100 * r['relative_to_best_rule']:+.1f} %")


if __name__ == "__main__":
    main()
