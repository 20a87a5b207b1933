"""trackenv._openmp: OpenMP threads that sleep while they wait, unless the user chose otherwise."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from trackenv._openmp import WAIT_POLICY, prefer_passive_wait


def test_sets_the_policy_where_unset(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    prefer_passive_wait()
    assert os.environ["OMP_WAIT_POLICY"] == WAIT_POLICY == "PASSIVE"


def test_keeps_the_users_choice(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OMP_WAIT_POLICY", "ACTIVE")
    prefer_passive_wait()
    assert os.environ["OMP_WAIT_POLICY"] == "ACTIVE"


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="reads the process's loaded libraries (Linux)")
def test_import_sets_it_before_any_openmp_runtime_loads() -> None:
    """The policy is read when an OpenMP runtime loads: importing trackenv (and its envs) must set it and load
    none, so that the first parallel call of the physics starts its threads with it."""
    code = ("import os, trackenv, trackenv.envs\n"
            "maps = open('/proc/self/maps').read()\n"
            "print(os.environ.get('OMP_WAIT_POLICY'), 'libgomp' in maps or 'omppool' in maps)\n")
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["PASSIVE", "False"]
