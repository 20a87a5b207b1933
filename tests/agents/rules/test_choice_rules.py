"""The rules that use the choices: their decisions on hand-made observations (drainage where a survey found a wet
cause, spot tamping of a local peak, capacity in work, masks), their memory, and the choice counts of the harness."""

import numpy as np
import pytest

from trackenv.envs.choices import CHOICES, code
from trackenv.envs.line import TampingLine
from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import CHOICE_NAMES, bind_policy, evaluate_many
from trackenv_agents.rules import problems
from trackenv_agents.rules.choices import (
    CHOICE_RULES,
    ChoiceThreshold,
    ChoiceThresholdNoLooking,
    ChoiceThresholdSpotOnly,
    choice_grid,
    choices_off,
    regrowth_mm_per_year,
)
from trackenv_agents.rules.line import LINE_HEURISTICS, GroupedThreshold

CFG = scenario("wet", n_sections=6, capacity=3, horizon_years=1.0)
OFF = {"spot_peak_mm": 0.0, "drain_surveyed": False, "survey_all": False}


def _obs(S=6, **keys):
    """One line's observation (batched, one env): sound track measured a quarter ago, nothing surveyed."""
    obs = {"section_sd": np.full((1, S), 1.0), "section_peak": np.full((1, S), 4.0),
           "register": np.zeros((1, S)), "tampings": np.zeros((1, S)), "tampings_since_renewal": np.zeros((1, S)),
           "years_since_tamping": np.full((1, S), 2.0), "time": np.full((1, 1), 0.5),
           "measurement_age": np.full((1, 1), 0.25), "budget_left": np.ones((1, 1)),
           "section_measurement_age": np.full((1, S), 0.25), "section_survey": np.full((1, S), -1.0)}
    for key, value in keys.items():
        obs[key] = np.asarray(value, dtype=float).reshape(1, S)
    return obs


def _act(rule, obs, config=CFG):
    return bind_policy(rule, config).predict(obs)[0][0]


def test_a_surveyed_wet_section_gets_drainage():
    obs = _obs(section_survey=[-1, 1, 0, -1, -1, -1])
    a = _act(ChoiceThreshold(**{**OFF, "drain_surveyed": True}), obs)
    assert a[1] == code("drainage") and (np.delete(a, 1) == 0).all()
    assert (_act(ChoiceThreshold(**OFF), obs) == 0).all()


def test_a_high_peak_on_low_sd_gets_a_spot_tamping_and_a_campaign_section_a_tamping():
    obs = _obs(section_peak=[4, 13, 13, 4, 4, 4], section_sd=[1.0, 1.0, 3.6, 1.0, 1.0, 1.0])
    a = _act(ChoiceThreshold(**{**OFF, "spot_peak_mm": 12.0}, trigger_mm=3.5, include_mm=3.0), obs)
    assert a.tolist() == [0, code("spot_tamp"), code("tamp"), 0, 0, 0]


def test_surveys_inspections_and_their_absence_without_looking():
    obs = _obs(section_survey=[-1, 0, 1, -1, -1, -1], section_sd=[1.0, 1.0, 1.0, 3.2, 1.0, 1.0],
               section_measurement_age=[0.25, 0.25, 0.25, 0.75, 0.75, 0.25])
    a = _act(ChoiceThreshold(**{**OFF, "survey_all": True, "inspect_margin_mm": 0.5, "inspect_age_years": 0.5},
                             trigger_mm=3.5), obs)
    # not yet surveyed: a survey, unless the section is due an inspection (an old measurement near the trigger)
    assert a.tolist() == [code("survey"), 0, 0, code("inspect"), code("survey"), code("survey")]
    blind = ChoiceThresholdNoLooking(**{**OFF, "drain_surveyed": True, "survey_all": True, "inspect_margin_mm": 0.5})
    assert _act(blind, obs).tolist() == [0, 0, code("drainage"), 0, 0, 0]
    assert "survey_all" not in blind.params


def test_the_spot_only_family_spot_tamps_and_tamps_and_does_nothing_else():
    """Its parameters are the campaign's and the spot peak's; a surveyed wet section, a fast-regrowing one and an
    old measurement near the trigger ask for nothing, as with the grouped threshold."""
    rule = ChoiceThresholdSpotOnly(trigger_mm=3.5, include_mm=3.3, spot_peak_mm=9.0, drain_surveyed=True,
                                   survey_all=True, inspect_margin_mm=0.5, renew_after_tampings=1)
    assert set(rule.params) == {"trigger_mm", "include_mm", "spot_peak_mm"}
    obs = _obs(section_survey=[1, -1, -1, -1, 1, -1], section_peak=[4, 10, 10, 4, 4, 4],
               section_sd=[1.0, 1.0, 3.6, 3.2, 1.0, 1.0], tampings=[2, 0, 0, 0, 2, 0],
               years_since_tamping=[0.5, 2, 2, 2, 0.5, 2], section_measurement_age=[0.25, 0.25, 0.25, 0.75, 0.25, 0.25])
    assert _act(rule, obs).tolist() == [0, code("spot_tamp"), code("tamp"), 0, 0, 0]
    everything = ChoiceThreshold(trigger_mm=3.5, include_mm=3.3, spot_peak_mm=9.0, drain_surveyed=True,
                                 survey_all=True, inspect_margin_mm=0.5)
    assert code("drainage") in _act(everything, obs)  # the same observation asks the full family for more


