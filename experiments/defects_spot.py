"""Where spot tamping pays on the short-defect line (``trackenv/TampingLineDefects-v0``): how often a section's
D1 peak reaches a limit while its SD is below the campaign trigger, what a spot tamping does to a section's SD and
peak, at once and after the step's traffic, what the line's form of its defects changes, and what the tuned choice
rule loses without spot tamping.

1. **Limits below the trigger.** The tuned grouped threshold (the best tamping-only rule) on the training
   seeds: the share of section-steps whose true D1 mean-to-peak reaches the alert, intervention (speed
   restriction) and immediate-action limits, overall and with the true SD below the rule's trigger, and the
   percentiles of peak / SD. A spot tamping pays where a local peak costs money while the section as a whole
   needs no tamping.
2. **A spot tamping's effect**, per section, grouped by its peak / SD before: the SD and peak right after the
   lift (the engine's :meth:`~trackenv.envs.line_episode.LineBatch.spot_tamp_rows` on the line at its start),
   and at the end of the step, after that step's traffic (every section spot-tamped at a step of the rule's
   episode against nothing done at that step). The lifted sleepers stand proud of their neighbours and take
   more of the load, and the defect's patch still settles faster, so part of the lift settles back within the
   step.
3. **Sharper defects** (:data:`SHARPER`): the largest true SD per episode under the same rule, against the
   shipped preset's: a sharper defect that multiplies a switch's rate runs away (the dynamics leave their
   validity).
4. **The contact sensor** as a trigger: the rank correlation (Spearman) over the section-steps of point 1
   between the observed dynamic share and the true D1 peak, with the sensor's error and without it.
5. **Where the speed restrictions are**: over the section-steps of point 1, those at or above the intervention
   limit per register class (plain, transition, switch or crossing) per episode, and how many of them with the
   true SD below the trigger: what a spot tamping could save at most.
6. **The form of the defects** (:data:`FORMS`): points 1 and 5 again with a section's SD that of its 30 m
   segment (``local_defect_near_m = 0``: a defect every 30 m instead of once in the section's 200 m), and with the
   line's earlier defects as well (2.4 m settling 2.5x faster, multiplied into a zone's rate, in the segment's
   SD).
7. **Never maintained** (the calibration seeds 2000-2003, no work at all): the largest D1 mean-to-peak and
   wheel/rail force over static wheel load of any section, and the sections past the engine's validity guard
   (:data:`~trackenv.envs.line_episode.VALID_PEAK_M`, :data:`~trackenv.envs.line_episode.VALID_CONTACT_FACTOR`),
   on the shipped line, with its defects multiplied into a zone's rate (``local_defect_in_zone = "multiply"``),
   and with the earlier defects: a defect on a transition's soft side multiplies the zone's factor, and such a
   section can run away.
8. ``--ablation``: the shipped choice rule (``agents/rules/defects_tuned_heuristics.json``) with spot tamping
   off (``spot_peak_mm = 0``, every other parameter as tuned) on the held-out episodes of the saved comparison
   (``experiments/saved/choices_compare_defects.json``), paired against the choice rule and the grouped
   threshold there; the choice family tuned without spot tamping (the cheapest setting with ``spot_peak_mm = 0``
   on the training seeds of the tuned file) against the choice rule, each tuned on its own; and the shipped
   choice rule with a spot tamping's possession at the full price (``spot_possession_share = 1``) against the
   rule without spot tamping.

    python experiments/defects_spot.py                      # seeds 1000:1004, writes saved/defects_spot.json
    python experiments/defects_spot.py --ablation           # and the rule without spot tamping (100 episodes)
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
from scipy.stats import spearmanr

from trackenv.envs.choices import SPOT_TAMP
from trackenv.envs.line_config import REGISTER_CLASSES, SLEEPER_SPACING_M, scenario
from trackenv.envs.line_episode import VALID_CONTACT_FACTOR, VALID_PEAK_M, LineBatch
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
#: the sharper local defects of point 3 (length [m], rate factor, how they meet a zone)
SHARPER = (3.0, 5.0, "multiply")
#: the steps of the rule's episode at which every section is spot-tamped (in its third and fourth year)
SPOT_STEPS = (9, 14)
#: point 6: the line with its section's SD that of its segment, and with the earlier defects as well
EARLIER = {"local_defect_near_m": 0.0, "local_defect_rate_factor": 2.5, "local_defect_in_zone": "multiply"}
FORMS = {"shipped": {}, "segment_sd": {"local_defect_near_m": 0.0}, "earlier_defects": EARLIER}
#: point 7: the calibration seeds
NEVER_MAINTAINED_SEEDS = (2000, 2001, 2002, 2003)


def _rule(cfg: Any) -> GroupedThreshold:
    params = json.loads(TUNED_FILES["defects"].read_text())["params"][GroupedThreshold.name]
    return GroupedThreshold(**params).bind(cfg)


def _run(cfg: Any, seeds: list[int], stop_at: int | None = None, last: int = 0) -> dict[str, np.ndarray]:
    """The tuned grouped threshold on ``seeds``: the true SD and peak per step and section [mm] and the observed
    dynamic share (steps, seeds, S), and the register (seeds, S); with ``stop_at``, the action code ``last`` on
    every section at that step instead of the rule's, and the run ends there."""
    env = make_vector_env(cfg, len(seeds), action_type="choices")
    rule = _rule(cfg)
    obs, _ = env.reset(seed=seeds)
    register = obs["register"].copy()
    state, sd, peak, share = None, [], [], []
    for t in range(cfg.horizon_steps if stop_at is None else stop_at + 1):
        action, state = rule.predict(obs, state=state, episode_start=np.full(len(seeds), t == 0))
        action = np.full_like(action, last) if t == stop_at else action
        obs, _, _, _, info = env.step(action)
        sd.append(info["section_sd_mm"].copy())
        peak.append(info["section_peak_mm"].copy())
        share.append(obs["section_dynamic_share"].copy())
    return {"sd": np.array(sd), "peak": np.array(peak), "dynamic_share": np.array(share), "register": register}


