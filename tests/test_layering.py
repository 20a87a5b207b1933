"""Data flows down: the physics (trackenv.physics) < the library users import (trackenv: the physics, the envs,
the settlement loop, rendering) < the studies (trackenv_studies, experiments/studies/) < the agents
(trackenv_agents, agents/: rules < evaluation < learning < the command line).

Two views of it: what a fresh interpreter has loaded after importing a layer (sys.modules, in a subprocess), and
every import statement of a layer's source, those inside functions (loaded later, or never in a test) included.
"""

from __future__ import annotations

import ast
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

import trackenv

ROOT = Path(__file__).resolve().parents[1]
#: import package -> its folder in the repository
PACKAGES = {"trackenv": ROOT / "trackenv", "trackenv_studies": ROOT / "experiments" / "studies",
            "trackenv_agents": ROOT / "agents"}
#: what no module of the library loads: the agents, the studies, RL frameworks, progress bars, configuration
#: files and pyplot's global state (rendering draws on a matplotlib Figure of its own)
NOT_IN_THE_LIBRARY = ("trackenv_agents", "trackenv_studies", "agents", "experiments", "stable_baselines3",
                      "sb3_contrib", "torch", "ray", "tqdm", "yaml", "matplotlib.pyplot", "pylab")
#: what the physics does not import on top of that: it runs without an env, a plot or a progress bar, and
#: imports nothing of trackenv but itself
NOT_IN_THE_PHYSICS = NOT_IN_THE_LIBRARY + ("gymnasium", "matplotlib", "trackenv.envs", "trackenv.render",
                                           "trackenv.degradation", "trackenv._json")
#: layer -> what it must not import (a name stands for itself and its submodules)
RULES = {
    "trackenv": NOT_IN_THE_LIBRARY,
    "trackenv.physics": NOT_IN_THE_PHYSICS,
    "trackenv_studies": ("trackenv_agents", "agents", "stable_baselines3", "sb3_contrib", "torch", "ray"),
    "trackenv_agents.rules": ("trackenv_agents.evaluation", "trackenv_agents.learning", "trackenv_agents.cli",
                              "stable_baselines3", "sb3_contrib", "torch"),
    "trackenv_agents.evaluation": ("trackenv_agents.learning", "trackenv_agents.cli", "stable_baselines3",
                                   "sb3_contrib", "torch"),
    "trackenv_agents.learning": ("trackenv_agents.cli",),
}
#: module -> what it may import although its layer may not: the one reader of line files, which are YAML by
#: their schema (with yaml.safe_load only), and the torch backend of the pass, which is torch
EXCEPTIONS = {"trackenv.envs.line_file": ("yaml",), "trackenv.physics.torch_pass": ("torch",)}
#: modules loaded only on request (simulate_passes(..., backend="torch")): importing the rest must not load them
ON_REQUEST = ("trackenv.physics.torch_pass",)
#: what importing the library loads (yaml is loaded by numba, which reads its configuration file with it)
NOT_LOADED = tuple(m for m in NOT_IN_THE_LIBRARY if m != "yaml")
STUDIES = ("bench", "paper", "validation", "line_calibration", "calibration")


def _within(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def _modules(package: str) -> dict[str, Path]:
    """Every module of ``package`` (its source files in the repository) by its dotted name."""
    root = PACKAGES[package.split(".")[0]]
    base = root.joinpath(*package.split(".")[1:])
    out = {}
    for path in sorted(base.rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join([package.split(".")[0], *parts])] = path
    return out


def _imports(name: str, path: Path) -> set[str]:
    """The modules the source of module ``name`` imports anywhere (relative imports resolved; for ``from m
    import x`` both ``m`` and ``m.x``, x may be a module), and ``importlib.import_module`` of a literal."""
    here = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(here[:len(here) - node.level + 1] + ([node.module] if node.module else []))
            found.add(base)
            found |= {f"{base}.{a.name}" for a in node.names}
        elif (isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) ==
              "import_module" and node.args and isinstance(node.args[0], ast.Constant)):
            found.add(str(node.args[0].value))
    return found