def test_the_spot_only_grid_and_with_spot_tamping_off_the_grouped_threshold():
    base = {"trigger_mm": 4.0, "include_mm": 2.0}
    grid = choice_grid(ChoiceThresholdSpotOnly, base)
    assert [g["spot_peak_mm"] for g in grid] and all(g["spot_peak_mm"] > 0 for g in grid)
    assert all(set(g) == {"trigger_mm", "include_mm", "spot_peak_mm"} and g.items() >= base.items() for g in grid)
    assert choices_off(ChoiceThresholdSpotOnly) == {"spot_peak_mm": 0.0}
    assert set(choices_off(ChoiceThresholdNoLooking)) < set(choices_off(ChoiceThreshold))
    rng = np.random.default_rng(1)
    obs = {**_obs(), "section_sd": rng.uniform(0.5, 4.5, (4, 6)), "section_peak": rng.uniform(2, 16, (4, 6)),
           "section_survey": rng.integers(-1, 2, (4, 6)).astype(float), "time": np.full((4, 1), 0.5),
           "years_since_tamping": np.full((4, 6), 2.0), "tampings": np.zeros((4, 6)),
           "measurement_age": np.full((4, 1), 0.25), "tampings_since_renewal": np.zeros((4, 6)),
           "section_measurement_age": np.full((4, 6), 0.25), "register": np.zeros((4, 6))}
    off = bind_policy(ChoiceThresholdSpotOnly(**base, **choices_off(ChoiceThresholdSpotOnly)), CFG).predict(obs)[0]
    tamp = bind_policy(GroupedThreshold(**base), CFG.replace(choices=("tamp",), surveyed_share=0.0)).predict(obs)[0]
    assert off.any() and (off == np.where(tamp, code("tamp"), 0)).all()


def test_the_work_fits_the_capacity_worst_measured_sd_first():
    """Drainage takes 2 of the capacity of 3: one drainage and one tamping fit; the section with the worst
    measured SD keeps its choice first."""
    obs = _obs(section_survey=[1, 1, 1, -1, -1, -1], section_sd=[1.2, 1.1, 1.0, 3.6, 1.0, 1.0])
    a = _act(ChoiceThreshold(**{**OFF, "drain_surveyed": True}, trigger_mm=3.5, include_mm=3.0), obs)
    work = CFG.choice_work
    assert sum(work[CHOICES[c]] for c in a if c) <= CFG.capacity
    assert a.tolist() == [code("drainage"), 0, 0, code("tamp"), 0, 0]


def test_masks_disabled_choices_and_work_too_soon_after_the_last():
    obs = _obs(section_survey=[1, 1, -1, -1, -1, -1], section_peak=[4, 4, 13, 4, 4, 4],
               years_since_tamping=[2.0, 0.25, 2.0, 2.0, 2.0, 2.0], tampings=[0, 1, 0, 0, 0, 0])
    rule = ChoiceThreshold(drain_surveyed=True, spot_peak_mm=12.0, survey_all=True)
    # section 1 was tamped last step (min_steps_between_tampings = 1): no track work on it now
    assert _act(rule, obs).tolist() == [code("drainage"), 0, code("spot_tamp")] + [code("survey")] * 3
    tamping_only = CFG.replace(choices=("tamp", "spot_tamp"), surveyed_share=0.0)
    assert _act(rule, obs, tamping_only).tolist() == [0, 0, code("spot_tamp"), 0, 0, 0]


def test_the_rule_remembers_its_spot_tamping_until_a_measurement_after_it():
    """A spot tamping leaves no trace in the observation: the rule's state keeps it, so the peak measured before
    it asks for no second spot tamping, and a measurement after it is read again."""
    rule = bind_policy(ChoiceThreshold(**{**OFF, "spot_peak_mm": 12.0}), CFG)
    obs = _obs(section_peak=[13, 4, 4, 4, 4, 4])
    obs["time"][:] = 0.25  # step 1 of 4
    a, state = rule.predict(obs, state=None, episode_start=np.array([True]))
    assert a[0, 0] == code("spot_tamp")
    for t, age in ((0.75, 0.5), (1.0, 0.75)):  # 2 and 3 steps later, the section not measured since
        later = {**obs, "time": np.full((1, 1), t), "section_measurement_age": np.full((1, 6), age)}
        a, state = rule.predict(later, state=state, episode_start=np.array([False]))
        assert a[0, 0] == 0
    measured = {**later, "section_measurement_age": np.full((1, 6), 0.0)}
    assert rule.predict(measured, state=state, episode_start=np.array([False]))[0][0, 0] == code("spot_tamp")
    assert rule.predict(later, state=state, episode_start=np.array([True]))[0][0, 0] == code("spot_tamp")