def limits_below_trigger(cfg: Any, seeds: list[int], run: dict[str, np.ndarray] | None = None) -> dict[str, Any]:
    run = _run(cfg, seeds) if run is None else run
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


def speed_restrictions(cfg: Any, run: dict[str, np.ndarray]) -> dict[str, Any]:
    """Point 5 on a run of :func:`_run`: per register class, the section-steps at or above the intervention limit
    per episode, and those with the true SD below the rule's trigger."""
    trigger = _rule(cfg).params["trigger_mm"]
    restricted = run["peak"] >= cfg.quality_limits.for_speed(cfg.speed).intervention_m * 1e3
    below = run["sd"] < trigger
    episodes = run["sd"].shape[1]
    out = {}
    for k, name in enumerate(REGISTER_CLASSES):
        zone = run["register"][None] == k
        out[name] = {"per_episode": float((restricted & zone).sum() / episodes),
                     "with_sd_below_trigger_per_episode": float((restricted & zone & below).sum() / episodes)}
    return out


def forms(seeds: list[int]) -> dict[str, Any]:
    """Point 6: points 1 and 5 on each variant of :data:`FORMS`."""
    out = {}
    for name, fields in FORMS.items():
        cfg = scenario("defects", **fields)
        run = _run(cfg, seeds)
        out[name] = {"fields": fields, "limits_below_trigger": limits_below_trigger(cfg, seeds, run),
                     "speed_restrictions": speed_restrictions(cfg, run)}
    return out


