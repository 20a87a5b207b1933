"""The agents' subpackages by job re-export the public names of their modules; the learners' load on first use."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest


@pytest.mark.parametrize("package", ["rules", "evaluation"])
def test_every_public_name_of_a_subpackage_is_its_modules(package):
    pkg = importlib.import_module(f"trackenv_agents.{package}")
    assert len(set(pkg.__all__)) == len(pkg.__all__)
    for name in pkg.__all__:
        value = getattr(pkg, name)
        # re-exported, not redefined, and no module of the package hides behind a name of the same spelling
        assert not isinstance(value, type(sys)), name


def test_the_learners_names_load_on_first_use_without_torch_up_front():
    from trackenv_agents import learning

    assert learning.__all__ == sorted(learning._EXPORTS)
    code = ("import sys, trackenv_agents.learning as l; import trackenv_agents.learning.actions; "
            "print([m for m in ('torch', 'stable_baselines3') if m in sys.modules]); "
            "l.section_features; print('trackenv_agents.learning.line_policy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split("\n")
    assert out[:2] == ["[]", "True"]
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        learning.nothing  # noqa: B018
    pytest.importorskip("stable_baselines3")
    for name in learning.__all__:
        value = getattr(learning, name)
        module = importlib.import_module(f"trackenv_agents.learning.{learning._EXPORTS[name]}")
        assert value is getattr(module, name) and not isinstance(value, type(sys)), name
