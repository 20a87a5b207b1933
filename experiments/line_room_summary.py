"""Merge hindsight searches of TampingLine episodes into the room-to-learn figure: per episode the cheapest
schedule any search found, against the best rule's cost on that episode, with a paired 95 % bootstrap CI.

The hindsight search costs minutes per episode, so the ≥ 100 episodes of the room criterion are searched in
several runs (``line_room.py --use-saved --test-start A --n-test N``, on this machine or others). A schedule's cost
depends only on the true state (tested: ``test_a_schedules_cost_does_not_depend_on_the_recording_design``), so
a search run under another recording design of the same line bounds the same episode too; every search result
was replayed in the env to its cost when it was found.

    python experiments/line_room_summary.py results/line_room.json results/line_hindsight_*.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from trackenv_agents.evaluation.line_hindsight import room_summary


def _searches(payload) -> list[dict]:
    if isinstance(payload, dict):
        return payload.get("hindsight", {}).get("episodes", [])
    return list(payload)


def summarise(room: dict, searches: list[dict]) -> dict:
    """:func:`~trackenv_agents.evaluation.line_hindsight.room_summary` of ``searches`` against the best rule of
    ``room`` (a ``line_room.py`` result)."""
    rule = dict(zip(room["test_seeds"], room["episode_costs"][room["best_rule"]], strict=True))
    return {"best_rule": room["best_rule"], **room_summary(rule, searches)}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("room", help="line_room.py result (the rules' held-out costs)")
    ap.add_argument("searches", nargs="*", help="more search results (line_room.py JSON)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    room = json.loads(Path(args.room).read_text())
    found = _searches(room)
    for f in args.searches:
        found += _searches(json.loads(Path(f).read_text()))
    out = summarise(room, found)
    print(f"{out['n_episodes']} episodes: {out['best_rule']} {out['rule_mean']:.1f} k€, hindsight "
          f"{out['hindsight_mean']:.1f} k€, difference {out['mean_difference']:.1f} "
          f"[{out['ci_low']:.1f}, {out['ci_high']:.1f}] = {100 * out['relative']:+.1f} % "
          f"[{100 * out['relative_ci'][0]:+.1f}, {100 * out['relative_ci'][1]:+.1f}]")
    if args.out:
        Path(args.out).write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
