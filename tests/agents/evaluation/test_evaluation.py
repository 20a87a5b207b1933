"""The evaluation harness on a tiny config (the 60 m track cut to 30 m, 3 sections, 2 years = 8 steps)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from trackenv.envs.tamping import TampingEnv
from trackenv_agents.evaluation.harness import EvaluationResult, evaluate_many, evaluate_one
from trackenv_agents.evaluation.line_compare import format_line_table, line_comparison
from trackenv_agents.evaluation.statistics import bootstrap_ci, paired_difference
from trackenv_agents.evaluation.tuning import tune, tune_many
from trackenv_agents.rules.line import LineNoMaintenance, SectionThreshold, UniformPeriodic

SEEDS = [0, 1, 2, 3]


@pytest.fixture(scope="module")
def results(small_config) -> dict[str, EvaluationResult]:
    """No maintenance and a section threshold on SEEDS, in one batched run (chunks of 3 to exercise the
    chunking)."""
    no, sd = evaluate_many([LineNoMaintenance(), SectionThreshold(threshold_mm=0.8)], small_config, SEEDS,
                           batch_size=3)
    return {"no": no, "sd": sd}


@pytest.mark.slow
def test_cost_is_minus_sum_of_rewards(results):
    for r in results.values():
        np.testing.assert_allclose(r.cost, -r.sum_rewards, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(r.cost, sum(r.cost_parts.values()))
        assert r.n_episodes == len(SEEDS)
        np.testing.assert_array_equal(r.seeds, SEEDS)


@pytest.mark.slow
def test_same_seeds_identical_results_whatever_the_batching(results, small_config):
    again = evaluate_one(SectionThreshold(threshold_mm=0.8), small_config, SEEDS, batch_size=4)
    first = results["sd"]
    np.testing.assert_array_equal(again.cost, first.cost)
    np.testing.assert_array_equal(again.section_tampings, first.section_tampings)
    np.testing.assert_array_equal(again.final_mean_sd_mm, first.final_mean_sd_mm)
    assert again.summary() == first.summary()


@pytest.mark.slow
def test_matches_single_env_rollout(results, small_config):
    """The harness's episode for seed 2 is the one TampingEnv.reset(seed=2) plays."""
    env = TampingEnv(small_config)
    policy = SectionThreshold(threshold_mm=0.8).bind(small_config)
    obs, _ = env.reset(seed=2)
    total, tamped = 0.0, 0
    for _ in range(small_config.horizon_steps):
        obs, r, term, trunc, info = env.step(policy.predict(obs)[0])
        total -= r
        tamped += int(info["tamped_sections"].sum())
    assert trunc and not term
    i = SEEDS.index(2)
    np.testing.assert_allclose(results["sd"].cost[i], total, rtol=1e-9)
    assert results["sd"].section_tampings[i] == tamped


@pytest.mark.slow  # uses the 5 s fixture
def test_no_maintenance_has_zero_tampings(results):
    s = results["no"].summary()
    assert s["tampings_per_km_year"] == 0.0 and s["section_tampings"] == 0.0
    assert results["no"].cost_parts["tamping"].sum() == 0.0
    assert results["sd"].section_tampings.sum() > 0  # a low threshold does tamp


@pytest.mark.slow  # uses the 5 s fixture
def test_summary_fields_and_ci(results, small_config):
    s = results["sd"].summary()
    for key in ("policy", "params", "n_episodes", "mean_cost", "ci_low", "ci_high", "tampings_per_km_year",
                "immediate_action_exceedances", "immediate_action_exceedances_mean", "mean_final_sd_mm"):
        assert key in s
    assert s["policy"] == "section-threshold" and s["params"] == {"threshold_mm": 0.8}
    assert s["ci_low"] <= s["mean_cost"] <= s["ci_high"]
    r = results["sd"]
    expected = r.section_tampings.mean() / (small_config.n_sections * small_config.horizon_years)
    assert s["tampings_per_km_year"] == pytest.approx(expected)
    json.dumps(s)  # JSON-friendly


def test_bootstrap_ci_contains_mean_and_is_reproducible():
    x = np.random.default_rng(5).normal(10, 2, 50)
    lo, hi = bootstrap_ci(x)
    assert lo < x.mean() < hi
    assert (lo, hi) == bootstrap_ci(x)
    assert bootstrap_ci(np.full(4, 3.0)) == (3.0, 3.0)


