"""The model-predictive planner: its closed-form forecast sums, its plan against every schedule of a small line,
its checks, and a run through the evaluation harness."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import evaluate_many
from trackenv_agents.rules.line import LINE_HEURISTICS
from trackenv_agents.rules.model_predictive import ModelPredictive, interval_square_sums

TRACK60 = scenario("track60", horizon_years=1.5)  # 6 steps


def test_interval_square_sums_are_the_sums_they_say():
    rng = np.random.default_rng(0)
    for _ in range(50):
        v, h = rng.normal(2.0, 1.0), rng.normal(0.05, 0.05)
        ref = int(rng.integers(-2, 5))
        a = int(rng.integers(ref + 1, 10))
        b = int(rng.integers(a - 2, 14))
        brute = sum((v + h * (tau - ref)) ** 2 for tau in range(a, b))
        got = interval_square_sums(np.array(v), np.array(h), np.array(ref), np.array(a), np.array(b))
        assert got == pytest.approx(brute, rel=1e-12, abs=1e-12)


def _forecast_cost(planner: ModelPredictive, sd, growth, step, schedule) -> float:
    """The planner's model priced step by step for a (steps, S) bool schedule from ``step`` on."""
    p, costs = planner.params, planner.costs
    total = costs["possession"] * schedule.any(axis=1).sum()
    for i in range(len(sd)):
        v, h, ahead = sd[i], growth[i], 0  # ahead: steps since the SD was last known (now, or a tamping)
        for k in range(planner.horizon_steps - step):
            if schedule[k, i]:
                v = p["tamped_sd_offset_mm"] + p["tamped_sd_slope"] * v + p["regrowth_factor"] * growth[i]
                h = p["regrowth_factor"] * growth[i]
                total += costs["tamping"][i]
                ahead = 1
            else:
                v = v + h
                ahead += 1
            # the expected square: the forecast's square plus the variance of an error grown by σ a step
            total += costs["geometry"][i] * (v * v + (p["forecast_error_mm_per_step"] * ahead) ** 2)
    return float(total)


@pytest.mark.parametrize("error", [0.0, 0.05])
def test_the_plan_is_the_cheapest_schedule_of_its_model_on_a_small_line(error):
    planner = ModelPredictive(max_campaigns=2, forecast_error_mm_per_step=error).bind(TRACK60)
    planner.costs = {**planner.costs, "tamping": planner.costs["tamping"][:2],  # two of its sections: every
                     "geometry": planner.costs["geometry"][:2]}  # schedule of both can be priced here
    rng = np.random.default_rng(1)
    for step in (0, 3):
        steps = planner.horizon_steps - step
        for _ in range(4):
            sd, growth = rng.uniform(0.5, 4.0, 2), rng.uniform(0.0, 0.3, 2)
            best = min(
                (_forecast_cost(planner, sd, growth, step, np.array(bits, dtype=bool).reshape(steps, 2)), bits)
                for bits in itertools.product((0, 1), repeat=2 * steps)
                if np.array(bits).reshape(steps, 2).any(axis=1).sum() <= 2)  # at most max_campaigns campaign steps
            cost, campaigns, sections = planner.plan(sd, growth, step)
            assert cost == pytest.approx(best[0], rel=1e-9)
            schedule = np.zeros((steps, 2), dtype=bool)
            for i, tamped in enumerate(sections):
                schedule[[t - step for t in tamped], i] = True
            assert _forecast_cost(planner, sd, growth, step, schedule) == pytest.approx(cost, rel=1e-9)
            assert set(campaigns) == set(np.flatnonzero(schedule.any(axis=1)) + step)


def test_it_tamps_what_pays_and_nothing_whose_benefit_comes_after_the_horizon():
    planner = ModelPredictive().bind(TRACK60)
    last = planner.horizon_steps - 1
    smooth, rough = np.full(6, 0.3), np.array([4.0, 4.0, 0.3, 0.3, 0.3, 0.3])
    assert planner.plan(smooth, np.full(6, 0.01), 0)[1] == ()
    cost, campaigns, sections = planner.plan(rough, np.full(6, 0.1), 0)
    assert campaigns[:1] == (0,) and sections[0][:1] == (0,) and sections[2] == ()
    assert planner.plan(rough, np.full(6, 0.1), last)[1] == ()  # one step of benefit does not pay a campaign


def test_an_uncertain_forecast_makes_a_long_wait_dearer():
    sd, growth = np.full(6, 1.5), np.full(6, 0.02)
    certain = ModelPredictive(forecast_error_mm_per_step=0.0).bind(TRACK60).plan(sd, growth, 0)
    uncertain = ModelPredictive(forecast_error_mm_per_step=0.5).bind(TRACK60)
    assert certain[1] == ()  # the mean forecast does not pay a campaign within the horizon
    cost, campaigns, _ = uncertain.plan(sd, growth, 0)
    assert campaigns != () and cost > certain[0]  # the error's variance does, and the line costs more


