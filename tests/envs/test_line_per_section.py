"""A section's own speed, traffic and length (``LineConfig.per_section``): each changes that section's passes,
degradation, limits, costs and work, and nothing of the other sections; bad values are refused naming the field."""

from __future__ import annotations

import numpy as np
import pytest

from trackenv.envs.line_config import LineConfig
from trackenv.envs.line_episode import LineBatch
from trackenv.physics.geometry import QualityLimits

# four plain sections at 120 km/h on short segments, no hidden wet spots: each test changes section 1 only
BASE = dict(n_sections=4, capacity=4, segment_length_m=18.0, speed_kmh=120.0, transition_probability=0.0,
            switch_probability=0.0, wet_spot_probability=0.0, horizon_years=1.0, min_steps_between_tampings=0)


def run(steps: int = 1, seed: int = 3, **per_section) -> LineBatch:
    """A batch of one line of BASE with ``per_section`` values, after ``steps`` steps without work."""
    batch = LineBatch(LineConfig(**BASE, per_section=per_section), 1)
    batch.start([0], [np.random.default_rng(seed)])
    for _ in range(steps):
        batch.advance(np.zeros((1, 4), dtype=np.int64), [0], [np.random.default_rng(0)])
    return batch


@pytest.fixture(scope="module")
def line_speed() -> LineBatch:
    return run()


def test_a_slower_section_has_its_own_forces_settlement_and_limits(line_speed):
    slow = run(speed_kmh=(120.0, 80.0, 120.0, 120.0))
    # the section's passes run at its own speed: its wheel/rail force (hardly changed on sound track, where the
    # dynamic part is small) and the settlement its ballast forces drive differ, on section 1 only
    assert slow.contact_force[1] != line_speed.contact_force[1]
    assert slow.u[1].mean() != line_speed.u[1].mean()
    others = [0, 2, 3]
    np.testing.assert_array_equal(slow.contact_force[others], line_speed.contact_force[others])
    np.testing.assert_array_equal(slow.u[others], line_speed.u[others])
    # its quality limits are those of its speed band (EN 13848-5: up to 80 km/h), the others' of 120 km/h
    table = QualityLimits.en13848()
    limits = slow.section_limits("intervention_m")
    assert limits[1] == table.for_speed(80 / 3.6).intervention_m
    assert (limits[others] == table.for_speed(120 / 3.6).intervention_m).all() and limits[1] != limits[0]
    peak = np.full(4, (limits[0] + limits[1]) / 2)  # between the two bands' intervention limits
    classes = slow.classify_rows(peak)
    assert classes[1] != classes[0] and (classes[others] == classes[0]).all()


def test_a_freight_heavier_section_degrades_faster(line_speed):
    freight = run(freight_share=(0.4, 0.8, 0.4, 0.4))
    assert freight.u[1].mean() > 1.05 * line_speed.u[1].mean()
    np.testing.assert_array_equal(freight.u[[0, 2, 3]], line_speed.u[[0, 2, 3]])
    # the same tonnage in fewer, heavier axles
    passes = freight.config.section_axle_passes()
    assert passes[1].sum() < passes[0].sum() and passes[1, 1] > passes[0, 1]
    assert freight.static_wheel_load[1] == freight.static_wheel_load[0]  # freight on both: the freight wheel
    passenger = run(freight_share=(0.4, 0.0, 0.4, 0.4))
    assert passenger.static_wheel_load[1] < passenger.static_wheel_load[0]  # no freight: the coach's wheel


def test_a_sections_tonnage_scales_its_axle_passes(line_speed):
    busy = run(annual_mgt=(15.0, 30.0, 15.0, 15.0))
    assert busy.config.section_axle_passes()[1] == pytest.approx(2 * busy.config.section_axle_passes()[0])
    assert busy.u[1].mean() > 1.05 * line_speed.u[1].mean()
    np.testing.assert_array_equal(busy.u[[0, 2, 3]], line_speed.u[[0, 2, 3]])