def never_maintained(seeds: tuple[int, ...] = NEVER_MAINTAINED_SEEDS) -> dict[str, Any]:
    """Point 7: the line never maintained: shipped, with its defects multiplied into a zone's rate, and with the
    earlier defects."""
    out = {}
    for name, fields in (("shipped", {}), ("multiply_in_zone", {"local_defect_in_zone": "multiply"}),
                         ("earlier_defects", EARLIER)):
        cfg = scenario("defects", **fields)
        batch = LineBatch(cfg, len(seeds))
        batch.start(list(range(len(seeds))), [np.random.default_rng(s) for s in seeds])
        peak, force = batch.peak.copy(), batch.contact_force / batch.static_wheel_load
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", RuntimeWarning)
            for _ in range(cfg.horizon_steps):
                batch.traffic()
                peak = np.maximum(peak, batch.peak)
                force = np.maximum(force, batch.contact_force / batch.static_wheel_load)
        out[name] = {"largest_peak_mm": round(float(peak.max() * 1e3), 1),
                     "largest_force_over_static": round(float(force.max()), 2),
                     "sections_past_the_guard": int(((peak > VALID_PEAK_M) | (force > VALID_CONTACT_FACTOR)).sum()),
                     "runtime_warning": any(issubclass(w.category, RuntimeWarning) for w in caught)}
    return {"seeds": list(seeds), **out}


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
        d1 = d1_filter(batch.level, SLEEPER_SPACING_M)  # one section per segment on this line
        at_once.append((sd0 * 1e3, batch._segment_sd(d1, np.arange(batch.S)) * 1e3, p0 * 1e3,
                        np.abs(d1).max(axis=1) * 1e3))
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
    length, factor, in_zone = SHARPER
    sharp = scenario("defects", local_defect_length_m=length, local_defect_rate_factor=factor,
                     local_defect_in_zone=in_zone)
    return {"local_defect_length_m": length, "local_defect_rate_factor": factor, "local_defect_in_zone": in_zone,
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
    full = evaluate_many([ChoiceThreshold(**saved[ChoiceThreshold.name]["params"])],
                         scenario("defects", spot_possession_share=1.0), saved[ChoiceThreshold.name]["seeds"],
                         action_type="choices", batch_size=50)[0]
    spot = paired_difference(result(ChoiceThreshold.name), off)
    tuned_off = min((row for row in json.loads(TUNED_FILES["defects"].read_text())["train_mean_cost"][
        ChoiceThreshold.name] if not row["params"]["spot_peak_mm"]), key=lambda row: row["mean_cost"])
    alone = evaluate_many([ChoiceThreshold(**tuned_off["params"])], scenario("defects"),
                          saved[ChoiceThreshold.name]["seeds"], action_type="choices", batch_size=50)[0]
    fair = paired_difference(result(ChoiceThreshold.name), alone)
    return {"params": params, "mean_cost": float(off.cost.mean()), "choices": off.summary()["choices"],
            "tuned_without_spot": {"params": tuned_off["params"], "train_mean_cost": tuned_off["mean_cost"],
                                   "mean_cost": float(alone.cost.mean()), "choices": alone.summary()["choices"],
                                   "choice_rule_minus_it": fair,
                                   "choice_rule_minus_it_relative": [fair[k] / float(alone.cost.mean()) for k in
                                                                     ("mean_difference", "ci_low", "ci_high")]},
            "choice_rule_minus_no_spot": spot,
            "choice_rule_minus_no_spot_relative": [spot[k] / float(off.cost.mean())
                                                   for k in ("mean_difference", "ci_low", "ci_high")],
            "no_spot_minus_grouped_threshold": paired_difference(off, result(GroupedThreshold.name)),
            "full_price_spot_possession": {"mean_cost": float(full.cost.mean()),
                                           "choices": full.summary()["choices"],
                                           "minus_no_spot": paired_difference(full, off)}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="1000:1004", metavar="A:B", help="training episodes (default 1000:1004)")
    ap.add_argument("--ablation", action="store_true", help="also the choice rule without spot tamping")
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    cfg = scenario("defects")
    t0 = time.time()
    run = _run(cfg, seeds)
    out = {"scenario": "defects", "seeds": seeds, "command": "python experiments/defects_spot.py",
           "limits_below_trigger": limits_below_trigger(cfg, seeds, run), "spot_effect": spot_effect(cfg, seeds),
           "sharper_defects": sharper_defects(cfg, seeds), "contact_sensor": contact_sensor(cfg, seeds),
           "speed_restrictions": speed_restrictions(cfg, run), "forms": forms(seeds),
           "never_maintained": never_maintained()}
    if args.ablation:
        out["spot_ablation"] = spot_ablation()
    out["seconds"] = round(time.time() - t0, 1)
    (SAVED / "defects_spot.json").write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
