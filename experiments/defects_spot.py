"""Why spot tamping hardly pays on the short-defect line (``trackenv/TampingLineDefects-v0``): how often a
section's D1 peak reaches a limit while its SD is below the campaign trigger, and what a spot tamping does to a
section's SD and peak, at once and after the step's traffic.

1. **Limits below the trigger.** The tuned grouped threshold (the best tamping-only rule) on the training
   seeds: the share of section-steps whose true D1 mean-to-peak reaches the alert, intervention (speed
   restriction) and immediate-action limits, overall and with the true SD below the rule's trigger, and the
   percentiles of peak / SD. A spot tamping pays where a local peak costs money while the section as a whole
   needs no tamping.
2. **A spot tamping's effect**, per section, grouped by its peak / SD before: the SD and peak right after the
   lift (the engine's :meth:`~trackenv.envs.line_episode.LineBatch.spot_tamp_rows` on the line at its start),
   and at the end of the step, after that step's traffic (every section spot-tamped at a step of the rule's
   episode against nothing done at that step). The lifted sleepers restart their consolidation while their
   neighbours do not, so part of the lift settles back within the step.
3. **Sharper defects** (:data:`SHARPER`): the largest true SD per episode under the same rule, against the
   shipped preset's; beyond a few times the plain rate on a switch the dynamics leave their validity.
4. **The contact sensor** as a trigger: the rank correlation (Spearman) over the section-steps of point 1
   between the observed dynamic share and the true D1 peak, with the sensor's error and without it.
5. ``--ablation``: the shipped choice rule (``agents/rules/defects_tuned_heuristics.json``) with spot tamping
   off (``spot_peak_mm = 0``, every other parameter as tuned) on the held-out episodes of the saved comparison
   (``experiments/saved/choices_compare_defects.json``), paired against the choice rule and the grouped
   threshold there.

    python experiments/defects_spot.py                      # seeds 1000:1004, writes saved/defects_spot.json
    python experiments/defects_spot.py --ablation           # and the rule without spot tamping (100 episodes)
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
from scipy.stats import spearmanr

from trackenv.envs.choices import SPOT_TAMP
from trackenv.envs.line_config import SLEEPER_SPACING_M, scenario
from trackenv.envs.line_episode import LineBatch
from trackenv.envs.problems import make_vector_env
from trackenv.physics.geometry import d1_filter
from trackenv_agents.evaluation.harness import evaluate_many
from trackenv_agents.evaluation.line_compare import parse_seeds
from trackenv_agents.evaluation.statistics import paired_difference
from trackenv_agents.rules.choices import ChoiceThreshold
from trackenv_agents.rules.line import GroupedThreshold
from trackenv_agents.rules.problems import TUNED_FILES

SAVED = Path(__file__).resolve().parent / "saved"
#: peak / SD classes the spot tamping's effect is reported in
RATIO_EDGES = (0.0, 2.5, 3.0, np.inf)
#: the sharper local defects of point 3 (length [m], rate factor)
SHARPER = (3.0, 5.0)
#: the steps of the rule's episode at which every section is spot-tamped (in its third and fourth year)
SPOT_STEPS = (9, 14)


def _rule(cfg: Any) -> GroupedThreshold:
    params = json.loads(TUNED_FILES["defects"].read_text())["params"][GroupedThreshold.name]
    return GroupedThreshold(**params).bind(cfg)


def _run(cfg: Any, seeds: list[int], stop_at: int | None = None, last: int = 0) -> dict[str, np.ndarray]:
    """The tuned grouped threshold on ``seeds``: the true SD and peak per step and section [mm] and the observed
    dynamic share (steps, seeds, S); with ``stop_at``, the action code ``last`` on every section at that step
    instead of the rule's, and the run ends there."""
    env = make_vector_env(cfg, len(seeds), action_type="choices")
    rule = _rule(cfg)
    obs, _ = env.reset(seed=seeds)
    state, sd, peak, share = None, [], [], []
    for t in range(cfg.horizon_steps if stop_at is None else stop_at + 1):
        action, state = rule.predict(obs, state=state, episode_start=np.full(len(seeds), t == 0))
        action = np.full_like(action, last) if t == stop_at else action
        obs, _, _, _, info = env.step(action)
        sd.append(info["section_sd_mm"].copy())
        peak.append(info["section_peak_mm"].copy())
        share.append(obs["section_dynamic_share"].copy())
    return {"sd": np.array(sd), "peak": np.array(peak), "dynamic_share": np.array(share)}


def limits_below_trigger(cfg: Any, seeds: list[int]) -> dict[str, Any]:
    run = _run(cfg, seeds)
    sd, peak = run["sd"], run["peak"]
    trigger = _rule(cfg).params["trigger_mm"]
    lim = cfg.quality_limits.for_speed(cfg.speed)
    below = sd < trigger
    out: dict[str, Any] = {"section_steps": int(sd.size), "trigger_mm": trigger}
    for name, limit_m in (("alert", lim.alert_m), ("intervention", lim.intervention_m),
                          ("immediate_action", lim.immediate_action_m)):
        over = peak >= limit_m * 1e3
        out[name] = {"limit_mm": limit_m * 1e3, "share": float(over.mean()),
                     "share_with_sd_below_trigger": float((over & below).mean())}
    out["peak_over_sd_percentiles"] = dict(zip(("5", "50", "95", "99", "100"),
                                               np.percentile(peak / sd, [5, 50, 95, 99, 100]).round(2).tolist()))
    return out


