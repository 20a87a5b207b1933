"""Pass reuse on the line (``LineConfig.pass_reuse_tolerance_m``, fast engine): how many passes it skips and
what it changes, per tolerance.

    python experiments/pass_reuse.py --seeds 16 --tolerances-mm 0.1,0.2,0.3,0.4,0.5,0.75,1.0,1.25,1.5,2.0
    python experiments/pass_reuse.py --seeds 16 --tolerances-mm 0.3,1.0 --policy random    # what ab_speed's line steps
    python experiments/pass_reuse.py --seeds 16 --tolerances-mm 1.0 --env trackenv/TampingLineDefects-v0

One episode of ``TampingLine-v0`` (or ``--env``, a line id: saved as ``pass_reuse_<scenario>.json``) per seed under
the id's tuned grouped-threshold rule, or its choice rule where the id has every choice (or, with
``--policy random``, random actions, the action space seeded with the episode's seed: what the ``line`` figures
of ``experiments/ab_speed.py`` step; saved under their own name), with the fast engine and no reuse (the
reference), then with each tolerance. Per tolerance: the share of segment passes skipped (reused) over the
episodes' steps (the reset's passes are always computed and not counted); the episode cost's relative change
against the reference (mean and largest |Δ|); the decisions that differ (the section-steps whose action
differs, and the episodes with any); and the error of the reused sleeper forces: at every step, each reused
segment's equivalent sleeper forces against a fresh pass at its current level (computed aside, changing
nothing), the largest |Δ| relative to the fresh pass's largest sleeper force of the segment, the same for the
kept forces without the static correction (``uncorrected_force_error``: what the correction removes), and the
same for its contact force.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "experiments" / "saved" / "pass_reuse.json"
ENV_ID = "trackenv/TampingLine-v0"


class PassRecorder:
    """Wraps a batch's ``_passes``: counts the segment passes asked for and those reused, and compares each
    reused segment's results with a fresh pass (:meth:`~trackenv.envs.line_episode.LineBatch._computed_passes`,
    which reads the state and writes nothing)."""

    def __init__(self, batch, compare: bool) -> None:
        self.batch, self.compare, self.passes = batch, compare, batch._passes
        self.asked = self.reused = 0
        self.force_error: list[float] = []  # per reused segment-step: max |ΔF| / max F of the fresh pass
        self.uncorrected_error: list[float] = []  # the same for the kept forces without the static correction
        self.contact_error: list[float] = []  # per reused segment-step: |Δ contact| / fresh contact
        batch._passes = self

    def __call__(self, segs: np.ndarray):
        tolerance = self.batch.config.pass_reuse_tolerance_m
        reusable = self.batch._reusable(segs, tolerance) if tolerance > 0 else np.zeros(len(segs), bool)
        force, contact, bays = self.passes(segs)
        self.asked += len(segs)
        self.reused += int(reusable.sum())
        if self.compare and reusable.any():
            fresh_force, fresh_contact, _ = self.batch._computed_passes(segs[reusable])
            scale = fresh_force.max(axis=1)
            self.force_error += list(np.abs(force[reusable] - fresh_force).max(axis=1) / scale)
            kept = self.batch.computed_force[segs[reusable]].transpose(1, 0, 2)
            uncorrected = self.batch._equivalent(kept, self.batch.axle_mix[segs[reusable]])
            self.uncorrected_error += list(np.abs(uncorrected - fresh_force).max(axis=1) / scale)
            self.contact_error += list(np.abs(contact[reusable] - fresh_contact) / fresh_contact)
        return force, contact, bays


def episode(seed: int, tolerance_m: float, compare: bool, policy: str = "rule", env_id: str = ENV_ID) -> dict:
    """One episode under the id's main rule with its tuned parameters
    (:func:`~trackenv_agents.rules.problems.main_rule`; or random actions): its cost, its actions, and the passes'
    record."""
    import gymnasium as gym

    sys.path.insert(0, str(ROOT))
    from agents.rules.problems import main_rule, tuned_rule

    env = gym.make(env_id, engine="fast", pass_reuse_tolerance_m=tolerance_m)
    config = env.unwrapped.config
    name = main_rule(config)
    rule = tuned_rule(config, name, require_tuned=True)
    env.action_space.seed(seed)
    obs, _ = env.reset(seed=seed)
    record = PassRecorder(env.unwrapped.engine, compare)
    cost, actions, done = 0.0, [], False
    while not done:
        action = rule.predict(obs, deterministic=True)[0] if policy == "rule" else env.action_space.sample()
        actions.append(np.asarray(action).ravel().tolist())
        obs, reward, terminated, truncated, _ = env.step(action)
        cost -= float(reward)
        done = terminated or truncated
    return {"cost": cost, "actions": actions, "asked": record.asked, "reused": record.reused,
            "force_error": record.force_error, "uncorrected_error": record.uncorrected_error,
            "contact_error": record.contact_error}


def quantiles(values: list[float]) -> dict:
    if not values:
        return {"n": 0}
    v = np.asarray(values)
    return {"n": int(v.size), "median": float(np.median(v)), "p99": float(np.quantile(v, 0.99)),
            "max": float(v.max())}


def measure(seeds: list[int], tolerances_mm: list[float], policy: str = "rule", env_id: str = ENV_ID) -> dict:
    reference = {s: episode(s, 0.0, False, policy, env_id) for s in seeds}
    rows = []
    for tol in tolerances_mm:
        runs = {s: episode(s, tol * 1e-3, True, policy, env_id) for s in seeds}
        relative = [(runs[s]["cost"] - reference[s]["cost"]) / reference[s]["cost"] for s in seeds]
        differ = [int(np.sum(np.asarray(runs[s]["actions"]) != np.asarray(reference[s]["actions"]))) for s in seeds]
        row = {
            "tolerance_mm": tol,
            "skipped_share": sum(r["reused"] for r in runs.values()) / sum(r["asked"] for r in runs.values()),
            "mean_relative": statistics.mean(relative),
            "mean_abs_relative": statistics.mean(abs(x) for x in relative),
            "max_abs_relative": max(abs(x) for x in relative),
            "section_steps_differing": sum(differ), "episodes_differing": sum(d > 0 for d in differ),
            "force_error": quantiles([e for r in runs.values() for e in r["force_error"]]),
            "uncorrected_force_error": quantiles([e for r in runs.values() for e in r["uncorrected_error"]]),
            "contact_error": quantiles([e for r in runs.values() for e in r["contact_error"]]),
            "episodes": [{"seed": s, "cost": runs[s]["cost"], "reference_cost": reference[s]["cost"],
                          "relative": rel, "section_steps_differing": d, "skipped_share": runs[s]["reused"] /
                          runs[s]["asked"]} for s, rel, d in zip(seeds, relative, differ, strict=True)],
        }
        rows.append(row)
        print(json.dumps({k: v for k, v in row.items() if k != "episodes"}), flush=True)
    steps = len(reference[seeds[0]]["actions"])
    import gymnasium as gym

    from agents.rules.problems import main_rule

    config = gym.make(env_id).unwrapped.config
    return {"env_id": env_id, "engine": "fast", "seeds": seeds,
            "policy": f"{main_rule(config)} (tuned)" if policy == "rule" else "random actions",
            "steps_per_episode": steps, "section_decisions": steps * len(reference[seeds[0]]["actions"][0]) *
            len(seeds), "reference_costs": {s: reference[s]["cost"] for s in seeds},
            "load_average_1min_end": os.getloadavg()[0], "tolerances": rows}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=8, help="episodes, seeds 0 .. seeds - 1 (default 8)")
    parser.add_argument("--tolerances-mm", default="0.02,0.05,0.1,0.2")
    parser.add_argument("--policy", choices=("rule", "random"), default="rule")
    parser.add_argument("--env", default=ENV_ID, help=f"a line id (default {ENV_ID})")
    parser.add_argument("--out", default=None, help="default: experiments/saved/pass_reuse.json (pass_reuse_random"
                                                    ".json with --policy random)")
    args = parser.parse_args()
    result = measure(list(range(args.seeds)), [float(t) for t in args.tolerances_mm.split(",")], args.policy,
                     args.env)
    Path(args.out or default_out(args.env, args.policy)).write_text(json.dumps(result, indent=1) + "\n")


def default_out(env_id: str, policy: str) -> Path:
    """Where a run is saved: ``pass_reuse.json`` for the default line, else ``pass_reuse_<name>.json`` (a line
    preset's scenario name, or the id's name), with ``_random`` before the suffix under random actions."""
    import gymnasium as gym

    import trackenv  # noqa: F401  (registers the ids)

    name = "" if env_id == ENV_ID else "_" + (gym.spec(env_id).kwargs.get("scenario") or env_id.split("/")[-1])
    return OUT.with_name(f"pass_reuse{name}{'_random' if policy == 'random' else ''}.json")


if __name__ == "__main__":
    main()
