"""Data flows down (DESIGN.md): the library never imports the agents, and the physics imports no RL or plotting."""

from __future__ import annotations

import subprocess
import sys


def _modules_after(imports: str) -> set[str]:
    code = f"import sys; {imports}; print(' '.join(sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    return set(out.split())


def test_the_library_never_imports_the_agents():
    loaded = _modules_after("import trackenv, trackenv.envs, trackenv.render, trackenv.degradation, "
                            "trackenv_studies.paper, trackenv_studies.validation, trackenv_studies.bench, "
                            "trackenv_studies.calibration")
    assert not {m for m in loaded if m.split(".")[0] in ("trackenv_agents", "agents", "stable_baselines3", "torch")}


def test_the_physics_imports_no_rl_no_plotting():
    loaded = _modules_after("import trackenv.physics.dynamics, trackenv.physics.settlement, "
                            "trackenv.physics.geometry, trackenv.physics.tamping")
    # importing trackenv.physics runs trackenv/__init__ (which registers the env), so look at what the physics
    # modules themselves need: none of them may pull in matplotlib or tqdm
    assert not {m for m in loaded if m.split(".")[0] in ("matplotlib", "tqdm", "trackenv_agents")}