@pytest.mark.slow  # uses the 5 s fixture
def test_paired_difference(results):
    d = paired_difference(results["sd"], results["no"])
    np.testing.assert_allclose(d["mean_difference"], results["sd"].cost.mean() - results["no"].cost.mean())
    assert d["ci_low"] <= d["mean_difference"] <= d["ci_high"]
    assert d["n_episodes"] == len(SEEDS)
    z = paired_difference(results["no"], results["no"])
    assert z["mean_difference"] == z["ci_low"] == z["ci_high"] == 0.0


@pytest.mark.slow
def test_tune_returns_grid_member(small_config):
    grid = [{"threshold_mm": 0.8}, {"threshold_mm": 50.0}]
    out = tune(SectionThreshold, small_config, train_seeds=[10, 11], grid=grid)
    assert out["best_params"] in grid
    assert [row["mean_cost"] for row in out["table"]] == sorted(row["mean_cost"] for row in out["table"])
    assert out["best_mean_cost"] == out["table"][0]["mean_cost"]


@pytest.mark.slow
def test_tune_many_keeps_per_episode_costs(small_config):
    out = tune_many([SectionThreshold], small_config, [10, 11], batch_size=4, progress=False)
    table = out[0]["table"]
    assert len(table) == len(SectionThreshold.param_grid())
    for row in table:
        assert len(row["episode_costs"]) == 2
        assert np.mean(row["episode_costs"]) == pytest.approx(row["mean_cost"])


@pytest.mark.slow
def test_comparison_on_the_60m_track_is_sorted_and_tunes(monkeypatch, tmp_path, small_coarse_config):
    """`trackenv evaluate --env trackenv/Tamping-v1 --retune` on the cut track: the rules tuned now on the
    training seeds (each over its grid, here two points), scored with no maintenance on the held-out seeds,
    cheapest first, the table one row a policy."""
    grids = {UniformPeriodic: [{"interval_years": 1.0, "offset_years": 0.0},
                               {"interval_years": 0.5, "offset_years": 0.0}],
             SectionThreshold: [{"threshold_mm": 0.8}, {"threshold_mm": 50.0}]}
    for cls, grid in grids.items():
        monkeypatch.setattr(cls, "param_grid", classmethod(lambda c, g=grid: g))
    cut = {k: getattr(small_coarse_config, k) for k in ("n_sections", "segment_length_m", "sections_per_segment",
                                                         "capacity", "horizon_years", "dt")}
    out = line_comparison("trackenv/Tamping-v1", seeds=[0, 1], rules=["no-maintenance", "uniform-periodic",
                                                                      "section-threshold"],
                          n_train=1, retune=True, batch_size=4, progress=False, out_dir=str(tmp_path), **cut)
    assert out["scenario"] == "track60" and out["config"] == small_coarse_config.to_dict()
    assert out["tuned_from"] == "tuned now on 1 seeds"
    rows = out["results"]
    costs = [r["mean_cost"] for r in rows]
    assert costs == sorted(costs)
    assert {r["policy"] for r in rows} == {"no-maintenance", "uniform-periodic", "section-threshold"}
    for r in rows:
        assert r["n_episodes"] == 2 and r["ci_low"] <= r["mean_cost"] <= r["ci_high"]
        assert r["params"] in [{}, *(p for g in grids.values() for p in g)]
        assert (r["vs_best"] is None) == (r is rows[0])
    table = format_line_table(out).splitlines()
    assert sum(line.split()[0] in {r["policy"] for r in rows} for line in table[2:]) == 3
    assert out["best_rule"] == rows[0]["policy"]


def test_episodes_beyond_the_models_validity_are_counted_and_the_table_warns(tmp_path):
    """A policy whose episodes ran a section beyond the model's validity (``info["beyond_validity"]``) has them
    counted in its summary, and the comparison's table ends with a warning naming it; a maintained line none."""
    runaway = {"local_defect_length_m": 3.0, "local_defect_rate_factor": 5.0, "local_defect_in_zone": "multiply",
               "horizon_years": 1.0}
    with pytest.warns(RuntimeWarning, match="has left the model's validity"):
        out = line_comparison("trackenv/TampingLineDefects-v0", seeds=[1000], rules=["no-maintenance"],
                              batch_size=4, progress=False, out_dir=str(tmp_path), **runaway)
    (row,) = out["results"]
    assert row["episodes_beyond_validity"] == 1
    assert format_line_table(out).splitlines()[-2] == (
        "warning: a section left the model's validity (its settlement ran away) in some episodes of no-maintenance "
        "(1 of 1): their costs from there on are not physical")
    plain = evaluate_one(SectionThreshold(threshold_mm=2.5), "small", [0])
    assert plain.beyond_validity.tolist() == [False] and plain.summary()["episodes_beyond_validity"] == 0


