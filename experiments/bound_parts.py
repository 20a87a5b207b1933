"""Where the hindsight bound saves against the tuned rule and the shipped agent: the cost parts and the choices of
each on the leaderboard's episodes of a scenario whose bound ships, and, on the wet line, whether a policy that
cannot see a wet spot's onset could drain as sparingly as the bound does.

    python experiments/bound_parts.py --scenario wet --scenario defects
    python experiments/bound_parts.py --scenario wet --drain-trial 1000:1032

The bound's schedules are the cached ones (``experiments/saved/leaderboard/bounds/``), replayed in the env itself
(their replayed costs must equal the cached ones: checked); the rule and the agent are those of
``experiments/engine_switch.py`` (the scenario's main tuned rule and its shipped agent). Reported per policy: the
mean cost per episode of each cost part and the mean count per episode of each choice.

Why: the bound knows each wet spot's onset; a survey finds a wet spot whether it works already or is still to
start. ``--drain-trial A:B`` runs, on training seeds, the wet line's tuned choice rule against the same rule
that drains a surveyed wet section only once it regrows fast after a tamping (``drain_after_tampings`` 1 or 2,
``fast_growth_mm_per_year`` 1.0, 1.5 or 2.5, ``drain_surveyed`` off): what waiting for a sign of the onset costs.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # its sibling script, from wherever it runs
from engine_switch import bound_file, reference_policies  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "experiments" / "saved" / "bound_parts.json"
SCENARIOS = ("default", "small", "track60", "choices", "wet", "defects")
#: the waiting drainage rules of --drain-trial: (tampings with fast regrowth, fast regrowth mm/year)
WAITING_DRAINAGE = ((1, 1.0), (1, 1.5), (1, 2.5), (2, 1.0), (2, 1.5), (2, 2.5))


def replay_parts(config, seeds: list[int], plans: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Each (H, S) schedule of ``plans`` (episodes, H, S) run on its episode in the env: the cost parts per
    episode (k€, :func:`~trackenv_agents.evaluation.line_hindsight.replay_schedule_parts`) and each choice's count
    per episode."""
    from trackenv.envs.choices import CHOICES
    from trackenv_agents.evaluation.line_hindsight import replay_schedule_parts

    _, parts = replay_schedule_parts(config, seeds, list(plans))
    counts = np.array([(plans == code).sum(axis=(1, 2)) for code in range(1, len(CHOICES))]).T
    return parts, counts


def parts_row(name: str, cost: np.ndarray, parts: dict[str, np.ndarray], choices: dict[str, float]) -> dict:
    return {"policy": name, "mean_cost": float(cost.mean()),
            "cost_parts": {k: float(v.mean()) for k, v in parts.items() if np.any(v)}, "choices": choices}


def scenario_parts(name: str) -> dict:
    """The bound's, the rule's and the agent's cost parts and choices on the leaderboard's episodes of ``name``."""
    from trackenv.envs.choices import CHOICES
    from trackenv.envs.line_config import scenario
    from trackenv_agents.evaluation.harness import evaluate_many
    from trackenv_agents.evaluation.line_hindsight import schedule_from_rows

    episodes = json.loads(bound_file(name).read_text())["episodes"]
    seeds = sorted(int(s) for s in episodes)
    plans = np.stack([schedule_from_rows(episodes[str(s)]["schedule"]) for s in seeds]).astype(np.int8)
    config = scenario(name)
    parts, counts = replay_parts(config, seeds, plans)
    cost = sum(parts.values())
    cached = np.array([episodes[str(s)]["cost"] for s in seeds])
    if not np.allclose(cost, cached, rtol=1e-6, atol=0.0):
        raise SystemExit(f"{bound_file(name).name}: the replays do not reproduce the cached bounds")
    rows = [parts_row("hindsight bound", cost, parts,
                      {c: float(counts[:, i].mean()) for i, c in enumerate(CHOICES[1:])})]
    for r in evaluate_many(reference_policies(config), config, seeds):
        rows.append(parts_row(r.policy, r.cost, r.cost_parts, r.summary()["choices"]))
    return {"scenario": name, "seeds": seeds, "rows": rows}


def drain_trial(seeds: list[int]) -> dict:
    """The wet line's tuned choice rule against the same rule draining a surveyed wet section only once it
    regrows fast (:data:`WAITING_DRAINAGE`), on ``seeds``, paired."""
    from trackenv.envs.line_config import scenario
    from trackenv_agents.evaluation.harness import evaluate_many
    from trackenv_agents.evaluation.statistics import paired_difference
    from trackenv_agents.rules.problems import tuned_rule

    config = scenario("wet")
    tuned = tuned_rule(config, "choice-threshold", require_tuned=True)
    waiting = [type(tuned)(**{**tuned.params, "drain_surveyed": False, "drain_after_tampings": n,
                              "fast_growth_mm_per_year": g}) for n, g in WAITING_DRAINAGE]
    results = evaluate_many([tuned, *waiting], config, seeds)
    rows = []
    for (n, g), r in zip(((0, None), *WAITING_DRAINAGE), results, strict=True):
        row = parts_row(r.policy, r.cost, r.cost_parts, r.summary()["choices"])
        row.update(drain_after_tampings=n, fast_growth_mm_per_year=g,
                   vs_tuned=None if r is results[0] else paired_difference(r, results[0]))
        rows.append(row)
    return {"seeds": seeds, "rows": rows}


def _print_parts(result: dict) -> None:
    print(f"{result['scenario']}: {len(result['seeds'])} episodes (the leaderboard's)")
    for row in result["rows"]:
        parts = ", ".join(f"{k} {v:.1f}" for k, v in row["cost_parts"].items())
        made = ", ".join(f"{k} {v:.2f}" for k, v in row["choices"].items() if v)
        print(f"  {row['policy']:18s} {row['mean_cost']:7.1f} k€: {parts}\n  {'':18s} per episode: {made}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", action="append", choices=SCENARIOS,
                        help="a scenario with a shipped bound (repeatable)")
    parser.add_argument("--drain-trial", metavar="A:B", help="training seeds of the wet line's drainage trial")
    parser.add_argument("--out", default=str(OUT))
    args = parser.parse_args(argv)
    if not args.scenario and not args.drain_trial:
        parser.error("give --scenario, --drain-trial or both")
    out = {"scenarios": [scenario_parts(name) for name in args.scenario or ()]}
    for result in out["scenarios"]:
        _print_parts(result)
    if args.drain_trial:
        a, b = (int(x) for x in args.drain_trial.split(":"))
        out["drain_trial"] = drain_trial(list(range(a, b)))
        print(f"wet line, seeds {a}-{b - 1}: drainage on survey (tuned) against drainage once a section regrows fast")
        for row in out["drain_trial"]["rows"]:
            d = row["vs_tuned"]
            vs = "" if d is None else f"  {d['mean_difference']:+.1f} [{d['ci_low']:+.1f}, {d['ci_high']:+.1f}]"
            when = ("on survey (tuned)" if d is None else
                    f"after {row['drain_after_tampings']} tampings, fast {row['fast_growth_mm_per_year']}")
            print(f"  {when}: {row['mean_cost']:.1f} k€ (drainage {row['cost_parts'].get('drainage', 0.0):.1f}){vs}")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
