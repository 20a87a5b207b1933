"""Library code changes no global state (a library that users import must not): matplotlib's backend stays the
user's."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_library_sources_neither_switch_the_backend_nor_use_pyplot():
    offenders = [
        f"{path.relative_to(ROOT)}:{i}"
        for folder in ("trackenv", "agents")
        for path in sorted((ROOT / folder).rglob("*.py"))
        for i, line in enumerate(path.read_text().splitlines(), start=1)
        if "matplotlib.use(" in line or "import matplotlib.pyplot" in line
    ]
    assert offenders == []


def test_rendering_and_plot_files_keep_the_users_backend(tmp_path):
    code = f"""
import matplotlib
matplotlib.use("pdf")
import gymnasium as gym
import numpy as np
import trackenv
from trackenv.envs import scenario
from trackenv_agents.evaluation.reporting import plot_comparison
from trackenv_agents.evaluation import EvaluationResult

cfg = scenario("track60", n_sections=3, segment_length_m=30.0, sections_per_segment=3, capacity=3, horizon_years=1.0)
env = gym.make("trackenv/Tamping-v1", config=cfg, render_mode="rgb_array")
env.reset(seed=0)
frame = env.render()
assert frame.ndim == 3 and frame.dtype == np.uint8, frame.shape
r = EvaluationResult("p", {{}}, cfg, np.arange(3), np.array([1.0, 2.0, 3.0]), {{}}, np.zeros(3), np.zeros(3),
                     np.zeros(3), -np.array([1.0, 2.0, 3.0]))
plot_comparison([r], {str(tmp_path / "costs.png")!r})
print(matplotlib.get_backend())
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "pdf"
    assert (tmp_path / "costs.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
