"""How the tables write a CI and a count of episodes (:mod:`trackenv_agents.evaluation.reporting`)."""

from trackenv_agents.evaluation.reporting import ci_text, count_text


def test_a_ci_of_fewer_than_two_episodes_is_not_given():
    """A bootstrap of one episode repeats it: "[198.1, 198.1]" claimed a certainty it has not; "n/a" instead."""
    assert ci_text(198.1, 198.1, 1) == ci_text(1.0, 2.0, 0) == "n/a"
    assert ci_text(131.44, 144.6, 2) == "[131.4, 144.6]"
    assert ci_text(-15.8, 11.6, 200, signed=True) == "[-15.8, +11.6]"
    assert ci_text(0.481, 0.812, 32, digits=2) == "[0.48, 0.81]"


def test_a_count_of_one_is_singular():
    assert count_text(1, "held-out episode") == "1 held-out episode"
    assert count_text(8, "held-out episode") == "8 held-out episodes"
    assert count_text(0, "paired episode") == "0 paired episodes"
