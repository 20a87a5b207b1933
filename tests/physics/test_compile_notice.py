"""A pass that must compile a kernel entry says so first (KernelCompileWarning); one whose entry is loaded or in
numba's on-disk cache says nothing."""

from __future__ import annotations

import warnings

import pytest

from trackenv.physics import _kernel, kernels


def test_a_pass_that_must_compile_warns_first(monkeypatch):
    monkeypatch.setattr(kernels, "_ANNOUNCED", set())
    monkeypatch.setattr(_kernel, "is_loaded", lambda entry, signature: False)
    monkeypatch.setattr(_kernel, "is_cached", lambda entry, signature: False)
    with pytest.warns(kernels.KernelCompileWarning, match="serial chunks of 6 rows.*trackenv compile"):
        kernels.announce_compile(False, 6)


@pytest.mark.parametrize(("loaded", "cached"), [(True, False), (False, True)])
def test_a_loaded_or_cached_entry_says_nothing(monkeypatch, loaded, cached):
    monkeypatch.setattr(kernels, "_ANNOUNCED", set())
    monkeypatch.setattr(_kernel, "is_loaded", lambda entry, signature: loaded)
    monkeypatch.setattr(_kernel, "is_cached", lambda entry, signature: cached)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        kernels.announce_compile(True, 1)


def test_an_entry_is_checked_once_per_process(monkeypatch):
    monkeypatch.setattr(kernels, "_ANNOUNCED", set())
    calls = []
    monkeypatch.setattr(_kernel, "is_loaded", lambda entry, signature: calls.append(entry) or True)
    for _ in range(3):
        kernels.announce_compile(False, 4)
    assert calls == [(False, 4)]