def test_a_longer_section_costs_and_takes_more_in_proportion():
    lengths = (200.0, 300.0, 100.0, 200.0)
    c = LineConfig(**{**BASE, "capacity": 2}, per_section={"section_length_m": lengths}, choices=("tamp", "renew"))
    batch = LineBatch(c, 1)
    batch.start([0], [np.random.default_rng(1)])
    ratio = np.array(lengths) / c.section_length_m
    costs = batch.code_costs()
    np.testing.assert_allclose(costs[:, 1], c.tamping_cost_per_m * np.array(lengths) + batch.renewing()
                               * c.renewal_cost_per_m * np.array(lengths))
    np.testing.assert_allclose(costs[:, 4], (c.tamping_cost_per_m + c.renewal_cost_per_m) * np.array(lengths))
    parts = dict(zip(LineConfig.cost_keys(), batch.campaign_parts(np.array([[1, 1, 0, 0]])), strict=False))
    assert parts["tamping"][0] == pytest.approx(c.tamping_cost_per_m * 500.0)
    # the possession's work: 1.5 + 0.5 sections fit a capacity of 2; 1.5 + 1 do not (the worst SD is kept)
    codes, clipped = batch.resolve(np.array([[0, 1, 1, 0]]))
    assert codes.tolist() == [[0, 1, 1, 0]] and not clipped[0]
    codes, clipped = batch.resolve(np.array([[1, 1, 0, 0]]))
    assert (codes == 1).sum() == 1 and clipped[0]
    assert not batch.choice_mask()[0, 1, 4]  # renewing 300 m takes 3 x 1.5 > 2 sections of work
    # the geometry cost is per metre: the same SD costs in proportion to the length
    batch.sd[:] = 1e-3
    np.testing.assert_allclose(batch.section_costs() / batch.section_costs()[0], ratio)


def test_the_rate_correlation_follows_the_distance_between_centres():
    c = LineConfig(**BASE, per_section={"section_length_m": (200.0, 400.0, 100.0, 200.0)})
    rho = LineBatch(c, 1)._rate_correlation()
    np.testing.assert_allclose(rho[1:], np.exp(-np.array([300.0, 250.0, 150.0]) / c.rate_correlation_m))


def test_without_per_section_values_every_section_has_the_lines():
    c = LineConfig(**BASE)
    for name in ("speed_kmh", "annual_mgt", "freight_share", "section_length_m"):
        assert (c.section_values(name) == getattr(c, name)).all()
    assert (c.section_axle_passes() == c.axle_passes_per_step()).all()
    assert (c.length_factors == 1.0).all() and (c.traffic_factors == 1.0).all()


@pytest.mark.parametrize("per_section, message", [
    ({"speed_kmh": (120.0, 80.0)}, r"per_section\['speed_kmh'\] must be 4 numbers"),
    ({"speed_kmh": (120.0, 400.0, 120.0, 120.0)}, r"per_section\['speed_kmh'\]\[1\] must lie in \[5, 300\]"),
    ({"freight_share": (0.4, 40.0, 0.4, 0.4)}, r"per_section\['freight_share'\]\[1\] must lie in \[0, 1\]"),
    ({"annual_mgt": (15.0, 0.0, 15.0, 15.0)}, r"per_section\['annual_mgt'\]\[1\] must lie in \[0.1, 200\]"),
    ({"section_length_m": (200.0, 15.0, 200.0, 200.0)},
     r"per_section\['section_length_m'\]\[1\] must lie in \[segment_length_m = 18, 1000\]"),
    ({"axle_load_t": (20.0,) * 4}, r"per_section: unknown field 'axle_load_t'"),
    ({"speed_kmh": "fast"}, r"per_section\['speed_kmh'\] must be 4 numbers"),
    ({"annual_mgt": np.array(2.0)}, r"per_section\['annual_mgt'\] must be 4 numbers"),  # 0-d: no len()
    ({"annual_mgt": np.full((4, 1), 15.0)}, r"per_section\['annual_mgt'\] must be 4 numbers"),
    ([1.0, 2.0], r"per_section must be a mapping"),
])
def test_bad_per_section_values_are_refused_naming_the_field(per_section, message):
    with pytest.raises(ValueError, match=message):
        LineConfig(**BASE, per_section=per_section)


