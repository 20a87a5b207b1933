"""Score the shipped line agent on the network of lines that share one tamping machine, paired against the
network's best tuned rule, on held-out episodes.

Every policy is a line policy run on every line of ``trackenv/TampingNetwork-v0`` (the default network: three
default lines, one machine) through :class:`~trackenv_agents.rules.network.NetworkRule`: a rule name (with the
tuned parameters of the network's line), ``cpi-agent`` or ``cpi-choice-agent`` (the shipped agents), under each
dispatch of ``--dispatch``: ``requests`` (the machine stays on its line while the line policy asks for work
there, else goes where most is asked: ``network(<policy>)``) and/or ``value`` (it goes where the requested work
is worth most: ``network-by-value(<policy>)``). The seeds run in chunks (``--chunk``), each chunk's costs merged
into ``DIR/<policy>.json`` as it ends, so a long run keeps what it has done; ``--report`` pairs every policy with
the best rule among those scored (the lowest mean cost on the seeds every policy has; ``--against`` another
reference, into ``DIR/report-vs-<reference>.json``): mean cost and the paired difference, each with a 95 %
bootstrap CI, into ``DIR/report.json``.
``--tune`` scores the value dispatch's parameter grid (:data:`DISPATCH_GRID`) on training episodes instead,
paired with the requests dispatch, into ``DIR/tuning.json``. ``--eager`` plays the shipped agents eager where the
machine stays (``NetworkRule(..., eager_probability=NETWORK_EAGER_PROBABILITY)``: its line asks for every section
the agent would tamp with at least that probability; ``network-by-value(<agent>, eager <p>)``); ``--tune-eager
P,...`` scores the agents under the value dispatch at each of those probabilities on training episodes, paired
with the agent not eager, into the rounds of ``DIR/tuning.json``.

Examples::

    nice -n 5 python experiments/network_agent.py --seeds 0:200 \\
        --policies grouped-threshold,section-threshold,cpi-agent
    nice -n 5 python experiments/network_agent.py --seeds 0:200 --policies grouped-threshold,cpi-agent \\
        --dispatch value
    python experiments/network_agent.py --report
    nice -n 5 python experiments/network_agent.py --tune --seeds 1000:1016 --policies grouped-threshold,cpi-agent
    nice -n 5 python experiments/network_agent.py --tune-eager 0.05,0.1,0.15,0.2,0.35 --seeds 1000:1048 \
        --policies cpi-agent
    nice -n 5 python experiments/network_agent.py --seeds 0:200 --policies cpi-agent --dispatch value --eager
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent / "saved" / "network_agent"


#: the value dispatch's parameters searched by ``--tune``: the switch margin (k€ per step) at a lead of one step,
#: then the lead (years) at the middle margin (an episode costs some 4-9 s a policy, so the grid is small)
DISPATCH_GRID = (*({"switch_margin": m, "lead_years": 0.25} for m in (5.0, 20.0, 60.0)),
                 *({"switch_margin": 20.0, "lead_years": y} for y in (0.0, 0.5)))


def network_policies(config, names: list[str], dispatches: tuple = ("requests",), eager: bool = False) -> dict:
    """``names`` as network policies by their labels: each rule (the tuned parameters of ``config``'s line) or
    shipped agent run on every line by a :class:`~trackenv_agents.rules.network.NetworkRule`, under each of
    ``dispatches`` (its ``dispatch`` argument), in that order; with ``eager`` the agents eager where the machine
    stays (:func:`~trackenv_agents.rules.network.eager_for`)."""
    from trackenv_agents.learning.line import load_line_trained
    from trackenv_agents.rules import rules_for, tuned_rule
    from trackenv_agents.rules.network import NetworkRule, eager_for
    from trackenv_agents.shipped import SHIPPED_AGENTS

    rules = rules_for(config.line_config)
    unknown = [n for n in names if n not in rules and n not in SHIPPED_AGENTS]
    if unknown:
        raise SystemExit(f"--policies: unknown {unknown}; give rules of {sorted(rules)} or {sorted(SHIPPED_AGENTS)}")
    lines = [tuned_rule(config.line_config, n) if n in rules else load_line_trained(SHIPPED_AGENTS[n], name=n)
             for n in names]
    built = [NetworkRule(line, dispatch, eager_probability=eager_for(line) if eager else None)
             for dispatch in dispatches for line in lines]
    return {p.name: p for p in built}


def score(policies: list[str], seeds: list[int], out: Path, chunk: int, batch_size: int,
          dispatches: tuple = ("requests",), eager: bool = False) -> None:
    """Each chunk of ``seeds``: every policy on the default network, its costs merged into ``out``."""
    from trackenv.envs.network import NetworkConfig
    from trackenv_agents.evaluation.harness import evaluate_many

    config = NetworkConfig()
    built = network_policies(config, policies, dispatches, eager)
    out.mkdir(parents=True, exist_ok=True)
    for start in range(0, len(seeds), chunk):
        part = seeds[start:start + chunk]
        t0, c0 = time.time(), time.process_time()
        results = evaluate_many(list(built.values()), config, part, batch_size=batch_size)
        wall, cpu = time.time() - t0, time.process_time() - c0
        for label, r in zip(built, results, strict=True):
            path = out / f"{label.replace(', ', ',').replace(' ', '_')}.json"  # no spaces in file names
            saved = json.loads(path.read_text()) if path.exists() else {"policy": label, "params": r.params,
                                                                          "config": config.to_dict(), "costs": {},
                                                                          "runs": []}
            saved["costs"].update({str(s): float(c) for s, c in zip(r.seeds, r.cost, strict=True)})
            saved["runs"].append({"policies": list(built), "seeds": [part[0], part[-1]], "wall_s": wall,
                                  "cpu_s": cpu})
            path.write_text(json.dumps(saved, indent=1) + "\n")
        print(f"seeds {part[0]}-{part[-1]}: {wall:.0f} s wall, {cpu:.0f} s CPU; "
              + ", ".join(f"{r.policy} {r.cost.mean():.1f}" for r in results), flush=True)


def tune(policies: list[str], seeds: list[int], out: Path, batch_size: int, grid: tuple = DISPATCH_GRID) -> dict:
    """Each line policy under the requests dispatch and the value dispatch at every point of ``grid``, on
    ``seeds`` (training episodes): mean cost and the paired difference with the requests dispatch (95 % bootstrap
    CI), added to the rounds of ``out/tuning.json``."""
    from trackenv.envs.network import NetworkConfig
    from trackenv_agents.rules.dispatch import ValueDispatch
    from trackenv_agents.rules.network import NetworkRule

    config = NetworkConfig()
    dispatches = ["requests", *(ValueDispatch(**point) for point in grid)]
    candidates = [NetworkRule(rule.line_rule, d) for rule in network_policies(config, policies).values()
                  for d in dispatches]
    return _tuning_round(config, candidates, len(dispatches), seeds, out, batch_size, "vs_requests", {})


def tune_eager(policies: list[str], seeds: list[int], out: Path, batch_size: int,
               probabilities: tuple[float, ...]) -> dict:
    """Each shipped agent of ``policies`` under the value dispatch, not eager and eager at each of
    ``probabilities``, on ``seeds`` (training episodes): mean cost and the paired difference with the agent not
    eager (95 % bootstrap CI), added to the rounds of ``out/tuning.json``."""
    from trackenv.envs.network import NetworkConfig
    from trackenv_agents.rules.network import NetworkRule

    config = NetworkConfig()
    agents = [rule.line_rule for rule in network_policies(config, policies).values()
              if callable(getattr(rule.line_rule, "requests", None))]
    if not agents:
        raise SystemExit(f"--tune-eager: no shipped agent among --policies {policies}")
    levels = (None, *probabilities)
    candidates = [NetworkRule(agent, "value", eager_probability=p) for agent in agents for p in levels]
    return _tuning_round(config, candidates, len(levels), seeds, out, batch_size, "vs_not_eager",
                         {"eager_probabilities": list(probabilities)})


def _tuning_round(config, candidates: list, group: int, seeds: list[int], out: Path, batch_size: int, key: str,
                  extra: dict) -> dict:
    """Score ``candidates`` on ``seeds``, each paired with the first of its ``group`` (``key``: the name of that
    difference in the rows), print them and add the round (with ``extra``) to ``out/tuning.json``."""
    from trackenv_agents.evaluation.harness import evaluate_many
    from trackenv_agents.evaluation.statistics import bootstrap_ci

    t0, c0 = time.time(), time.process_time()
    results = evaluate_many(candidates, config, seeds, batch_size=batch_size)
    rows = []
    for i, r in enumerate(results):
        d = r.cost - results[i - i % group].cost
        lo, hi = bootstrap_ci(d)
        rows.append({"policy": r.policy, "params": r.params, "mean_cost": float(r.cost.mean()),
                     key: {"mean_difference": float(d.mean()), "ci": [lo, hi]}})
        print(f"{r.policy:44s} {r.params.get('switch_margin', '-')!s:>6} {r.params.get('lead_years', '-')!s:>5} "
              f"{r.cost.mean():8.1f} {d.mean():+8.1f} [{lo:+.1f}, {hi:+.1f}]", flush=True)
    payload = {"env": "trackenv/TampingNetwork-v0", "seeds": [seeds[0], seeds[-1]], "n_episodes": len(seeds),
               **extra, "results": rows, "wall_s": time.time() - t0, "cpu_s": time.process_time() - c0}
    out.mkdir(parents=True, exist_ok=True)
    path = out / "tuning.json"
    rounds = json.loads(path.read_text())["rounds"] if path.exists() else []
    path.write_text(json.dumps({"rounds": [*rounds, payload]}, indent=1) + "\n")
    return payload


def report(out: Path, against: str | None = None) -> dict:
    """Every policy of ``out`` against the best rule (or the policy ``against``) on the seeds they all have,
    paired."""
    from trackenv_agents.evaluation.statistics import bootstrap_ci
    from trackenv_agents.shipped import SHIPPED_AGENTS

    runs = {json.loads(p.read_text())["policy"]: json.loads(p.read_text())
            for p in sorted(out.glob("*.json")) if not p.name.startswith(("report", "tuning"))}
    if not runs:
        raise SystemExit(f"no scored policy in {out}")
    seeds = sorted(set.intersection(*(set(map(int, r["costs"])) for r in runs.values())))
    cost = {name: np.array([r["costs"][str(s)] for s in seeds]) for name, r in runs.items()}

    def line_policy(label: str) -> str:  # network-by-value(cpi-agent, eager 0.15) -> cpi-agent
        return label.partition("(")[2].rstrip(")").partition(",")[0]

    rules = [name for name in cost if line_policy(name) not in SHIPPED_AGENTS]
    if not rules:
        raise SystemExit("--report needs a rule among the scored policies")
    if against is not None and against not in cost:
        raise SystemExit(f"--against: {against!r} is not among the scored policies {sorted(cost)}")
    best = against or min(rules, key=lambda name: float(cost[name].mean()))
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
    (out / ("report.json" if against is None else f"report-vs-{against}.json")).write_text(
        json.dumps(payload, indent=1) + "\n")
    return payload


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", default="0:200", help="held-out episodes A:B (seeds A..B-1)")
    parser.add_argument("--policies", default="grouped-threshold,section-threshold,cpi-agent",
                        help="comma-separated rule names and shipped agents, each run on every line")
    parser.add_argument("--chunk", type=int, default=40, help="seeds per chunk (saved as each chunk ends)")
    parser.add_argument("--batch-size", type=int, default=32, help="network episodes per vector env")
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--dispatch", default="requests",
                        help="comma-separated dispatches of the machine, each with every policy: requests, value")
    parser.add_argument("--report", action="store_true", help="pair the saved costs; run nothing")
    parser.add_argument("--against", default=None, help="the reference of --report (default: the best rule)")
    parser.add_argument("--tune", action="store_true",
                        help="score the value dispatch's grid on --seeds (training episodes) into DIR/tuning.json")
    parser.add_argument("--grid", default=None,
                        help="--tune's points MARGIN:LEAD_YEARS,... (default: DISPATCH_GRID)")
    parser.add_argument("--eager", action="store_true",
                        help="the shipped agents eager where the machine stays (NETWORK_EAGER_PROBABILITY)")
    parser.add_argument("--tune-eager", default=None, metavar="P,...",
                        help="score the agents eager at these probabilities on --seeds (training episodes)")
    args = parser.parse_args()
    a, b = (int(v) for v in args.seeds.split(":"))
    policies = [p.strip() for p in args.policies.split(",")]
    if args.tune:
        points = [] if args.grid is None else [point.split(":") for point in args.grid.split(",")]
        grid = tuple({"switch_margin": float(m), "lead_years": float(y)} for m, y in points) or DISPATCH_GRID
        tune(policies, list(range(a, b)), args.out, args.batch_size, grid)
        return
    if args.tune_eager:
        tune_eager(policies, list(range(a, b)), args.out, args.batch_size,
                   tuple(float(p) for p in args.tune_eager.split(",")))
        return
    if not args.report:
        score(policies, list(range(a, b)), args.out, args.chunk, args.batch_size,
              tuple(d.strip() for d in args.dispatch.split(",")), args.eager)
    payload = report(args.out, args.against)
    print(f"{payload['n_episodes']} episodes, best rule {payload['best_rule']}; the runs took "
          f"{payload['wall_s']:.0f} s wall, {payload['cpu_s']:.0f} s CPU")
    for r in payload["results"]:
        d = r["vs_best_rule"]
        print(f"{r['policy']:36s} {r['mean_cost']:8.1f} [{r['ci'][0]:.1f}, {r['ci'][1]:.1f}]  "
              f"{d['mean_difference']:+8.1f} [{d['ci_low']:+.1f}, {d['ci_high']:+.1f}]  "
              f"{100 * r['relative_to_best_rule']:+.1f} %")


if __name__ == "__main__":
    main()
