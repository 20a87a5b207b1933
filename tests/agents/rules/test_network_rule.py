"""NetworkRule: the line rule on every line, the machine kept on its line while there is work there, else sent
where the most is; its actions through the network env and the evaluation harness."""

import numpy as np

from trackenv.envs.network import NetworkConfig
from trackenv.envs.network_env import TampingNetwork
from trackenv_agents.evaluation.harness import evaluate_many
from trackenv_agents.rules import NetworkRule, SectionThreshold

S = 4


def _obs(sd_mm: np.ndarray, machine: int) -> dict[str, np.ndarray]:
    """A batched network observation of one network of len(sd_mm) // S lines, never tamped in the episode."""
    n_lines = sd_mm.size // S
    zeros = np.zeros((1, sd_mm.size), dtype=np.float32)
    return {"section_sd": sd_mm[None].astype(np.float32), "section_peak": zeros, "register": zeros,
            "tampings": zeros, "tampings_since_renewal": zeros, "years_since_tamping": zeros + 1.0,
            "measurement_age": np.zeros((1, n_lines), np.float32), "budget_left": np.ones((1, n_lines), np.float32),
            "time": np.zeros((1, 1), np.float32),
            "machine_line": (np.arange(n_lines) == machine).astype(np.float32)[None]}


def test_stays_while_its_line_has_work_else_asks_for_all():
    rule = NetworkRule(SectionThreshold(threshold_mm=2.0, capacity=2))
    sd = np.array([3.0, 1.0, 1.0, 1.0,  3.0, 3.0, 3.0, 1.0,  1.0, 1.0, 1.0, 1.0])
    act, _ = rule.predict(_obs(sd, machine=0))
    assert act.shape == (1, 3 * S) and np.flatnonzero(act[0]).tolist() == [0]  # its own line's one section
    sd[0] = 1.0
    act, _ = rule.predict(_obs(sd, machine=0))
    assert np.flatnonzero(act[0]).tolist() == [S + 0, S + 1]  # the line rule's two worst (capacity 2) on line 1


def test_runs_on_the_env_and_the_harness():
    env = TampingNetwork(line_config="small", n_lines=2, horizon_years=0.5)
    rule = NetworkRule(SectionThreshold(threshold_mm=0.0)).bind(env.config)
    obs, _ = env.reset(seed=0)
    act, _ = rule.predict(obs)
    assert act.shape == (2 * 6,) and not act[6:].any() and act[:6].sum() <= env.config.capacity
    config = NetworkConfig.coerce(None, line_config="small", n_lines=2, horizon_years=0.5)
    (result,) = evaluate_many([NetworkRule()], config, seeds=[0, 1], batch_size=2)
    assert result.cost.shape == (2,) and (result.cost > 0).all()
    assert np.allclose(result.cost, -result.sum_rewards, rtol=1e-12, atol=0)
    assert set(result.cost_parts) == set(NetworkConfig.cost_keys())
