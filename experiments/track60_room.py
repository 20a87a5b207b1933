"""Where the room on the 60 m track (``trackenv/Tamping-v1``) lies: the whole-line hindsight schedules of training
episodes against the tuned grouped threshold on the same episodes, by cost part and by what each does (campaign
steps, sections tamped, tampings in the last year), and what the rule gains by doing no work in the last steps
before the horizon (whose benefit the life-cycle cost no longer counts).

The schedules come from a ``line_room.py`` search of training seeds (none of them a held-out seed of the
leaderboard or of the agents' selection)::

    python experiments/line_room.py --scenario track60 --use-saved --test-start 3000 --n-test 64 \\
        --n-hindsight 64 --hindsight-batch 8 --rounds 2 --thresholds 2 3 --designs 0 \\
        --out experiments/saved/track60_room_3000-3063.json           # the searches, ~14 min on 2 cores
    python experiments/track60_room.py                                 # this comparison, ~1 min

Writes ``experiments/saved/track60_room.json`` (``--out``).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import evaluate_many
from trackenv_agents.evaluation.line_hindsight import saved_schedules
from trackenv_agents.evaluation.statistics import paired_difference
from trackenv_agents.rules.line import GroupedThreshold
from trackenv_agents.rules.problems import tuned_rule

SAVED = Path(__file__).resolve().parent / "saved"
#: steps before the horizon without work that the end-stop variants of the rule try
STOP_STEPS = (2, 4, 6)


class SchedulePlayer:
    """Plays fixed (H, S) schedules, one per env of a single batch in the order of ``plans``: a policy for the
    evaluation harness when every episode runs in one batch (the harness's slots are then the seeds in order)."""

    name = "hindsight"
    params: ClassVar[dict[str, Any]] = {}

    def __init__(self, plans: list[np.ndarray], horizon_steps: int) -> None:
        self.plans = np.stack(plans).astype(np.int8)
        self.horizon_steps = horizon_steps

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        steps = np.rint(np.asarray(obs["time"], dtype=float).reshape(-1) * self.horizon_steps).astype(int)
        if len(steps) != len(self.plans) or len(set(steps.tolist())) != 1:
            raise ValueError("SchedulePlayer plays every episode in one batch, all at the same step")
        return self.plans[:, steps[0]], state


class EndStop(GroupedThreshold):
    """The grouped threshold that does no work in the last ``stop_steps`` steps of the horizon."""

    name: ClassVar[str] = "grouped-threshold-end-stop"

    def __init__(self, trigger_mm: float = 3.0, include_mm: float = 1.0, stop_steps: int = 4, **kw: Any) -> None:
        super().__init__(trigger_mm=trigger_mm, include_mm=include_mm, **kw)
        self.params["stop_steps"] = int(stop_steps)

    def _act(self, obs):
        working = self._step(obs) < self.horizon_steps - self.params["stop_steps"]
        return super()._act(obs) & working[:, None]


def summary(result: Any) -> dict[str, Any]:
    """Mean cost, cost parts (k€ per episode) and what the policy did, per episode."""
    tamped = np.asarray(result.tamped, dtype=bool)
    return {"mean_cost": float(result.cost.mean()),
            "parts": {k: float(v.mean()) for k, v in result.cost_parts.items() if v.any()},
            "campaign_steps": float(tamped.any(axis=2).sum(axis=1).mean()),
            "sections_tamped": float(tamped.sum(axis=(1, 2)).mean()),
            "tampings_last_year": float(tamped[:, -4:].sum(axis=(1, 2)).mean())}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--search", default=str(SAVED / "track60_room_3000-3063.json"),
                    help="a line_room.py search of the 60 m track (its hindsight schedules)")
    ap.add_argument("--out", default=str(SAVED / "track60_room.json"))
    a = ap.parse_args(argv)
    t0 = time.time()
    config = scenario("track60")
    seeds, plans, saved_costs = saved_schedules([a.search], config)
    rule = tuned_rule(config, "grouped-threshold", require_tuned=True)
    p = rule.params
    policies = [rule, SchedulePlayer(plans, config.horizon_steps)] + [
        EndStop(p["trigger_mm"], p["include_mm"], s) for s in STOP_STEPS]
    results = evaluate_many(policies, config, seeds, batch_size=len(seeds))
    replayed = results[1].cost
    if not np.allclose(replayed, saved_costs, atol=1e-6):
        raise SystemExit(f"the schedules of {a.search} do not replay at their saved costs (largest difference "
                         f"{np.abs(replayed - np.asarray(saved_costs)).max():.3g} k€)")
    out: dict[str, Any] = {"search": Path(a.search).name, "seeds": [int(s) for s in seeds], "rule": dict(p)}
    for r in results:
        label = r.policy if r.policy != EndStop.name else f"{r.policy} ({r.params['stop_steps']} steps)"
        row = summary(r)
        if r is not results[0]:
            d = paired_difference(r, results[0])
            row["vs_rule"] = {**{k: d[k] for k in ("mean_difference", "ci_low", "ci_high")},
                              "relative": d["mean_difference"] / float(results[0].cost.mean())}
        out[label] = row
        print(label, json.dumps(row), flush=True)
    out["wall_seconds"] = time.time() - t0
    Path(a.out).write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {a.out} ({out['wall_seconds']:.0f} s)")


if __name__ == "__main__":
    main()
