"""The command line as a user runs it: ``trackenv evaluate --quick --json`` end to end."""

from __future__ import annotations

import json

import pytest

from trackenv_agents.cli import main


@pytest.mark.slow
def test_evaluate_quick_prints_one_json_object(tmp_path, capsys):
    assert main(["evaluate", "--quick", "--json", "--out", str(tmp_path)]) == 0
    out = json.loads(capsys.readouterr().out)
    rows = out["results"]
    names = {row["policy"] for row in rows}
    assert {"periodic", "campaign", "no_maintenance", "random"} <= names
    for row in rows:
        assert row["ci_low"] <= row["mean_cost"] <= row["ci_high"]
    costs = [row["mean_cost"] for row in rows]
    assert costs == sorted(costs)
    assert (tmp_path / "comparison.json").exists() and (tmp_path / "costs.png").exists()


def test_evaluate_rejects_quick_with_the_trained_policy(capsys):
    with pytest.raises(SystemExit, match="default one"):
        main(["evaluate", "--quick", "--policy", "ppo"])


def test_train_seed_default_is_the_training_seed_of_agents_train():
    pytest.importorskip("stable_baselines3")
    from trackenv_agents.cli import build_parser
    from trackenv_agents.train import DEFAULT_TRAIN_SEED

    assert build_parser().parse_args(["train"]).seed == DEFAULT_TRAIN_SEED


def test_evaluate_ray_options_parse():
    from trackenv_agents.cli import build_parser

    args = build_parser().parse_args(["evaluate", "--ray-address", "ray://head:10001", "--batch-size", "8"])
    assert args.ray_address == "ray://head:10001" and args.batch_size == 8 and not args.ray
    assert build_parser().parse_args(["evaluate", "--ray"]).ray
