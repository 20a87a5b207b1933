"""What every trackenv env shares on the Gymnasium side, written once: decoding and masking the sections'
actions, checking ``reset``'s arguments and the render mode."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from ..physics._checks import check_int
from .choices import CHOICES

ACTION_TYPES = ("multibinary", "discrete", "choices")
RENDER_MODES = (None, "rgb_array")

#: Bounds of the observation keys that every problem has (units of the envs' tables: mm, counts, fractions);
#: each problem's bounds table starts from these, and its space and its clipping both read that one table.
SHARED_BOUNDS: dict[str, tuple[float, float]] = {
    "level": (-100.0, 200.0),
    "section_sd": (0.0, 100.0),
    "section_peak": (0.0, 200.0),
    "tampings": (0.0, 1000.0),
    "time": (0.0, 1.0),
    "contact_force": (0.0, 2000.0),  # kN: wheel/rail force over each sleeper bay (static ~100 kN)
}


def clip_observation(raw: dict[str, np.ndarray], bounds: dict[str, tuple[float, float]]) -> dict[str, np.ndarray]:
    """The observed quantities ``raw`` clipped to their ``bounds`` and cast to float32 (the space's dtype)."""
    return {k: np.clip(v, *bounds[k]).astype(np.float32) for k, v in raw.items()}


def clipped_values(raw: dict[str, np.ndarray], bounds: dict[str, tuple[float, float]]) -> int:
    """How many of the observed quantities ``raw`` lie beyond their ``bounds`` (and are clipped in the
    observation): ``info["observation_clipped"]``, so that no value is clipped silently."""
    return int(sum(np.count_nonzero((v < bounds[k][0]) | (v > bounds[k][1])) for k, v in raw.items()))


def observation_space(bounds: dict[str, tuple[float, float]], shapes: dict[str, tuple[int, ...]]) -> spaces.Dict:
    """The Dict observation space of a bounds table, each key's Box of its shape in ``shapes``."""
    return spaces.Dict({k: spaces.Box(low, high, shapes[k], np.float32) for k, (low, high) in bounds.items()})


def action_space(config, action_type: str) -> spaces.Space:
    """The action space of ``action_type`` over ``config.n_sections`` sections."""
    if action_type == "multibinary":
        return spaces.MultiBinary(config.n_sections)
    if action_type == "discrete":
        return spaces.Discrete(config.n_sections + 1)
    if action_type == "choices":
        return spaces.MultiDiscrete([len(CHOICES)] * config.n_sections)
    raise ValueError(f"action_type must be one of {list(ACTION_TYPES)}, got {action_type!r}")


RESET_OPTIONS: tuple[str, ...] = ()  # reset() takes no options yet; any key is refused, not ignored


def check_reset_arguments(seed, options) -> int | None:
    """The seed as a Python int (or None); refuse a seed that is not a non-negative integer, and any option
    (none is known)."""
    if seed is not None:
        seed = check_int("seed", seed, low=0)
    if options is not None:
        if not isinstance(options, dict):
            raise ValueError(f"options must be a dict or None, got {type(options).__name__}")
        unknown = sorted(str(k) for k in options if k not in RESET_OPTIONS)
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; known: {list(RESET_OPTIONS)}")
    return seed


def numeric_action(action: Any, expected: str) -> np.ndarray:
    """``action`` as an array of floats; ValueError saying ``expected`` where it is not numbers (text, a dict,
    None, complex numbers, a ragged sequence), which numpy would otherwise take or fail on deep inside."""
    try:
        a = np.asarray(action)
    except ValueError:  # a ragged sequence
        a = np.empty(0, dtype=object)
    if a.dtype.kind not in "biuf":
        raise ValueError(f"action must be {expected}, got {action!r:.80} ({type(action).__name__})")
    return a.astype(float)


def decode_action(action, action_type: str, n_sections: int) -> np.ndarray:
    """The sections to tamp (bool, n_sections) from an action, or with ``action_type="choices"`` the action code
    of each section (int64, n_sections: :data:`~trackenv.envs.choices.CHOICES`); a malformed action raises
    ValueError."""
    if action_type == "choices":
        return _decode_choices(action, n_sections)
    if action_type == "discrete":
        a = numeric_action(action, f"one integer in [0, {n_sections}]")
        if a.size != 1 or not np.all(np.isfinite(a)) or float(a.ravel()[0]) != int(a.ravel()[0]):
            raise ValueError(f"action must be one integer in [0, {n_sections}], got {action!r}")
        k = int(a.ravel()[0])
        if not 0 <= k <= n_sections:
            raise ValueError(f"action must be an integer in [0, {n_sections}] (0 = no tamping), got {k}")
        out = np.zeros(n_sections, dtype=bool)
        if k:
            out[k - 1] = True
        return out
    a = numeric_action(action, f"an array of {n_sections} values in {{0, 1}}")
    if a.shape != (n_sections,):
        raise ValueError(f"action must have shape ({n_sections},) (one 0/1 per section), got {a.shape}")
    if not np.all(np.isfinite(a)) or not np.all((a == 0) | (a == 1)):
        raise ValueError(f"action values must be 0 or 1 (no NaN), got {a.tolist()}")
    return a.astype(bool)


def _decode_choices(action, n_sections: int) -> np.ndarray:
    top = len(CHOICES) - 1
    a = numeric_action(action, f"an array of {n_sections} choice codes in [0, {top}]")
    if a.shape != (n_sections,):
        raise ValueError(f"action must have shape ({n_sections},) (one choice code per section), got {a.shape}")
    if not np.all(np.isfinite(a)) or not np.all((a == np.round(a)) & (a >= 0) & (a <= top)):
        raise ValueError(f"action values must be integer choice codes in [0, {top}] ({', '.join(CHOICES)}), "
                         f"got {a.tolist()}")
    return a.astype(np.int64)


def action_mask(allowed: np.ndarray, action_type: str) -> np.ndarray:
    """Valid actions for masked algorithms from ``allowed`` (..., n_sections) bool, the sections that may be
    tamped now: Discrete (..., n_sections + 1) with "nothing" always valid; MultiBinary (..., 2·n_sections) as
    [may-not-tamp, may-tamp] pairs per section (sb3-contrib's convention); "choices" (MultiDiscrete) from
    ``allowed`` (..., n_sections, len(CHOICES)), the choices each section may get, flat (..., n_sections ·
    len(CHOICES)), section after section, as sb3-contrib expects for MultiDiscrete."""
    allowed = np.asarray(allowed, dtype=bool)
    if action_type == "choices":  # allowed: (..., n_sections, len(CHOICES)), flat per section as sb3-contrib reads
        return allowed.reshape(allowed.shape[:-2] + (-1,))
    if action_type == "discrete":
        return np.concatenate([np.ones(allowed.shape[:-1] + (1,), dtype=bool), allowed], axis=-1)
    return np.stack([np.ones_like(allowed), allowed], axis=-1).reshape(allowed.shape[:-1] + (-1,))


def check_render_mode(value: str | None) -> str | None:
    """``value`` if it is a render mode trackenv's envs draw (None or "rgb_array"), else ValueError."""
    if value not in RENDER_MODES:
        raise ValueError(f"render_mode must be None or 'rgb_array', got {value!r}")
    return value
