"""What a track manager decides per section (``action_type="choices"``): each choice's effect in the physics, the
masks, the possession counted in work, the budget, the info and costs, the configs refused, and the new ids
under the checkers, the vector env and the state API."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from same_results import assert_same

import trackenv  # noqa: F401  (registers the ids)
from trackenv.envs.choices import CHOICES, INTERVENTIONS, choice_counts, code
from trackenv.envs.line import TampingLine
from trackenv.envs.line_config import SLEEPER_SPACING_M, LineConfig, scenario
from trackenv.envs.line_episode import LineBatch
from trackenv.physics.geometry import d1_filter
from trackenv.physics.tamping import line_fit_rows

ALL = {"choices": INTERVENTIONS, "horizon_years": 2.0}
NEW_IDS = ("trackenv/TampingLine-v1", "trackenv/TampingLineWet-v0", "trackenv/TampingLineDefects-v0")
TAMP, SPOT, DRAIN, RENEW, INSPECT, SURVEY = (code(n) for n in INTERVENTIONS)


def _batch(seed: int = 0, **fields) -> LineBatch:
    batch = LineBatch(scenario("small", **{**ALL, **fields}), 1)
    batch.start([0], [np.random.default_rng(seed)])
    return batch


def _codes(batch: LineBatch, **by_section: int) -> np.ndarray:
    out = np.zeros((1, batch.S), dtype=np.int64)
    for j, c in by_section.items():
        out[0, int(j[1:])] = c
    return out


def _env(**fields) -> TampingLine:
    return TampingLine(scenario="small", action_type="choices", **{**ALL, **fields})


# --- the physics of each choice ---
def test_spot_tamping_lifts_the_worst_defect_and_leaves_the_rest_of_the_section():
    batch = _batch(1, local_defects_mean=2.0)
    j = int(np.argmax(batch.peak))
    level, u = batch.level[j].copy(), batch.u[j].copy()
    centre = int(np.argmax(np.abs(batch.d1[j])))
    count, tampings = batch.count[j], batch.tampings[j]
    t = np.zeros(batch.S, dtype=bool)
    t[j] = True
    batch.spot_tamp_rows(t, 0)
    window = np.abs(np.arange(level.size) - centre) <= batch.spot_half
    assert 2 * batch.spot_half + 1 == round(batch.config.spot_tamping_length_m / SLEEPER_SPACING_M) + 1
    np.testing.assert_array_equal(batch.level[j][~window], level[~window])  # outside the window: untouched
    np.testing.assert_array_equal(u[~window], batch.u[j][~window])
    assert (batch.u[j][window] == 0).all() and (batch.cyc[j][window] == 0).all()  # consolidation restarts there
    d1 = np.abs(d1_filter(batch.level[j][None], SLEEPER_SPACING_M)[0])
    assert d1[window].max() < 0.7 * np.abs(batch.d1[j])[window].max()  # the local peak comes down
    assert (batch.count[j], batch.tampings[j]) == (count, tampings)  # a spot is not a tamping of the section
    others = np.arange(batch.S) != j
    np.testing.assert_array_equal(batch.last_work[others], _batch(1, local_defects_mean=2.0).last_work[others])
    assert batch.last_work[j] == 0


def test_a_spot_tamping_on_a_local_defect_lowers_its_peak_more_than_its_sd():
    # the short-defect line at its start: a section whose D1 peak stands at least 3 SDs out is a local defect,
    # and a lift of the few metres around it brings its peak down, on average by more than its SD
    ratios = []
    for seed in range(3):
        batch = LineBatch(scenario("defects", horizon_years=1.0), 1)
        batch.start([0], [np.random.default_rng(seed)])
        local = batch.peak >= 3.0 * batch.sd
        sd, peak = batch.sd[local], batch.peak[local]
        batch.spot_tamp_rows(local, 0)
        d1 = d1_filter(batch.level[local], SLEEPER_SPACING_M)  # one section per segment on this line
        sd_after = batch._segment_sd(d1, np.flatnonzero(local))  # the section's SD: its defects once in 200 m
        ratios.append(np.stack([sd_after / sd, np.abs(d1).max(axis=1) / peak]))
    sd_ratio, peak_ratio = np.concatenate(ratios, axis=1)
    assert sd_ratio.size >= 3
    assert (peak_ratio < 1).all() and peak_ratio.mean() < sd_ratio.mean() and (sd_ratio < 1).all()


def test_drainage_returns_a_wet_patch_to_the_plain_rate_and_stops_a_latent_one():
    batch = _batch(2, wet_spot_probability=1.0, wet_spot_active_share=0.5, drainage_work=0.5)
    plain = batch.base_rate.copy()
    batch.advance(np.zeros((1, batch.S), dtype=np.int64), [0], [])
    active = batch.wet_active.copy()
    assert active.any() and not active.all()
    np.testing.assert_allclose(batch.base_rate[active][batch.wet_mask[active]],
                               plain[active][batch.wet_mask[active]] * batch.config.wet_spot_rate_factor)
    _, _, infos = batch.advance(np.full((1, batch.S), DRAIN), [0], [])
    np.testing.assert_allclose(batch.base_rate, plain, rtol=1e-12)  # active and latent: the plain rate
    assert not batch.wet_present().any() and (batch.survey == 0).all()
    assert infos[0]["costs"]["drainage"] == pytest.approx(6 * batch.config.drainage_cost)
    for _ in range(batch.config.horizon_steps - 3):  # no latent spot starts any more
        batch.advance(np.zeros((1, batch.S), dtype=np.int64), [0], [])
    assert not batch.wet_active.any()
    np.testing.assert_allclose(batch.base_rate, plain, rtol=1e-12)


def test_work_rows_apply_each_sections_choice_as_the_step_does():
    """The engine's per-section entry (what a search over schedules of choices replays) does what the line's step
    applies: a per-section replay of a schedule is the env's episode."""
    a, b = _batch(3, wet_spot_probability=1.0), _batch(3, wet_spot_probability=1.0)
    codes = _codes(a, s0=TAMP, s1=SPOT, s2=DRAIN, s3=RENEW, s4=SURVEY, s5=INSPECT)
    a.apply(codes)
    b.work_rows(codes.ravel(), 0)
    for name in ("offset", "u", "cyc", "base_rate", "wet_onset", "wet_active", "count", "tampings", "last_work",
                 "survey", "measured_sd"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert b.wet_onset[2] == -1 and b.survey[4] in (0, 1) and b.count[3] == 0


def test_a_wet_spot_works_from_its_onset_step_on():
    batch = _batch(2, wet_spot_probability=1.0, horizon_years=1.0)
    onset = batch.wet_onset.copy()  # one section per segment on the line presets
    assert (onset > 0).any()
    for t in range(batch.config.horizon_steps):
        np.testing.assert_array_equal(batch.wet_working_rows(t), (onset >= 0) & (onset <= t))
        batch.traffic()


def test_drainage_of_a_dry_section_changes_nothing_but_is_paid():
    batch = _batch(3, wet_spot_probability=0.0)
    rate = batch.base_rate.copy()
    _, _, infos = batch.advance(_codes(batch, s2=DRAIN), [0], [])
    np.testing.assert_array_equal(batch.base_rate, rate)
    assert infos[0]["costs"]["drainage"] == batch.config.drainage_cost
    assert infos[0]["costs"]["possession"] == batch.config.possession_cost
    assert infos[0]["section_costs"][2] >= batch.config.drainage_cost


def test_renewal_resets_the_count_and_the_shape():
    batch = _batch(4, initial_max_tampings=6)
    j = int(np.argmax(batch.count))
    assert batch.count[j] > 0
    t = np.zeros(batch.S, dtype=bool)
    t[j] = True
    before = batch.level[j].copy()
    batch.tamp_rows(t, 0, renew=t)
    assert batch.count[j] == 0 and batch.tampings[j] == 1 and batch.last_tamped[j] == 0
    # nothing of the old shape is kept: the least-squares line of the old level plus the machine's residual
    np.testing.assert_allclose(batch.level[j] - line_fit_rows(before[None])[0],
                               batch.tm.residual_sd_m * batch.tamp_noise[0, j], atol=1e-15)
    np.testing.assert_allclose(batch.rate()[j], batch.base_rate[j])  # the rate factor's growth reset


def test_renewal_costs_a_tamping_and_a_renewal():
    batch = _batch(4)
    costs = batch.advance(_codes(batch, s1=RENEW), [0], [])[2][0]["costs"]
    c = batch.config
    assert (costs["tamping"], costs["renewal"]) == (c.section_tamping_cost, c.section_renewal_cost)


def test_inspection_measures_that_section_only_and_resets_its_age():
    env = _env(measurement_interval=100)
    obs, _ = env.reset(seed=5)
    for _ in range(2):
        obs, *_ = env.step(np.zeros(6, dtype=np.int64))
    action = np.zeros(6, dtype=np.int64)
    action[3] = INSPECT
    new, _, _, _, info = env.step(action)
    age = new["section_measurement_age"]
    assert age[3] == 0 and np.allclose(np.delete(age, 3), 0.75)
    np.testing.assert_array_equal(np.delete(new["section_sd"], 3), np.delete(obs["section_sd"], 3))
    noise = env.config.inspection_sd_noise_mm
    assert abs(new["section_sd"][3] - info["section_sd_mm"][3]) < 5 * noise
    assert new["section_sd"][3] != obs["section_sd"][3]
    assert info["costs"]["inspection"] == env.config.inspection_cost and info["costs"]["possession"] == 0


def test_the_recording_car_resets_every_sections_age():
    env = _env(measurement_interval=2)
    env.reset(seed=0)
    action = np.zeros(6, dtype=np.int64)
    action[0] = INSPECT
    obs = env.step(action)[0]
    assert obs["section_measurement_age"][0] == 0 and (obs["section_measurement_age"][1:] == 0.25).all()
    obs = env.step(np.zeros(6, dtype=np.int64))[0]
    assert (obs["section_measurement_age"] == 0).all()


def test_a_measurement_of_some_sections_dates_those_sections_only():
    """``measure_rows`` (a recording-car reading of some sections, as the per-section forks take one) dates what
    it measured, as the line's run and the trolley do: a fork's fresh measurement does not read as an old one."""
    batch = _batch(measurement_interval=100)
    before = batch.measured_at.copy()
    seg = np.zeros(batch.S, dtype=bool)
    seg[[1, 4]] = True
    batch.measure_rows(seg, 3)
    assert (batch.measured_at[seg] == 3).all()
    np.testing.assert_array_equal(batch.measured_at[~seg], before[~seg])


def test_a_survey_reveals_whether_a_wet_spot_is_there():
    env = _env(wet_spot_probability=0.5)
    obs, _ = env.reset(seed=6)
    assert (obs["section_survey"] == -1).all()
    truth = env.unwrapped.engine.wet_present()
    assert truth.any() and not truth.all()
    obs, _, _, _, info = env.step(np.full(6, SURVEY))
    np.testing.assert_array_equal(obs["section_survey"], truth.astype(np.float32))
    assert info["costs"]["survey"] == pytest.approx(6 * env.config.survey_cost) and info["costs"]["possession"] == 0


def test_a_line_surveyed_before_the_start_shows_what_was_found():
    batch = _batch(7, wet_spot_probability=0.5, surveyed_share=0.6)
    known = batch.survey >= 0
    assert known.any() and not known.all()
    np.testing.assert_array_equal(batch.survey[known], batch.wet_present()[known])


def test_local_defects_and_early_wet_spots_are_drawn_only_where_asked():
    a, b = _batch(8), _batch(8, local_defects_mean=3.0)
    assert (b.base_rate >= a.base_rate).all() and (b.base_rate > a.base_rate).any()
    c = _batch(9, wet_spot_probability=1.0, wet_spot_active_share=1.0)
    assert (c.wet_onset == 0).all()


def test_one_defect_per_section_weighs_the_defects_neighbourhood_by_its_length():
    # a hand-made D1 level on the 51 sleepers of a 30 m segment: 10 (6 m) near a defect at ±4 mm, 40 of the other
    # 41 at ±1 mm and the last at 0 (mean 0), on a 200 m section: SD² = (6·16 + 194·40/41) / 200 mm², below the
    # segment's own (10·16 + 40) / 51 mm²
    batch = _batch(0, local_defects_mean=1.0, local_defect_near_m=3.0)
    n = batch.config.n_sleepers
    assert n == 51
    near = np.zeros((2, n), dtype=bool)
    near[0, 20:30] = True
    sign = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    sign[-1] = 0.0
    d1 = np.stack([np.where(near[0], 4.0, 1.0) * sign, sign]) * 1e-3
    batch.defect_near[:2] = near
    sd = batch._segment_sd(d1, np.arange(2))
    assert sd[0] == pytest.approx(np.sqrt((6.0 * 16 + 194.0 * 40 / 41) / 200) * 1e-3, rel=1e-12)
    assert sd[0] < d1[0].std()
    assert sd[1] == pytest.approx(d1[1].std(), rel=1e-12)  # no defect: the segment's own SD


def test_one_defect_per_section_changes_the_sd_where_a_defect_is_and_never_the_peak():
    fields = {"local_defects_mean": 1.0, "switch_probability": 0.0, "transition_probability": 0.0}
    plain, once = _batch(3, **fields), _batch(3, **fields, local_defect_near_m=3.0)
    has = once.defect_near.any(axis=1)
    assert has.any() and not has.all()
    np.testing.assert_array_equal(once.peak, plain.peak)  # the same draws and physics
    np.testing.assert_allclose(once.sd[~has], plain.sd[~has], rtol=1e-12)
    assert (once.sd[has] != plain.sd[has]).all()
    assert once.sd[has].mean() < plain.sd[has].mean()  # a defect in 200 m of track, not in every 30 m
    assert not plain.defect_near.any()  # off: nothing kept


def test_a_local_defect_in_a_zone_keeps_the_faster_rate_where_asked():
    # every section a switch (4x the plain rate): a defect at 2.5x the plain rate adds nothing there with
    # "faster", and multiplies the zone's with "multiply" (the default)
    fields = {"local_defects_mean": 2.0, "switch_probability": 1.0, "transition_probability": 0.0,
              "wet_spot_probability": 0.0}
    times, faster = _batch(4, **fields), _batch(4, **fields, local_defect_in_zone="faster")
    zone_only = _batch(4, **{**fields, "local_defect_rate_factor": 1.0})
    patches = times.base_rate > zone_only.base_rate * 1.01
    assert patches.any()
    np.testing.assert_allclose(times.base_rate[patches], 2.5 * zone_only.base_rate[patches], rtol=1e-12)
    np.testing.assert_allclose(faster.base_rate, zone_only.base_rate, rtol=1e-12)


# --- masks, capacity in work, budget ---
def test_masks_follow_the_config_the_last_work_and_the_capacity():
    env = _env(choices=("tamp", "drainage", "inspect"), capacity=2, drainage_work=2.0)
    assert env.action_space == gym.spaces.MultiDiscrete([len(CHOICES)] * 6)
    before = env.action_masks().reshape(6, len(CHOICES))
    enabled = np.isin(CHOICES, ("nothing", "tamp", "drainage", "inspect"))
    assert (before == enabled).all()
    env.reset(seed=0)
    mask = env.action_masks().reshape(6, len(CHOICES))
    free = env.unwrapped.engine.allowed()[0]
    assert free.any() and not free.all()  # some sections were tamped just before the start
    np.testing.assert_array_equal(mask[free], np.broadcast_to(enabled, mask[free].shape))
    np.testing.assert_array_equal(mask[~free][:, [TAMP, DRAIN]], False)
    j = int(np.flatnonzero(free)[0])
    action = np.zeros(6, dtype=np.int64)
    action[j] = DRAIN
    env.step(action)
    mask = env.action_masks().reshape(6, len(CHOICES))
    assert mask[j].tolist() == [True, False, False, False, False, True, False]  # no track work next step
    assert env.action_masks().dtype == bool and env.action_masks().shape == (6 * len(CHOICES),)


def test_work_that_cannot_fit_is_masked_and_the_possession_counts_work():
    env = _env(capacity=2, drainage_work=2.0, renewal_work=3.0, spot_tamping_work=0.5, min_steps_between_tampings=0)
    env.reset(seed=1)
    mask = env.action_masks().reshape(6, -1)
    assert mask[:, DRAIN].all() and not mask[:, RENEW].any()  # renewal's work of 3 never fits in 2
    sd = env.unwrapped.engine.measured_sd.copy()
    # two drainages (work 4) do not fit in 2: the worse section by measured SD keeps its choice
    action = np.zeros(6, dtype=np.int64)
    action[[0, 1]] = DRAIN
    info = env.step(action)[4]
    kept = int(np.argmax(sd[[0, 1]]))
    assert info["clipped"]
    assert info["section_choices"].tolist() == [DRAIN if i == kept else 0 for i in range(2)] + [0] * 4
    # four spot tampings (work 2) fit, and an inspection takes none of the possession
    action = np.array([0, 0, SPOT, SPOT, SPOT, SPOT])
    env.step(np.zeros(6, dtype=np.int64))
    action[0] = INSPECT
    info = env.step(action)[4]
    assert not info["clipped"] and info["choices"]["spot_tamp"] == 4 and info["choices"]["inspect"] == 1
    assert info["costs"]["possession"] == env.config.possession_cost


def test_over_capacity_raise_names_the_work():
    env = _env(capacity=2, drainage_work=2.0, over_capacity="raise", min_steps_between_tampings=0)
    env.reset(seed=1)
    with pytest.raises(ValueError, match="track work of 4 tamping sections.*capacity is 2"):
        env.step(np.array([DRAIN, DRAIN, 0, 0, 0, 0]))


def test_over_capacity_raise_makes_a_masked_choice_nothing():
    """With ``over_capacity="raise"`` a choice the masks forbid alone (a renewal's work of 3 in a possession of 2;
    a drainage the budget left cannot pay) becomes nothing, as with "clip", instead of raising; what the masks
    allow, asked for together beyond the capacity, still raises (above)."""
    env = _env(capacity=2, renewal_work=3.0, over_capacity="raise", min_steps_between_tampings=0)
    env.reset(seed=1)
    assert not env.action_masks().reshape(6, -1)[0, RENEW]
    info = env.step(np.array([RENEW, 0, 0, 0, 0, 0]))[4]
    assert info["section_choices"].tolist() == [0] * 6 and info["cost"] > 0
    env = _env(annual_budget=16.0, over_capacity="raise", min_steps_between_tampings=0)
    env.reset(seed=1)
    mask = env.action_masks().reshape(6, -1)
    assert not mask[0, DRAIN] and mask[0, INSPECT]
    info = env.step(np.array([DRAIN, INSPECT, 0, 0, 0, 0]))[4]
    assert info["section_choices"].tolist() == [0, INSPECT, 0, 0, 0, 0]


def test_the_budget_masks_what_it_cannot_pay_and_drops_the_mildest():
    env = _env(annual_budget=20.0, min_steps_between_tampings=0)
    env.reset(seed=2)
    mask = env.action_masks().reshape(6, -1)
    assert not mask[:, DRAIN].any() and not mask[:, RENEW].any() and mask[:, TAMP].all() and mask[:, SURVEY].all()
    info = env.step(np.array([TAMP, TAMP, TAMP, INSPECT, 0, 0]))[4]  # 15 + 3 x 2 + 0.3 > 20: one is dropped
    assert info["clipped"] and sum(info["choices"].values()) == 3
    assert sum(info["costs"][k] for k in ("possession", "tamping", "inspection")) <= 20.0


def test_disabled_choices_and_early_track_work_become_nothing():
    env = _env(choices=("tamp",))
    env.reset(seed=0)
    order = np.argsort(env.unwrapped.engine.allowed()[0], kind="stable")  # a free section last
    action = np.zeros(6, dtype=np.int64)
    action[order] = [SPOT, DRAIN, RENEW, INSPECT, SURVEY, TAMP]
    info = env.step(action)[4]
    assert info["section_choices"].tolist() == np.where(action == TAMP, TAMP, 0).tolist()
    info = env.step(np.where(action == TAMP, TAMP, 0))[4]  # tamped last step: masked
    assert info["choices"] == dict.fromkeys(INTERVENTIONS, 0)


# --- info, costs, compatibility ---
def test_info_counts_the_choices_and_the_reward_is_the_sum_of_the_parts():
    env = _env(capacity=6, renewal_work=2.0, min_steps_between_tampings=0)
    env.reset(seed=3)
    action = np.array([TAMP, SPOT, DRAIN, RENEW, INSPECT, SURVEY])
    obs, reward, _, _, info = env.step(action)
    assert info["choices"] == choice_counts(action) == dict.fromkeys(INTERVENTIONS, 1)
    assert tuple(info["costs"]) == LineConfig.cost_keys()
    assert reward == pytest.approx(-sum(info["costs"].values()), rel=1e-12)
    assert info["tamped_sections"].tolist() == [True, False, False, True, False, False]
    assert info["section_costs"].sum() + info["costs"]["possession"] == pytest.approx(-reward, rel=1e-12)
    assert env.observation_space.contains(obs)


def test_a_tamping_the_budget_cannot_pay_is_masked_in_every_action_type():
    """With an annual budget below a possession and a tamping, the tamp-or-wait masks (MultiBinary, Discrete)
    forbid every tamping, as the choice masks' tamping column does: a masked learner is never offered what the env
    would drop."""
    config = LineConfig(n_sections=6, horizon_years=1.0, annual_budget=10.0)  # < 15 possession + 2 tamping
    for action_type, width in (("multibinary", 2), ("discrete", None), ("choices", len(CHOICES))):
        env = TampingLine(config, action_type=action_type)
        env.reset(seed=3)
        mask = env.action_masks()
        tamp = mask[1:] if width is None else mask.reshape(6, width)[:, 1]
        assert not tamp.any(), action_type
    env = TampingLine(config.replace(annual_budget=100.0))
    env.reset(seed=3)
    allowed = env.unwrapped.engine.allowed()[0]  # affordable: the gap since the last tamping decides
    assert allowed.sum() >= 3 and env.action_masks().reshape(6, 2)[:, 1].tolist() == allowed.tolist()


def test_tamping_as_choices_is_tamping_as_multibinary():
    a = TampingLine(scenario="small", horizon_years=1.0)
    b = TampingLine(scenario="small", horizon_years=1.0, action_type="choices")
    rng = np.random.default_rng(0)
    a.reset(seed=4)
    b.reset(seed=4)
    for _ in range(4):
        act = (rng.random(6) < 0.5).astype(np.int8)
        assert_same(a.step(act)[:4], b.step(act.astype(np.int64))[:4])
        np.testing.assert_array_equal(a.action_masks(), b.action_masks().reshape(6, -1)[:, :2].ravel())


@pytest.mark.parametrize("fields, match", [
    ({"choices": "tamp"}, "choices must be"),
    ({"choices": ("tamp", "grind")}, "choices must be"),
    ({"choices": ("tamp", "tamp")}, "choices must be"),
    ({"choices": ()}, "choices must be"),
    ({"choices": ("tamp",), "surveyed_share": 0.5}, "surveyed_share"),
    ({"drainage_work": 101.0}, "drainage_work"),
    ({"spot_tamping_length_m": 0.1}, "spot_tamping_length_m"),
    ({"spot_tamping_length_m": 100.0}, "segment_length_m"),
    ({"drainage_cost": -1.0}, "drainage_cost"),
    ({"inspection_sd_noise_mm": float("nan")}, "inspection_sd_noise_mm"),
    ({"wet_spot_active_share": 1.5}, "wet_spot_active_share"),
    ({"local_defects_mean": -1}, "local_defects_mean"),
    ({"local_defect_rate_factor": 0.0}, "local_defect_rate_factor"),
    ({"local_defect_near_m": -1.0}, "local_defect_near_m"),
    ({"local_defect_near_m": 20.0}, "segment_length_m"),
    ({"local_defect_in_zone": "add"}, "local_defect_in_zone"),
])
def test_bad_choice_fields_are_refused_by_name(fields, match):
    with pytest.raises(ValueError, match=match):
        LineConfig(**fields)


def test_one_defect_per_section_needs_a_segment_per_section():
    with pytest.raises(ValueError, match="local_defect_near_m = 3 needs sections_per_segment = 1"):
        scenario("track60", local_defect_near_m=3.0)


def test_choices_are_stored_in_their_canonical_order():
    assert LineConfig(choices=["survey", "tamp"]).choices == ("tamp", "survey")
    assert LineConfig.from_dict(LineConfig(choices=("inspect",)).to_dict()).choices == ("inspect",)


def test_tamping_only_configs_keep_their_observation():
    space = gym.make("trackenv/TampingLine-v0").observation_space
    assert "section_survey" not in space.spaces and "section_measurement_age" not in space.spaces


# --- the new ids ---
@pytest.mark.parametrize("env_id", NEW_IDS)
def test_new_ids_pass_the_checkers(env_id):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check

    env = gym.make(env_id, horizon_years=0.75, n_sections=4, capacity=3)
    assert env.action_space == gym.spaces.MultiDiscrete([len(CHOICES)] * 4)
    assert {"section_survey", "section_measurement_age", "section_contact_peak"} <= set(env.observation_space.spaces)
    check_env(env.unwrapped, skip_render_check=True)
    sb3_check(env.unwrapped, warn=False)


@pytest.mark.parametrize("env_id", NEW_IDS)
def test_new_ids_vector_env_equals_single_envs(env_id):
    kw = {"horizon_years": 0.75, "n_sections": 4, "capacity": 3}
    vec = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point", **kw)
    singles = [gym.make(env_id, **kw) for _ in range(2)]
    obs, _ = vec.reset(seed=[10, 11])
    for i, env in enumerate(singles):
        o, _ = env.reset(seed=10 + i)
        assert_same({k: v[i] for k, v in obs.items()}, o)
    rng = np.random.default_rng(1)
    for _ in range(2):
        masks = vec.unwrapped.action_masks().reshape(2, 4, -1)
        actions = np.array([[rng.choice(np.flatnonzero(m)) for m in row] for row in masks])
        obs, rewards, _, _, _ = vec.step(actions)
        for i, env in enumerate(singles):
            np.testing.assert_array_equal(env.unwrapped.action_masks(), masks[i].ravel())
            o, r, *_ = env.step(actions[i])
            assert r == rewards[i]
            assert_same({k: v[i] for k, v in obs.items()}, o)


def test_new_fields_round_trip_through_the_state_api():
    env = gym.make("trackenv/TampingLineWet-v0", horizon_years=1.5, n_sections=4, capacity=3)
    env.reset(seed=12)
    env.step(np.array([SURVEY, INSPECT, SPOT, DRAIN]))
    state = env.unwrapped.get_state()
    future = [np.array([INSPECT, DRAIN, SURVEY, SPOT]), np.array([RENEW, INSPECT, 0, SURVEY])]
    first = [env.step(a)[:4] for a in future]
    env.unwrapped.set_state(state)
    assert_same(tuple(first), tuple(env.step(a)[:4] for a in future))
    for name in ("last_work", "measured_at", "survey"):
        assert name in state.episode.rows
    assert "inspect_noise" in state.episode.noise


def test_the_wet_line_starts_with_known_wet_spots():
    env = gym.make("trackenv/TampingLineWet-v0")
    found = sum(int((env.reset(seed=s)[0]["section_survey"] == 1).sum()) for s in range(3))
    assert found >= 3


def test_the_section_level_flat_and_mask_wrappers_take_the_choices():
    from trackenv.envs.wrappers import ActionMaskObservation, RankedActions, SectionObservation

    base = gym.make("trackenv/TampingLine-v1", horizon_years=0.5, n_sections=4, capacity=3)
    flat = gym.wrappers.FlattenObservation(SectionObservation(base))
    obs, _ = flat.reset(seed=0)
    assert flat.observation_space.contains(obs)
    np.testing.assert_array_equal(flat.get_wrapper_attr("action_masks")(), base.unwrapped.action_masks())
    masked = ActionMaskObservation(base)
    obs, _ = masked.reset(seed=0)
    assert obs["action_mask"].shape == (4 * len(CHOICES),) and masked.observation_space.contains(obs)
    # the ranked form of the choices: one count per choice (tests/envs/test_ranking.py)
    assert RankedActions(base).action_space == gym.spaces.MultiDiscrete([5] * len(INTERVENTIONS))


def test_a_line_files_known_wet_zones_read_as_surveyed_wet():
    """A section the line file marks wet has its survey known from the start (section_survey = 1 on every seed),
    so a rule that surveys what is not yet surveyed does not pay to survey it; the other sections keep the
    scenario's drawn surveys."""
    from pathlib import Path

    example = Path(trackenv.__file__).parent / "lines" / "example.yaml"
    cfg = scenario("wet", line=str(example), surveyed_share=0.0)
    known = np.array([s.wet for s in cfg.line.sections])
    env = TampingLine(cfg, action_type="choices")
    for seed in (0, 1):
        obs, _ = env.reset(seed=seed)
        assert known.any() and (obs["section_survey"][known] == 1).all()
        assert (obs["section_survey"][~known] == -1).all()  # none drawn at surveyed_share 0
