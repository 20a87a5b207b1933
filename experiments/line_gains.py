"""Where the trained line policy gains over the best tuned rule, and how it carries to other lines and traffic.

1. **Gains** (default line, ``--seeds``, default 0:100, the episodes with saved hindsight searches): the shipped
   policy and the best tuned rule on the same episodes (common random numbers). Per section class (plain,
   transition zone, switch or crossing, hidden wet spot) the sections per episode and, for each policy, the own
   cost and the tampings per section and episode, with the paired difference per episode; campaigns and
   possession per episode; the share of the gap between the rule and the hindsight bound
   (``experiments/searches``) that the policy closes; and one episode side by side (``line_gains_episode.png``).
   ``--compare results/line_compare/line_compare.json`` takes them from a saved ``trackenv evaluate --env
   trackenv/TampingLine-v0`` result instead (no episode run again; per class the mean differences only).
2. **Generalisation** (``--generalisation N``): the same policy, the best rule and the best uniform periodic
   rule (the parameters tuned on the default line, not re-tuned) on N episodes of the small and the hard line
   and of the default line with 25 % less and 25 % more tonnage.

Writes ``results/line_gains.json`` (``--out``); progress on stderr.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from trackenv.envs.line_config import LineConfig, scenario
from trackenv_agents.evaluation.harness import evaluate_many
from trackenv_agents.evaluation.line_compare import SECTION_CLASSES, class_breakdown, parse_seeds, plot_line_episode
from trackenv_agents.evaluation.line_hindsight import saved_schedules
from trackenv_agents.evaluation.statistics import paired_difference
from trackenv_agents.learning.line import load_line_trained
from trackenv_agents.rules.problems import tuned_rule

SEARCHES = Path(__file__).resolve().parent / "searches"


def hindsight_costs(config) -> dict[int, float]:
    """The cheapest saved hindsight schedule's cost per held-out seed (every search in experiments/searches)."""
    seeds, _, costs = saved_schedules(sorted(SEARCHES.glob("*.json")), config)
    return dict(zip(seeds, costs))


def gap_closed(seeds: list[int], rule_costs, agent_costs, config) -> dict | None:
    """On the episodes of ``seeds`` with a saved hindsight search: the mean costs of the rule, the agent and the
    hindsight bound, and the share of the rule's gap to the bound that the agent closes. None where no search
    covers them (the saved searches are of the default line: another scenario's shapes do not match)."""
    try:
        hs = hindsight_costs(config)
    except ValueError:
        return None
    covered = [i for i, s in enumerate(seeds) if s in hs]
    if not covered:
        return None
    r, a = np.asarray(rule_costs)[covered], np.asarray(agent_costs)[covered]
    h = np.array([hs[seeds[i]] for i in covered])
    return {"episodes": len(covered), "rule": float(r.mean()), "agent": float(a.mean()), "hindsight": float(h.mean()),
            "share_of_gap_closed": float((r.mean() - a.mean()) / (r.mean() - h.mean()))}


def _agent_minus_rule(results: list[dict], rule: dict, agent: dict) -> dict | None:
    """The paired difference agent − rule (k€, 95 % CI) from a comparison's rows, each paired with the best."""
    best = results[0]["policy"]
    if agent["policy"] == best:  # the rule's row holds rule − agent
        d = rule["vs_best"]
        return {"mean_difference": -d["mean_difference"], "ci_low": -d["ci_high"], "ci_high": -d["ci_low"],
                "n_episodes": d["n_episodes"]}
    if rule["policy"] == best:
        return agent["vs_best"]
    return None  # a third policy was the best: the pair is not in the file


def gains_from_comparison(path: Path) -> dict:
    """The gains from a saved ``trackenv evaluate --env trackenv/TampingLine-v0`` result (its line_compare.json
    with the trained policy "ppo"): no episode is run again. Per class, the difference of the mean own costs is
    the mean paired difference (the same episodes)."""
    payload = json.loads(Path(path).read_text())
    rows = {r["policy"]: r for r in payload["results"]}
    rule, agent = rows[payload["best_rule"]], rows["ppo"]
    per_class = {c: {"mean_difference_per_episode": (agent["classes"][c]["cost_per_section"] or 0.0)
                     * agent["classes"][c]["sections_per_episode"]
                     - (rule["classes"][c]["cost_per_section"] or 0.0) * rule["classes"][c]["sections_per_episode"]}
                 for c in SECTION_CLASSES}
    seeds = payload["seeds"]
    return {"from": str(path), "seeds": [seeds[0], seeds[-1]], "n": len(seeds), "rule": payload["best_rule"],
            "vs_rule": _agent_minus_rule(payload["results"], rule, agent),
            "classes": {"rule": rule["classes"], "agent": agent["classes"]}, "per_class_paired": per_class,
            "hindsight": gap_closed(seeds, rule["episode_costs"], agent["episode_costs"],
                                    LineConfig.coerce(payload["config"]))}