def test_it_checks_its_parameters_and_its_config():
    with pytest.raises(ValueError, match=r"tamped_sd_slope must lie in \[0, 1\], got 1.5"):
        ModelPredictive(tamped_sd_slope=1.5)
    with pytest.raises(ValueError, match=r"own_slope_weight must lie in \[0, 1\], got -0.1"):
        ModelPredictive(own_slope_weight=-0.1)
    with pytest.raises(ValueError, match="regrowth_factor must be a real number"):
        ModelPredictive(regrowth_factor="1.5")  # text is not read as a number
    with pytest.raises(ValueError, match="neighbour_mm must be a finite number"):
        ModelPredictive(neighbour_mm=float("nan"))
    with pytest.raises(ValueError, match=r"forecast_error_mm_per_step must lie in \[0, 1\], got -0.01"):
        ModelPredictive(forecast_error_mm_per_step=-0.01)
    with pytest.raises(ValueError, match=r"max_campaigns must be an integer in \[1, 4\], got 0"):
        ModelPredictive(max_campaigns=0)
    with pytest.raises(ValueError, match="window_steps must be an integer"):
        ModelPredictive(window_steps=True)
    with pytest.raises(ValueError, match="max_campaigns=4 over a horizon of 80 steps makes .* plans, more than"):
        ModelPredictive(max_campaigns=4).bind(scenario("track60", horizon_years=20.0))
    with pytest.raises(ValueError, match="measurement_interval must be 1 and sd_noise_mm 0"):
        ModelPredictive().bind(scenario("default"))
    with pytest.raises(ValueError, match="bind the planner"):
        ModelPredictive().predict({"section_sd": np.zeros(6)})
    assert ModelPredictive.name not in LINE_HEURISTICS  # never the reference scores are normalised to


def test_it_plays_episodes_through_the_harness_keeping_its_history():
    config = scenario("track60")
    planner = ModelPredictive()
    result = evaluate_many([planner], config, [3000, 3003], batch_size=2)[0]
    alone = evaluate_many([planner], config, [3003], batch_size=1)[0]
    assert np.isfinite(result.cost).all() and result.tamped.any()
    assert alone.cost[0] == result.cost[1]  # an episode's plan does not depend on its batch
    bound = planner.bind(config)
    obs = {"section_sd": np.full(6, 1.0, dtype=np.float32), "years_since_tamping": np.full(6, 2.0, np.float32),
           "time": np.zeros(1, np.float32)}
    action, state = bound.predict(obs)  # no state: the current SD only, at the prior growth
    assert action.shape == (6,) and state[0].shape == (1, 1, 6)
    later = {**obs, "section_sd": np.full(6, 1.2, dtype=np.float32), "time": np.full(1, 0.1, np.float32)}
    _, (history, since, slope) = bound.predict(later, state)
    assert history.shape == (1, 2, 6) and (since == 1).all()  # a slope from two observations
    assert (slope == bound.params["tamped_sd_slope"]).all()  # no tamping seen: the prior
    _, (_, since, _) = bound.predict(later, state, episode_start=np.array([True]))
    assert (since == 0).all()  # a new episode: no slope from the last one's SD
    # a section tamped in the step just run (a quarter since) that barely improved: its own slope rises
    tamped = {**later, "years_since_tamping": np.array([0.25, 2.1, 2.1, 2.1, 2.1, 2.1], np.float32),
              "section_sd": np.array([0.96, 1.2, 1.2, 1.2, 1.2, 1.2], np.float32)}
    _, (_, since, slope) = bound.predict(tamped, state)
    prior = bound.params["tamped_sd_slope"]
    assert since[0, 0] == 0 and (slope == prior).all()  # by default a tamping's outcome does not move the slope
    learning = ModelPredictive(own_slope_weight=0.5).bind(config)
    _, (_, since, slope) = learning.predict(tamped, state)
    assert since[0, 0] == 0 and slope[0, 0] == pytest.approx(0.5 * (prior + 0.9 / 1.0))
    assert (slope[0, 1:] == prior).all()


def test_a_campaign_takes_the_neighbours_of_its_sections_from_their_sd():
    config = scenario("track60")
    obs = {"section_sd": np.array([0.3, 1.5, 6.0, 0.5, 1.2, 0.2], np.float32),
           "years_since_tamping": np.full(6, 3.0, np.float32), "time": np.zeros(1, np.float32)}
    alone, _ = ModelPredictive(neighbour_mm=0.0).bind(config).predict(obs)
    grouped, _ = ModelPredictive(neighbour_mm=1.0).bind(config).predict(obs)
    assert alone[2] == 1 and grouped[2] == 1  # the rough section is tamped now
    assert grouped[1] == 1 and grouped[3] == alone[3]  # its neighbour at 1.5 mm joins; the one at 0.5 mm does not