def _by_ratio(ratio: np.ndarray, sd0: np.ndarray, sd1: np.ndarray, p0: np.ndarray, p1: np.ndarray) -> list[dict]:
    rows = []
    for lo, hi in zip(RATIO_EDGES[:-1], RATIO_EDGES[1:], strict=True):
        m = (ratio >= lo) & (ratio < hi)
        if m.any():
            rows.append({"peak_over_sd": [lo, None if np.isinf(hi) else hi], "sections": int(m.sum()),
                         "sd_after_over_before": float(np.mean(sd1[m] / sd0[m])),
                         "peak_after_over_before": float(np.mean(p1[m] / p0[m]))})
    return rows


def spot_effect(cfg: Any, seeds: list[int]) -> dict[str, Any]:
    at_once = []
    for seed in seeds:
        batch = LineBatch(cfg, 1)
        batch.start([0], [np.random.default_rng(seed)])
        sd0, p0 = batch.sd.copy(), batch.peak.copy()
        batch.spot_tamp_rows(np.ones(batch.S, dtype=bool), 0)
        d1 = d1_filter(batch.level, SLEEPER_SPACING_M) * 1e3  # one section per segment on this line
        at_once.append((sd0 * 1e3, d1.std(axis=1), p0 * 1e3, np.abs(d1).max(axis=1)))
    sd0, sd1, p0, p1 = (np.concatenate(x) for x in zip(*at_once, strict=True))
    after = []
    for k in SPOT_STEPS:
        plain = _run(cfg, seeds, stop_at=k, last=0)
        spot = _run(cfg, seeds, stop_at=k, last=SPOT_TAMP)
        after.append((plain["sd"][k].ravel(), spot["sd"][k].ravel(), plain["peak"][k].ravel(),
                      spot["peak"][k].ravel()))
    a_sd0, a_sd1, a_p0, a_p1 = (np.concatenate(x) for x in zip(*after, strict=True))
    return {"at_once": _by_ratio(p0 / sd0, sd0, sd1, p0, p1),
            "after_the_step": _by_ratio(a_p0 / a_sd0, a_sd0, a_sd1, a_p0, a_p1), "spot_steps": list(SPOT_STEPS)}


def sharper_defects(cfg: Any, seeds: list[int]) -> dict[str, Any]:
    length, factor = SHARPER
    sharp = scenario("defects", local_defect_length_m=length, local_defect_rate_factor=factor)
    return {"local_defect_length_m": length, "local_defect_rate_factor": factor,
            "largest_sd_mm": _run(sharp, seeds)["sd"].max(axis=(0, 2)).round(1).tolist(),
            "largest_sd_mm_shipped": _run(cfg, seeds)["sd"].max(axis=(0, 2)).round(1).tolist()}


def contact_sensor(cfg: Any, seeds: list[int]) -> dict[str, float]:
    out = {}
    for key, noise in (("with_error", cfg.contact_sensor_noise), ("without_error", 0.0)):
        run = _run(scenario("defects", contact_sensor_noise=noise), seeds)
        out[f"spearman_dynamic_share_true_peak_{key}"] = float(
            spearmanr(run["dynamic_share"].ravel(), run["peak"].ravel())[0])
    return out


def spot_ablation() -> dict[str, Any]:
    saved = json.loads((SAVED / "choices_compare_defects.json").read_text())["rules"]

    def result(name: str) -> SimpleNamespace:
        rule = saved[name]
        return SimpleNamespace(policy=name, seeds=np.array(rule["seeds"]), cost=np.array(rule["episode_costs"]))

    params = {**saved[ChoiceThreshold.name]["params"], "spot_peak_mm": 0.0}
    off = evaluate_many([ChoiceThreshold(**params)], scenario("defects"), saved[ChoiceThreshold.name]["seeds"],
                        action_type="choices", batch_size=50)[0]
    return {"params": params, "mean_cost": float(off.cost.mean()), "choices": off.summary()["choices"],
            "choice_rule_minus_no_spot": paired_difference(result(ChoiceThreshold.name), off),
            "no_spot_minus_grouped_threshold": paired_difference(off, result(GroupedThreshold.name))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1000:1004", metavar="A:B", help="training episodes (default 1000:1004)")
    ap.add_argument("--ablation", action="store_true", help="also the choice rule without spot tamping")
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    cfg = scenario("defects")
    t0 = time.time()
    out = {"scenario": "defects", "seeds": seeds, "command": "python experiments/defects_spot.py",
           "limits_below_trigger": limits_below_trigger(cfg, seeds), "spot_effect": spot_effect(cfg, seeds),
           "sharper_defects": sharper_defects(cfg, seeds), "contact_sensor": contact_sensor(cfg, seeds)}
    if args.ablation:
        out["spot_ablation"] = spot_ablation()
    out["seconds"] = round(time.time() - t0, 1)
    (SAVED / "defects_spot.json").write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