def gains(agent, rule, seeds: list[int], batch_size: int, out: Path) -> dict:
    cfg = scenario("default")
    res_rule, res_agent = evaluate_many([rule, agent], cfg, seeds, batch_size=batch_size, progress=True,
                                        desc="gains")
    table = {"rule": class_breakdown(res_rule), "agent": class_breakdown(res_agent)}
    per_class = {}
    cls_rule = np.where(res_rule.extra["wet_spot"], 3, res_rule.extra["register"])
    for k, name in enumerate(SECTION_CLASSES):  # paired per episode: the class's summed own cost
        m = cls_rule == k
        d = (res_agent.extra["section_cost"] * m).sum(1) - (res_rule.extra["section_cost"] * m).sum(1)
        per_class[name] = {"mean_difference_per_episode": float(d.mean()),
                           "episodes_cheaper": float(np.mean(d < -1e-9)), "episodes_dearer": float(np.mean(d > 1e-9))}
    closed = gap_closed(seeds, res_rule.cost, res_agent.cost, cfg)
    plot = plot_line_episode([rule, agent], cfg, seeds[0], str(out / "line_gains_episode.png"))
    return {"seeds": [seeds[0], seeds[-1]], "n": len(seeds), "rule": res_rule.summary(), "agent": res_agent.summary(),
            "vs_rule": paired_difference(res_agent, res_rule), "classes": table, "per_class_paired": per_class,
            "hindsight": closed, "episode_plot": plot,
            "per_episode": {"seed": seeds, "rule": res_rule.cost.tolist(), "agent": res_agent.cost.tolist()}}


def generalisation(agent, rules: dict, n: int, batch_size: int) -> dict:
    cases = {"small": scenario("small"), "hard": scenario("hard"),
             "default, tonnage -25 %": scenario("default", annual_mgt=11.25),
             "default, tonnage +25 %": scenario("default", annual_mgt=18.75)}
    out = {}
    for name, cfg in cases.items():
        seeds = list(range(n))
        res = evaluate_many([*rules.values(), agent], cfg, seeds, batch_size=batch_size, progress=True, desc=name)
        by = {r.policy: r for r in res}
        row = {p: by[p].summary() for p in by}
        for p in rules:
            row[p]["agent_vs_this"] = paired_difference(by[agent.name], by[p])
        out[name] = row
        print(name, {p: round(r["mean_cost"], 1) for p, r in row.items()}, flush=True)
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0:100", help="held-out episodes of the gains: A:B ('' for none)")
    ap.add_argument("--compare", default=None, metavar="JSON",
                    help="take the gains from a saved `trackenv evaluate --env trackenv/TampingLine-v0` result "
                         "(line_compare.json) instead of running --seeds")
    ap.add_argument("--generalisation", type=int, default=0, metavar="N", help="episodes per generalisation case")
    ap.add_argument("--model", default=None, help="a trained line policy (default: the shipped one)")
    ap.add_argument("--batch-size", type=int, default=50)
    ap.add_argument("--out", default="results")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    agent = load_line_trained(a.model, name="ppo")
    nominal = scenario("default")
    rule = tuned_rule(nominal, "grouped-threshold", require_tuned=True)
    payload: dict = {"model": a.model or "shipped"}
    if a.compare:
        payload["gains"] = gains_from_comparison(Path(a.compare))
    elif a.seeds:
        payload["gains"] = gains(agent, rule, parse_seeds(a.seeds), a.batch_size, out)
    if "gains" in payload:
        g = payload["gains"]
        print(json.dumps({k: g[k] for k in ("vs_rule", "per_class_paired", "hindsight")}, default=float), flush=True)
    if a.generalisation:
        rules = {"grouped-threshold": rule,
                 "uniform-periodic": tuned_rule(nominal, "uniform-periodic", require_tuned=True)}
        payload["generalisation"] = generalisation(agent, rules, a.generalisation, a.batch_size)
    payload["wall_seconds"] = time.time() - t0
    (out / "line_gains.json").write_text(json.dumps(payload, indent=1, default=float))
    print(f"wrote {out / 'line_gains.json'} ({payload['wall_seconds']:.0f} s)")
    return payload


if __name__ == "__main__":
    main()