def test_evaluate_policy_is_a_deprecated_name_of_evaluate_one(small_config):
    from trackenv_agents import evaluation

    with pytest.warns(DeprecationWarning, match="evaluate_one"):
        old = evaluation.evaluate_policy(SectionThreshold(threshold_mm=0.8), small_config, SEEDS[:1])
    np.testing.assert_array_equal(old.cost,
                                  evaluate_one(SectionThreshold(threshold_mm=0.8), small_config, SEEDS[:1]).cost)


def test_the_network_comparison_runs_each_line_rule_on_every_line(tmp_path):
    """``trackenv evaluate --env trackenv/TampingNetwork-v0``: every line rule wrapped in a NetworkRule with the
    line's tuned parameters and dispatched by value, named after it, costs summing the lines' and the machine's
    moves."""
    from trackenv.envs.network import NetworkConfig

    out = line_comparison("trackenv/TampingNetwork-v0", seeds=[0], rules=["no-maintenance", "section-threshold"],
                          batch_size=4, progress=False, out_dir=str(tmp_path), n_lines=2, line_config="small",
                          horizon_years=0.5)
    assert out["scenario"] == "network" and out["episode_plot"].endswith("network_episode.png")
    assert (tmp_path / "network_episode.png").stat().st_size > 0
    assert NetworkConfig.from_dict(out["config"]) == NetworkConfig(n_lines=2, line_config="small").replace(
        line_config=NetworkConfig(line_config="small").line_config.replace(horizon_years=0.5))
    by = {r["policy"]: r for r in out["results"]}
    assert set(by) == {"network-by-value(no-maintenance)", "network-by-value(section-threshold)"}
    assert by["network-by-value(no-maintenance)"]["tampings_per_km_year"] == 0.0
    with pytest.raises(ValueError, match="retune"):
        line_comparison("trackenv/TampingNetwork-v0", seeds=[0], retune=True, out_dir=str(tmp_path))


def test_the_machine_steps_of_a_network_are_those_its_env_reports():
    """On a network each step of the machine is counted once, as working (track work on its line), moving
    (``info["moved"]``) or idle, as a single env's rollout of the same seed reports them; a line has none."""
    import gymnasium as gym

    from trackenv.envs.network import NetworkConfig
    from trackenv_agents.rules.network import NetworkRule

    config = NetworkConfig(n_lines=2, line_config="small").replace(
        line_config=NetworkConfig(line_config="small").line_config.replace(horizon_years=1.5))
    rule = NetworkRule(SectionThreshold(threshold_mm=0.5))
    result, idle_rule = evaluate_many([rule, NetworkRule(LineNoMaintenance())], config, [3, 4], batch_size=4)
    steps = result.machine_steps
    total = sum(steps.values())
    assert set(steps) == {"work", "move", "idle"} and (total == config.horizon_steps).all()
    assert idle_rule.machine_steps["idle"].tolist() == [config.horizon_steps] * 2
    assert result.summary()["machine_steps"] == {k: float(v.mean()) for k, v in steps.items()}
    env = gym.make("trackenv/TampingNetwork-v0", config=config)
    obs, _ = env.reset(seed=4)
    policy = rule.bind(config)
    counted = {"work": 0, "move": 0, "idle": 0}
    for _ in range(config.horizon_steps):
        obs, _, _, _, info = env.step(policy.predict(obs)[0])
        kind = "move" if info["moved"] else "work" if info["tamped_sections"].any() else "idle"
        counted[kind] += 1
    assert counted == {k: int(v[1]) for k, v in steps.items()}
    assert counted["move"] > 0 and counted["work"] > 0  # the case tests both
    assert "machine_steps" not in evaluate_one(LineNoMaintenance(), "small", [0]).summary()


