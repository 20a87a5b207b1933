"""What a track manager may decide for a section in one step: the names of the choices, their action codes and
which of them is track work.

The action code of a choice is its index in :data:`CHOICES` (``action_type="choices"``: one code per section,
``MultiDiscrete([len(CHOICES)] * n_sections)``). Code 1 is ``"tamp"``, so a tamp-or-wait action (MultiBinary,
1 = tamp) is already a vector of choice codes. What each choice does to the track, what it costs and how much
of the possession it takes: :class:`~trackenv.envs.line_config.LineConfig` (fields) and
:class:`~trackenv.envs.line_episode.LineBatch` (physics); the documentation's page "Choices" has the table.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

__all__ = ["CHOICES", "COST_KEY", "DRAINAGE", "INSPECT", "INTERVENTIONS", "IS_TRACK_WORK", "NOTHING", "PER_METRE",
           "RENEW", "SPOT_TAMP", "SURVEY", "TAMP", "TRACK_WORK", "action_type_for", "choice_counts", "code",
           "enabled_codes", "spot_only_steps", "step_possession", "work_on_sections", "work_per_code"]

#: every choice, by action code
CHOICES = ("nothing", "tamp", "spot_tamp", "drainage", "renew", "inspect", "survey")
NOTHING = 0
#: the choices a config may enable ("nothing" is always allowed)
INTERVENTIONS = CHOICES[1:]
#: the choices that are work on the track (they need the possession, count against its capacity and against
#: ``min_steps_between_tampings``); "inspect" and "survey" look without working
TRACK_WORK = ("tamp", "spot_tamp", "drainage", "renew")
#: per action code: whether it is track work
IS_TRACK_WORK = np.array([name in TRACK_WORK for name in CHOICES])
#: the cost part (``info["costs"]``) of each choice besides the tamping and renewal that ``tamp`` and ``renew``
#: share with the tamping-only problem
COST_KEY = {"spot_tamp": "spot_tamping", "drainage": "drainage", "inspect": "inspection", "survey": "survey"}


def action_type_for(config: Any) -> str:
    """The action type a config's env runs with unless told otherwise: ``"choices"`` (a code per section) where
    the config enables more than tamping, else ``"multibinary"`` (tamp or wait). A tamp-or-wait action is also a
    valid choices action (codes 0 and 1), so tamping-only policies run on either."""
    return "choices" if tuple(getattr(config, "choices", ("tamp",))) != ("tamp",) else "multibinary"


def code(name: str) -> int:
    """The action code of the choice ``name``."""
    return CHOICES.index(name)


#: the action codes of the interventions, by name
TAMP, SPOT_TAMP, DRAINAGE, RENEW, INSPECT, SURVEY = (code(name) for name in INTERVENTIONS)


def enabled_codes(choices: Iterable[str]) -> np.ndarray:
    """(len(CHOICES),) bool per action code: "nothing" and the enabled ``choices`` (names)."""
    enabled = set(choices)
    return np.array([name == "nothing" or name in enabled for name in CHOICES])


def work_per_code(choice_work: Mapping[str, float]) -> np.ndarray:
    """(len(CHOICES),) the possession work of each action code (nothing: 0), from ``choice_work`` by name
    (``LineConfig.choice_work``: tamping-section equivalents)."""
    return np.array([0.0] + [float(choice_work[name]) for name in INTERVENTIONS])


#: per action code: whether its cost and possession work scale with the section's length (tamping, renewal)
PER_METRE = np.array([name in ("tamp", "renew") for name in CHOICES])


def work_on_sections(work: np.ndarray, codes: np.ndarray, length_factors: np.ndarray | float = 1.0) -> np.ndarray:
    """The possession work of the action ``codes`` (any shape) on their sections, in tamping-section equivalents:
    ``work[codes]`` (per code: :func:`work_per_code`), a tamping's and a renewal's times the section's
    ``length_factors`` (its length over the line's section length, shaped like ``codes`` or broadcast to it;
    ``LineConfig.length_factors``)."""
    codes = np.asarray(codes, dtype=np.int64)
    return work[codes] * np.where(PER_METRE[codes], length_factors, 1.0)



def spot_only_steps(codes: np.ndarray) -> np.ndarray:
    """(rows,) bool: the rows of action codes ``codes`` (rows, S; a step of a line) whose only track work is spot
    tamping. Such a step pays ``LineConfig.spot_possession_share`` of the possession, any other step with track
    work the whole of it (the env's costs and the hindsight search's prices read this one rule)."""
    codes = np.asarray(codes, dtype=np.int64)
    work = IS_TRACK_WORK[codes]
    return work.any(axis=1) & ~(work & (codes != SPOT_TAMP)).any(axis=1)


def step_possession(config, codes: np.ndarray) -> np.ndarray:
    """(rows,) k€: the possession each row of action codes ``codes`` (rows, S; a step of a line) pays under
    ``config`` (a :class:`~trackenv.envs.line_config.LineConfig`): ``possession_cost`` where any section gets track
    work, ``spot_possession_share`` of it where that work is spot tamping alone (:func:`spot_only_steps`), none
    where no section works."""
    codes = np.asarray(codes, dtype=np.int64)
    price = np.where(spot_only_steps(codes), config.spot_possession_share * config.possession_cost,
                     config.possession_cost)
    return IS_TRACK_WORK[codes].any(axis=1) * price


def choice_counts(codes: np.ndarray) -> dict[str, int]:
    """How many sections of ``codes`` (any shape, action codes) got each choice but "nothing", by name."""
    counts = np.bincount(np.asarray(codes, dtype=np.int64).ravel(), minlength=len(CHOICES))
    return {name: int(counts[i]) for i, name in enumerate(CHOICES) if i != NOTHING}