def test_a_high_peak_just_tamped_is_inspected_and_then_spot_tamped_if_it_stands():
    """The rule remembers the peak it tamped a section on; the next step (the measurement stale) it inspects the
    section, and on the trolley's fresh peak, still high while the SD is low, it asks for a spot tamping."""
    rule = bind_policy(ChoiceThreshold(**{**OFF, "spot_peak_mm": 12.0}, check_peak_mm=12.0, trigger_mm=3.5,
                                  include_mm=3.0), CFG)
    obs = _obs(section_sd=[4.0, 1, 1, 1, 1, 1], section_peak=[18, 4, 4, 4, 4, 4])
    obs["time"][:] = 0.25
    a, state = rule.predict(obs, state=None, episode_start=np.array([True]))
    assert a[0].tolist() == [code("tamp"), 0, 0, 0, 0, 0]
    tamped = {**obs, "time": np.full((1, 1), 0.5), "tampings": np.array([[1.0, 0, 0, 0, 0, 0]]),
              "years_since_tamping": np.array([[0.25, 2, 2, 2, 2, 2]])}
    a, state = rule.predict(tamped, state=state, episode_start=np.array([False]))
    assert a[0].tolist() == [code("inspect"), 0, 0, 0, 0, 0]
    inspected = {**tamped, "time": np.full((1, 1), 0.75), "years_since_tamping": np.array([[0.5, 2, 2, 2, 2, 2]]),
                 "section_measurement_age": np.array([[0.0, 0.25, 0.25, 0.25, 0.25, 0.25]]),
                 "section_sd": np.array([[1.5, 1, 1, 1, 1, 1]]), "section_peak": np.array([[16.0, 4, 4, 4, 4, 4]])}
    assert rule.predict(inspected, state=state, episode_start=np.array([False]))[0][0].tolist() == [
        code("spot_tamp"), 0, 0, 0, 0, 0]
    quiet = bind_policy(ChoiceThreshold(**{**OFF, "spot_peak_mm": 12.0}, trigger_mm=3.5, include_mm=3.0), CFG)
    _, s = quiet.predict(obs, state=None, episode_start=np.array([True]))
    assert quiet.predict(tamped, state=s, episode_start=np.array([False]))[0][0].tolist() == [0] * 6


def test_regrowth_reads_the_sd_over_the_years_between_tamping_and_measurement():
    obs = _obs(section_sd=[2.0, 2.0, 2.0, 2.0, 2.0, 2.0], tampings=[1, 1, 0, 1, 1, 1],
               years_since_tamping=[1.25, 0.5, 1.25, 0.25, 2.25, 0.3])
    rate = regrowth_mm_per_year(obs)[0]
    assert rate[0] == pytest.approx(2.0) and rate[1] == pytest.approx(8.0)  # 1 year; at least a quarter
    assert rate[2] == 0 and rate[3] == 0  # not tamped in the episode; tamped after the measurement
    assert rate[4] == pytest.approx(1.0)


@pytest.mark.parametrize("cls", list(CHOICE_RULES.values()))
def test_every_grid_point_gives_valid_codes_within_capacity(cls):
    rng = np.random.default_rng(0)
    for params in choice_grid(cls, {"trigger_mm": 3.0, "include_mm": 1.5}):
        obs = {**_obs(), "section_sd": rng.uniform(0.5, 4.0, (3, 6)), "section_peak": rng.uniform(2, 16, (3, 6)),
               "section_survey": rng.integers(-1, 2, (3, 6)).astype(float), "tampings": rng.integers(0, 3, (3, 6)),
               "years_since_tamping": rng.uniform(0.5, 3, (3, 6)), "time": np.full((3, 1), 0.5),
               "measurement_age": np.full((3, 1), 0.25), "tampings_since_renewal": rng.integers(0, 8, (3, 6)),
               "section_measurement_age": rng.uniform(0, 1, (3, 6)), "register": np.zeros((3, 6))}
        a, state = bind_policy(cls(**params), CFG).predict(obs)
        assert a.shape == (3, 6) and a.dtype == np.int8 and state.shape == (3, 3, 6)
        work = np.array([0.0] + [CFG.choice_work[n] for n in CHOICES[1:]])[a].sum(axis=1)
        assert (work <= CFG.capacity).all() and a.min() >= 0 and a.max() < len(CHOICES)
        unused = [code(name) for name in CHOICES[1:] if name not in cls.uses]
        assert not np.isin(a, unused).any()


