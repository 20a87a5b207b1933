"""The registered ids: the default line with tamping only (v0) is a current problem beside the one with every
choice (v1), so making it tells nobody to upgrade; Gymnasium's advice about other ids is left as it is. Run as a
user's script runs (a fresh interpreter with every warning shown), since pytest puts its own warning filters
first."""

from __future__ import annotations

import subprocess
import sys

SCRIPT = """
import gymnasium as gym
import trackenv
for version in (0, 1):
    gym.register(f"trackenv_test/OldAndNew-v{version}", entry_point="gymnasium.envs.classic_control:CartPoleEnv")
gym.make("trackenv/TampingLine-v0").close()
gym.make("trackenv_test/OldAndNew-v0").close()
"""


def test_the_default_line_v0_is_not_called_out_of_date_and_other_ids_are() -> None:
    run = subprocess.run([sys.executable, "-W", "always::DeprecationWarning", "-c", SCRIPT], capture_output=True,
                         text=True, timeout=120, check=True)
    assert "trackenv/TampingLine-v0 is out of date" not in run.stderr
    assert "trackenv_test/OldAndNew-v0 is out of date" in run.stderr