def test_every_sections_speed_is_checked_against_the_passes_time_steps():
    """A pass the dynamics could not take (too many time steps at a slow section's speed) is refused by the config,
    naming the per-section speed, where the line's speed alone is fine."""
    LineConfig(n_sections=2, capacity=1, dt=1e-5)
    with pytest.raises(ValueError, match=r"per_section\['speed_kmh'\] and dt: .*MAX_TIME_STEPS"):
        LineConfig(n_sections=2, capacity=1, dt=1e-5, per_section={"speed_kmh": (100.0, 5.0)})


def test_per_section_needs_one_section_per_segment():
    with pytest.raises(ValueError, match="per_section needs sections_per_segment = 1"):
        LineConfig(n_sections=4, section_length_m=10.0, segment_length_m=40.0, sections_per_segment=4, capacity=4,
                   per_section={"speed_kmh": (100.0, 80.0, 100.0, 100.0)})


def test_per_section_values_round_trip_and_keep_the_config_hashable():
    c = LineConfig(**BASE, per_section={"speed_kmh": [120, 80, 120, 120], "freight_share": (0.4, 0.4, 0.6, 0.6)})
    assert c.per_section == (("freight_share", (0.4, 0.4, 0.6, 0.6)), ("speed_kmh", (120.0, 80.0, 120.0, 120.0)))
    again = LineConfig.from_dict(c.to_dict())
    assert again == c and hash(again) == hash(c)
    assert c.replace(per_section={}) == LineConfig(**BASE)


def test_the_masks_and_the_rules_count_a_sections_work_by_its_length():
    """The env's first masks (before a reset), the engine's and the rules' capacity agree on a line with sections
    of several lengths."""
    from trackenv.envs.env import _masks
    from trackenv.envs.line import TampingLine
    from trackenv_agents.rules.choices import ChoiceThreshold
    from trackenv_agents.rules.line import GroupedThreshold

    c = LineConfig(**{**BASE, "capacity": 2}, per_section={"section_length_m": (200.0, 300.0, 100.0, 200.0)},
                   choices=("tamp", "renew"))
    env = TampingLine(c, action_type="choices")
    first = _masks(None, c, 1, "choices")
    env.reset(seed=0)
    assert (first == _masks(env.engine, c, 1, "choices")).all()
    assert not env.engine.choice_mask()[0, 1, 4] and env.engine.choice_mask()[0, 2, 4]  # 4.5 and 1.5 sections
    rule = ChoiceThreshold().bind(c)
    codes = rule.allowed(np.array([[1, 1, 1, 0]]), {"years_since_tamping": np.full((1, 4), 5.0),
                                                     "section_sd": np.array([[1.0, 2.0, 3.0, 0.5]])},
                          np.zeros(1, dtype=np.int64), np.full((1, 4), -10))
    assert codes.tolist() == [[0, 1, 1, 0]]  # 1.5 + 0.5 fit a capacity of 2; the mildest section is left
    tamp = GroupedThreshold().bind(c)._cap(np.array([[True, True, True, False]]),
                                           {"section_sd": np.array([[1.0, 2.0, 3.0, 0.5]])})
    assert tamp.tolist() == [[False, True, True, False]]  # the line rules count work too
    assert GroupedThreshold().bind(LineConfig(**BASE)).length_factors is None  # one length: sections, as before


def test_sections_shorter_than_a_segment_need_several_sections_on_a_segment():
    """One section per segment represents each section by a segment of its own track, at least 12 m long: shorter
    sections (the 60 m track's 10 m ones) are refused naming sections_per_segment, not an empty range."""
    from trackenv.envs.line_config import scenario

    with pytest.raises(ValueError, match=r"section_length_m = 10 with sections_per_segment = 1.*>= 12 m"):
        scenario("track60", sections_per_segment=1)
    assert scenario("track60").sections_per_segment == 6