def test_the_rules_of_a_config_and_their_tuned_files():
    assert problems.rules_for(scenario("default")) is LINE_HEURISTICS
    assert problems.rules_for(CFG) == {**LINE_HEURISTICS, **CHOICE_RULES}
    for name in ("choices", "wet", "defects"):
        assert problems.tuned_file_for(scenario(name)) == problems.TUNED_FILES[name]
        # how the passes are computed does not make another line: the preset keeps its tuned parameters
        fast = scenario(name).replace(engine="fast", pass_reuse_tolerance_m=1e-3)
        assert problems.tuned_file_for(fast) == problems.TUNED_FILES[name]
        # what the line is does: another traffic is no shipped preset
        heavier = scenario(name).replace(annual_mgt=scenario(name).annual_mgt * 1.5)
        assert problems.tuned_file_for(heavier) == problems.LINE_TUNED_FILE
        assert problems.preset_of(fast.replace(horizon_years=2.0)) == name and problems.preset_of(heavier) is None


def test_the_harness_counts_the_applied_choices():
    """The rule surveys every section in the first step (nothing surveyed before: ``surveyed_share`` 0) and
    drains the wet ones found: the counts match the episode's ``info["choices"]``; the tamping rule on the same
    id gets its tampings counted as ``tamp`` (code 1 of its 0/1 action) and nothing else."""
    cfg = CFG.replace(surveyed_share=0.0, horizon_years=0.5)
    rule = ChoiceThreshold(**{**OFF, "survey_all": True, "drain_surveyed": True}, trigger_mm=10.0)
    res = evaluate_many([rule, GroupedThreshold(trigger_mm=1.0, include_mm=1.0)], cfg, [3, 4],
                        action_type="choices", batch_size=4)
    for r, pol in zip(res, (rule, GroupedThreshold(trigger_mm=1.0, include_mm=1.0)), strict=True):
        assert set(r.summary()["choices"]) == set(CHOICE_NAMES)
        for i, seed in enumerate((3, 4)):
            env = TampingLine(cfg, action_type="choices")
            obs, _ = env.reset(seed=seed)
            pol_b, state, counts = bind_policy(pol, cfg), None, dict.fromkeys(CHOICE_NAMES, 0)
            for t in range(cfg.horizon_steps):
                a, state = pol_b.predict(obs, state=state, episode_start=np.array([t == 0]))
                obs, _, _, _, info = env.step(a)
                assert not info["clipped"]
                for name in CHOICE_NAMES:
                    counts[name] += info["choices"][name]
            assert {k: float(v[i]) for k, v in r.choices.items()} == counts
    assert res[0].choices["survey"].tolist() == [cfg.n_sections] * 2
    assert (res[1].choices["tamp"] == res[1].section_tampings).all()
    assert all((res[1].choices[n] == 0).all() for n in CHOICE_NAMES if n != "tamp")


@pytest.mark.slow
def test_trackenv_evaluate_scores_the_choice_rules_and_reports_the_choices(tmp_path, capsys):
    """`trackenv evaluate --env trackenv/TampingLineWet-v0 --seeds 0:2 --json` scores the tamping and the choice
    rules with their shipped parameters, and reports per policy the mean count of each choice."""
    import json

    from trackenv_agents.cli import main

    assert main(["evaluate", "--env", "trackenv/TampingLineWet-v0", "--seeds", "0:2", "--json", "--policy", "rules",
                 "--rules", "grouped-threshold,choice-threshold", "--out", str(tmp_path)]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["action_type"] == "choices" and payload["tuned_from"].startswith("shipped (agents/rules/wet_")
    by = {r["policy"]: r for r in payload["results"]}
    assert set(by) == {"grouped-threshold", "choice-threshold"}
    for r in by.values():
        assert list(r["choices"]) == ["tamp", "spot_tamp", "drainage", "renew", "inspect", "survey"]
    assert by["grouped-threshold"]["choices"]["tamp"] == by["grouped-threshold"]["section_tampings"]
    assert all(by["grouped-threshold"]["choices"][n] == 0 for n in CHOICE_NAMES if n != "tamp")


def test_main_rule_is_the_choice_rule_where_the_config_has_choices_and_one_of_its_rules():
    for name in ("default", "small", "track60", "choices", "wet", "defects"):
        config = scenario(name)
        rule = problems.main_rule(config)
        assert rule in problems.rules_for(config)
        assert (rule == "choice-threshold") == (tuple(config.choices) != ("tamp",))