class _Constant:
    """A policy of the harness's interface that returns ``value`` for every section (or one row: ``batched=False``;
    the batch transposed or flat: ``layout``; the actions alone, without the state: ``pair=False``)."""

    name = "constant"

    def __init__(self, value, batched: bool = True, layout: str = "rows", pair: bool = True) -> None:
        self.value, self.batched, self.layout, self.pair = value, batched, layout, pair

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        n, s = obs["section_sd"].shape
        a = np.full((n, s), self.value) if self.batched else np.zeros(s)
        a = {"rows": a, "transposed": a.T, "flat": a.ravel()}[self.layout]
        return (a, state) if self.pair else a


@pytest.mark.parametrize("policy, message", [
    (_Constant(0.7), r"policy 'constant': predict returned actions that are not whole numbers .*\[0\.7"),
    (_Constant(np.nan), r"policy 'constant': predict returned actions that are not whole numbers .*\[nan"),
    (_Constant(0, batched=False), r"policy 'constant': predict returned actions of shape \(6,\) for a batch of 2 "
                                  r"envs; .* shape \(2, 6\)"),
    # a transposed or flat batch has the right size, and was read row by row as other envs' actions
    (_Constant(0, layout="transposed"), r"policy 'constant': predict returned actions of shape \(6, 2\)"),
    (_Constant(0, layout="flat"), r"policy 'constant': predict returned actions of shape \(12,\)"),
    (_Constant(2), r"policy 'constant': predict returned actions outside \[0, 1\]: \[2"),
    (_Constant(-1), r"policy 'constant': predict returned actions outside \[0, 1\]: \[-1"),
    # the actions alone: two envs' rows unpacked into "actions" and "state"
    (_Constant(0, pair=False), r"policy 'constant': predict must return a pair \(actions, state\)"),
    (_Constant, r"policy <class .*_Constant'> has no predict.*\(a class: give an instance of it\)"),
    ("runs/ppo/model.zip", r"has no predict.*\(load a saved model first\)"),
])
def test_a_policys_bad_actions_are_refused_naming_it_not_cast_to_wait(policy, message):
    """The harness casts actions to integers for the vector env: 0.7 or NaN became "wait" (scored as a policy that
    never tamps); now they are refused naming the policy, as the env refuses them; so is one action for a batch."""
    from trackenv.envs.problems import problem_config

    with pytest.raises(ValueError, match=message):
        evaluate_many([policy], problem_config("small").replace(horizon_years=0.5), seeds=[0, 1])
    result = evaluate_many([_Constant(1.0)], problem_config("small").replace(horizon_years=0.5), seeds=[0, 1])
    assert result[0].n_episodes == 2  # whole numbers given as floats are actions


def test_a_plain_function_of_the_batch_is_a_policy():
    """A function of the batched observation returning the actions plays as the same policy written with SB3's
    predict (:class:`CallablePolicy`, named by the function), and its bad actions are refused naming it."""
    from trackenv.envs.problems import problem_config

    def tamp_above(obs):
        return (obs["section_sd"] >= 1.0).astype(int)

    class TampAbove:
        name = "tamp-above-object"

        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            return tamp_above(obs), state

    cfg = problem_config("small").replace(horizon_years=1.0)
    plain, written = evaluate_many([tamp_above, TampAbove()], cfg, seeds=[0, 1])
    assert plain.policy == "tamp_above" and plain.cost.tolist() == written.cost.tolist()
    assert plain.section_tampings.sum() > 0

    def halves(obs):
        return np.full(obs["section_sd"].shape, 0.5)

    with pytest.raises(ValueError, match=r"policy 'halves': predict returned actions that are not whole numbers"):
        evaluate_many([halves], cfg, seeds=[0])


def test_two_policies_of_one_name_stay_two_rows():
    """Two plain lambdas (both named ``<lambda>``) are two results named apart, in the order given, each with its
    own episodes: a table or a paired comparison keyed by name cannot merge them."""
    from trackenv.envs.problems import problem_config

    cfg = problem_config("small").replace(horizon_years=1.0)
    never, always = evaluate_many([lambda obs: np.zeros(obs["section_sd"].shape, dtype=int),
                                   lambda obs: np.ones(obs["section_sd"].shape, dtype=int)], cfg, seeds=[0])
    assert (never.policy, always.policy) == ("<lambda>", "<lambda> (2)")
    assert never.section_tampings.sum() == 0 < always.section_tampings.sum()