def _loaded_after(imports: str) -> set[str]:
    code = f"import sys; {imports}; print(' '.join(sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    return set(out.split())


#: scipy's submodules that the library uses in a few functions only (the D1 filter's design, a PSD's variance,
#: splines through profiles, correlated random fields): imported there, since loading them took ~0.9 s of the
#: ~1.9 s of `import trackenv`, which every command, worker process and spawned env pays
LOADED_ON_USE = ("scipy.signal", "scipy.stats", "scipy.integrate", "scipy.interpolate", "scipy.ndimage")


def test_importing_the_library_leaves_the_slow_scipy_submodules_for_their_first_use():
    loaded = _loaded_after("import trackenv, trackenv.envs")
    assert not {m for m in loaded if _within(m, LOADED_ON_USE)}
    used = _loaded_after("import numpy as np, trackenv; trackenv.physics.geometry.d1_filter(np.zeros(60), 0.6)")
    assert "scipy.signal" in used  # the lazy import is where the filter is designed


@pytest.mark.parametrize("layer", sorted(RULES))
def test_no_layer_imports_what_sits_above_it(layer):
    modules = _modules(layer)
    assert modules, layer
    bad = {name: sorted(m for m in _imports(name, path) if _within(m, RULES[layer])
                        and not _within(m, EXCEPTIONS.get(name, ())))
           for name, path in modules.items()}
    assert not {k: v for k, v in bad.items() if v}


def test_the_scan_sees_lazy_and_relative_imports(tmp_path):
    src = tmp_path / "mod.py"
    src.write_text("def f():\n    from ..envs import line\n    import tqdm.auto\n"
                   "    importlib.import_module('matplotlib.pyplot')\n")
    found = _imports("trackenv.physics.mod", src)
    assert {"trackenv.envs", "trackenv.envs.line", "tqdm.auto", "matplotlib.pyplot"} <= found
    assert _within("tqdm.auto", NOT_IN_THE_PHYSICS) and _within("trackenv.envs.line", NOT_IN_THE_PHYSICS)
    assert not _within("trackenv.physics.dynamics", NOT_IN_THE_PHYSICS)


def test_the_library_holds_no_study():
    names = {m.name for m in pkgutil.walk_packages(trackenv.__path__, "trackenv.")}
    assert "trackenv.physics.dynamics" in names and "trackenv.envs.line" in names  # the walk sees the modules
    assert not {n for n in names if n.rsplit(".", 1)[-1] in STUDIES}


def test_importing_every_module_of_the_library_loads_neither_agents_nor_studies():
    names = sorted(m.name for m in pkgutil.walk_packages(trackenv.__path__, "trackenv.") if m.name not in ON_REQUEST)
    loaded = _loaded_after("import " + ", ".join(["trackenv", *names]))
    assert set(names) <= loaded
    assert not {m for m in loaded if _within(m, NOT_LOADED)}


def test_the_physics_imports_no_rl_no_plotting():
    names = sorted(m.name for m in pkgutil.walk_packages(trackenv.physics.__path__, "trackenv.physics.")
                   if m.name not in ON_REQUEST)
    loaded = _loaded_after("import " + ", ".join(names))
    # importing trackenv.physics runs trackenv/__init__ (which registers the env, with gymnasium), so look at
    # what the library as a whole must not load; the physics' own imports are scanned above
    assert not {m for m in loaded if _within(m, NOT_LOADED + ("matplotlib",))}


def test_the_studies_load_no_agent():
    loaded = _loaded_after("import trackenv_studies.bench, trackenv_studies.paper, trackenv_studies.validation, "
                           "trackenv_studies.calibration")
    assert not {m for m in loaded if _within(m, RULES["trackenv_studies"])}
