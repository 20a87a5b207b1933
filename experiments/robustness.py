"""How the shipped line agent, the tuned rules and the model-predictive planner degrade outside the conditions they
were trained, tuned or fitted on.

The shipped per-section agent (``cpi-agent``) was trained, and the rules' parameters were tuned, on the default
line (``trackenv/TampingLine-v0``: 15 MGT a year at 100 km/h, realistic ballast, a recording-car run once a
year). Here each is run, unchanged, on the default line with one condition moved outside that range:

* tonnage −50 % and +50 % (``annual_mgt`` 7.5 and 22.5);
* ballast stiffness ×0.5 and ×2 (``ballast_stiffness_factor``: softer and stiffer support, other sleeper forces);
* speed 70 and 140 km/h (``speed_kmh``; the passes' time step follows the speed);
* the recording car twice a year and every two years (``measurement_interval`` 2 and 8 steps).

``--scenario track60`` does the same on the 60 m track (``trackenv/Tamping-v1``: 40 MGT a year at 100 km/h, the SD
measured every step), with the rules' parameters tuned there, the model-predictive planner (``model-predictive``,
its model fitted and chosen on the nominal track) and the 60 m track's shipped agent (``cpi-track60-agent``, the
planner as its advisor, trained on the nominal track) beside ``cpi-agent``: tonnage −50 % and
+50 % (20 and 60 MGT), ballast stiffness ×0.5 and ×2, speed 70 and 140 km/h. (The planner needs the SD of every
step, so the track has no recording-interval conditions.)

On the same held-out episodes (``--seeds``, default 2000:2032, common random numbers across policies) the mean
life-cycle cost of each policy with its 95 % CI, and the paired difference of the agent (and the planner) to the
best rule with its CI, per condition. The rules are the shipped tuned ones (not re-tuned: a planner who keeps the
rule as tuned); the best rule on the nominal track is grouped-threshold. Writes ``results/robustness.json``
(``--out``) and prints a Markdown table; progress on stderr.

    python experiments/robustness.py                       # 32 episodes per condition, ~15 min on 2 cores
    python experiments/robustness.py --seeds 2000:2008     # a quick look
    python experiments/robustness.py --scenario track60 --seeds 2000:2100 --batch-size 50   # the 60 m track, ~9 min
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import evaluate_many
from trackenv_agents.evaluation.line_compare import parse_seeds
from trackenv_agents.evaluation.statistics import bootstrap_ci, paired_difference
from trackenv_agents.learning.line import load_line_trained
from trackenv_agents.rules.model_predictive import ModelPredictive
from trackenv_agents.rules.problems import tuned_rule
from trackenv_agents.shipped import TRACK60_AGENT_NAME, TRACK60_PRETRAINED_FILE


def physical_conditions(scenario_name: str) -> tuple[tuple[str, dict], ...]:
    """(name, overrides of the preset ``scenario_name``): the nominal track first, then its tonnage −50 % and +50 %,
    ballast stiffness ×0.5 and ×2, and speed 70 and 140 km/h, one at a time."""
    mgt = scenario(scenario_name).annual_mgt
    return (
        ("nominal", {}),
        ("tonnage -50 %", {"annual_mgt": 0.5 * mgt}),
        ("tonnage +50 %", {"annual_mgt": 1.5 * mgt}),
        ("ballast stiffness x0.5", {"ballast_stiffness_factor": 0.5}),
        ("ballast stiffness x2", {"ballast_stiffness_factor": 2.0}),
        ("speed 70 km/h", {"speed_kmh": 70.0}),
        ("speed 140 km/h", {"speed_kmh": 140.0}),
    )


#: the default line's conditions (15 MGT a year nominal), with its recording interval moved too
CONDITIONS: tuple[tuple[str, dict], ...] = physical_conditions("default") + (
    ("recording car twice a year", {"measurement_interval": 2}),
    ("recording car every 2 years", {"measurement_interval": 8}),
)
#: the same on the 60 m track (40 MGT a year nominal; its SD is measured every step, so no recording interval)
TRACK60_CONDITIONS = physical_conditions("track60")
RULES = ("grouped-threshold", "uniform-periodic")
AGENT = "cpi-agent"
#: per scenario: its conditions and the policies other than the rules, each paired with the best rule
SCENARIOS: dict[str, tuple[tuple[tuple[str, dict], ...], tuple[str, ...]]] = {
    "default": (CONDITIONS, (AGENT,)),
    "track60": (TRACK60_CONDITIONS, (AGENT, TRACK60_AGENT_NAME, ModelPredictive.name)),
}


def policies(scenario_name: str = "default") -> list:
    """The shipped agent, the scenario's other policies (on the 60 m track its own shipped agent and the planner)
    and the shipped tuned rules (parameters of the nominal scenario)."""
    nominal = scenario(scenario_name)
    named = SCENARIOS[scenario_name][1]
    others = ([load_line_trained(TRACK60_PRETRAINED_FILE, name=TRACK60_AGENT_NAME)]
              if TRACK60_AGENT_NAME in named else []) + ([ModelPredictive()] if ModelPredictive.name in named else [])
    return [load_line_trained(name=AGENT), *others] + [tuned_rule(nominal, n, require_tuned=True) for n in RULES]


def run_condition(name: str, overrides: dict, seeds: list[int], batch_size: int,
                  scenario_name: str = "default") -> dict:
    """Every policy on ``seeds`` of the scenario with ``overrides``: costs with CIs, each of the agent and the
    scenario's other policies − the best rule (``agent_minus_best_rule`` the agent's, ``vs_best_rule`` all)."""
    cfg = scenario(scenario_name, **overrides)
    results = evaluate_many(policies(scenario_name), cfg, seeds, batch_size=batch_size, progress=True, desc=name)
    rows = {}
    for r in results:
        lo, hi = bootstrap_ci(r.cost)
        rows[r.policy] = {"mean_cost": float(r.cost.mean()), "ci_low": lo, "ci_high": hi,
                          "tampings_per_km_year": float(r.tampings_per_km_year.mean())}
    by_name = {r.policy: r for r in results}
    best_rule = min(RULES, key=lambda n: rows[n]["mean_cost"])
    versus = {}
    for policy in SCENARIOS[scenario_name][1]:
        diff = paired_difference(by_name[policy], by_name[best_rule])
        versus[policy] = {**diff, "relative": float(diff["mean_difference"] / rows[best_rule]["mean_cost"])}
    return {"condition": name, "overrides": overrides, "costs": rows, "best_rule": best_rule,
            "agent_minus_best_rule": {k: v for k, v in versus[AGENT].items() if k != "relative"},
            "agent_vs_best_rule_relative": versus[AGENT]["relative"], "vs_best_rule": versus}


def table(rows: list[dict]) -> str:
    """Markdown: per condition the mean cost of each policy and the paired difference of each policy other than
    the rules to the best rule."""
    others = list(rows[0]["vs_best_rule"]) if rows and "vs_best_rule" in rows[0] else [AGENT]
    head = ("| condition | " + " | ".join([*others, *RULES]) + " | "
            + " | ".join(f"{p} − best rule [k€] (95 % CI)" for p in others) + " |\n"
            + "|---|" + "---:|" * (len(RULES) + 2 * len(others)))
    out = [head]
    for r in rows:
        versus = r.get("vs_best_rule") or {AGENT: {**r["agent_minus_best_rule"],
                                                   "relative": r["agent_vs_best_rule_relative"]}}
        costs = " | ".join(f"{r['costs'][p]['mean_cost']:.1f}" for p in [*others, *RULES])
        diffs = " | ".join(f"{d['mean_difference']:+.1f} [{d['ci_low']:+.1f}, {d['ci_high']:+.1f}] "
                           f"({100 * d['relative']:+.1f} % vs {r['best_rule']})"
                           for d in (versus[p] for p in others))
        out.append(f"| {r['condition']} | {costs} | {diffs} |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", default="default", choices=sorted(SCENARIOS),
                    help="the default line, or the 60 m track (track60) with the model-predictive planner")
    ap.add_argument("--seeds", default="2000:2032", help="held-out seeds A:B (default 2000:2032)")
    ap.add_argument("--only", default=None, help="comma-separated condition names (default: all)")
    ap.add_argument("--batch-size", type=int, default=24)
    ap.add_argument("--out", default="results/robustness.json")
    args = ap.parse_args(argv)
    seeds = parse_seeds(args.seeds)
    conditions = SCENARIOS[args.scenario][0]
    wanted = set(args.only.split(",")) if args.only else None
    unknown = (wanted or set()) - {n for n, _ in conditions}
    if unknown:
        ap.error(f"--only: unknown conditions {sorted(unknown)}; known: {[n for n, _ in conditions]}")
    t0 = time.perf_counter()
    rows = [run_condition(n, o, seeds, args.batch_size, args.scenario) for n, o in conditions
            if wanted is None or n in wanted]
    payload = {"scenario": args.scenario, "seeds": [seeds[0], seeds[-1] + 1], "n_episodes": len(seeds), "rows": rows,
               "wall_time_s": time.perf_counter() - t0}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(payload, indent=1, default=float))
    print(table(rows))
    print(f"wrote {out} ({payload['wall_time_s']:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
