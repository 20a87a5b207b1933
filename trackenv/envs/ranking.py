"""Ranked actions, decoded: a count per kind of work, and a fixed order of preference that says which sections get
it. Batched (a leading row per env); the single and vector wrappers of :mod:`trackenv.envs.wrappers` call these
functions, so every library gets one implementation.

**Tamping only** (:func:`ranked_to_sections`): ``k`` tamps the ``k`` sections with the largest observed SD.

**The choices** (:func:`ranked_to_choices`; ``action_type="choices"``): one count per enabled intervention (a
*head*, in the order of :data:`~trackenv.envs.choices.CHOICES`), each in ``[0, n_sections]``. Head ``h`` with
count ``k`` marks the ``k`` sections that rank first by its score (:data:`RANKED_SCORES`) among those the env's
mask lets get ``h`` now. A section marked by several heads gets the first of them in :data:`PRECEDENCE`. Every
decoded code is therefore one the env's mask allows for its section; the joint limits (the possession's capacity,
the annual budget), which the env's masks do not cover, are resolved by the env as for any action (its
``over_capacity`` rule). The masks of the ranked form (:func:`ranked_choice_masks`) allow a count up to the number
of sections the env's mask lets get the head's choice, and (given their work and the capacity) up to as many of
them as fit the possession together; a larger count (masked) decodes as the number of sections allowed.

The scores read the observation only (what a planner has). A section's *growth* is its measured SD over the
years since its last tamping, with at least :data:`MIN_GROWTH_YEARS` (so that a section just tamped does not look
fast); SD after tamping is not zero, so it is an upper estimate **[assumption]**.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from .choices import CHOICES
from .common import numeric_action

__all__ = ["MIN_GROWTH_YEARS", "PRECEDENCE", "RANKED_SCORES", "choice_scores", "rank_mask", "ranked_choice_masks",
           "ranked_to_choices", "ranked_to_sections", "score_keys"]

SD_KEY = "section_sd"
SURVEY_KEY = "section_survey"
#: the shortest time (years) over which the growth of a section's SD is estimated
MIN_GROWTH_YEARS = 1.0
#: per head, what ranks a section first (most significant first; the next breaks the ties of the one before,
#: the lower section index the last ties)
RANKED_SCORES = {
    "tamp": "largest measured SD (section_sd)",
    "spot_tamp": "largest measured D1 mean-to-peak (section_peak)",
    "drainage": "a survey found a wet cause, then not surveyed, then none found (section_survey, where the "
                "observation has it); then the fastest growth",
    "renew": "most tampings since the last renewal (tampings_since_renewal); then the largest SD",
    "inspect": "largest growth expected since the last measurement: measurement age (section_measurement_age) "
               "× growth",
    "survey": "not yet surveyed (section_survey = -1) first; then the fastest growth",
}
#: which head's choice a section gets when several heads mark it: the heavier work first, then the looks
PRECEDENCE = ("renew", "drainage", "tamp", "spot_tamp", "survey", "inspect")
#: the observation keys each head's score needs
_KEYS = {
    "tamp": (SD_KEY,),
    "spot_tamp": ("section_peak",),
    "drainage": (SD_KEY, "years_since_tamping"),
    "renew": ("tampings_since_renewal", SD_KEY),
    "inspect": ("section_measurement_age", SD_KEY, "years_since_tamping"),
    "survey": (SURVEY_KEY, SD_KEY, "years_since_tamping"),
}


def rank_mask(score, eligible: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Per row, True for the ``k[row]`` highest-``score`` entries among ``eligible`` (rows, S) (ties: lower index).
    ``score``: one (rows, S) array, or a tuple of them compared in turn (the first decides, the next breaks its
    ties)."""
    if isinstance(score, tuple):
        keys = [np.where(eligible, -np.asarray(s, dtype=float), np.inf) for s in score]
        order = np.lexsort(tuple(reversed(keys)), axis=-1)  # lexsort: its last key is the primary one; stable
    else:
        s = np.where(eligible, score, -np.inf)
        order = np.argsort(-s, axis=1, kind="stable")
    ranks = np.empty_like(order)
    np.put_along_axis(ranks, order, np.arange(order.shape[1])[None, :].repeat(order.shape[0], 0), axis=1)
    return eligible & (ranks < np.asarray(k).reshape(-1, 1))


def _counts(k, rows: int, heads: int, n_sections: int) -> np.ndarray:
    """(rows, heads) integer counts from ``k``; ValueError if their number or range is wrong."""
    counts = numeric_action(k, f"ranked counts, integers in [0, {n_sections}]")
    if counts.size != rows * heads:
        raise ValueError(f"need {heads} ranked count(s) per row for {rows} row(s), got {counts.size} value(s)")
    if not np.all((counts >= 0) & (counts <= n_sections) & (counts == np.round(counts))):
        raise ValueError(f"ranked actions must be integers in [0, {n_sections}], got {counts.tolist()}")
    return counts.astype(np.int64).reshape(rows, heads)


def ranked_to_sections(k, section_sd) -> np.ndarray:
    """MultiBinary actions (int8, ``section_sd``'s shape) tamping the ``k`` worst sections by SD per row.

    ``k``: one count per row (or a scalar for a single unbatched observation); ``section_sd``: (n_sections,)
    or (n_envs, n_sections). Ties go to the lower section index. A count outside [0, n_sections] raises.
    """
    sd = np.asarray(section_sd, dtype=float)
    single = sd.ndim == 1
    sd2 = sd[None] if single else sd
    if np.asarray(k).size != sd2.shape[0]:
        raise ValueError(f"need one ranked action per row of section_sd ({sd2.shape[0]}), got {np.asarray(k).size}")
    counts = _counts(k, sd2.shape[0], 1, sd2.shape[1])[:, 0]
    out = rank_mask(sd2, np.ones(sd2.shape, dtype=bool), counts).astype(np.int8)
    return out[0] if single else out


def score_keys(heads: Sequence[str]) -> tuple[str, ...]:
    """The observation keys the scores of ``heads`` need (``section_survey`` is used where present)."""
    unknown = [h for h in heads if h not in _KEYS]
    if unknown:
        raise ValueError(f"ranked heads must be among {list(_KEYS)}, got {unknown}")
    return tuple(dict.fromkeys(key for h in heads for key in _KEYS[h]))


def choice_scores(observation: Mapping[str, np.ndarray], head: str) -> tuple[np.ndarray, ...]:
    """The score of ``head`` (:data:`RANKED_SCORES`) from a batched ``observation`` (rows, S) per key: a tuple of
    (rows, S) arrays, most significant first."""
    obs = {k: np.asarray(v, dtype=float) for k, v in observation.items()}
    if head == "spot_tamp":
        return (obs["section_peak"],)
    sd = obs[SD_KEY]
    if head == "tamp":
        return (sd,)
    if head == "renew":
        return (obs["tampings_since_renewal"], sd)
    growth = sd / np.maximum(obs["years_since_tamping"], MIN_GROWTH_YEARS)
    if head == "inspect":
        return (obs["section_measurement_age"] * growth,)
    if head == "survey":
        return (obs[SURVEY_KEY] < 0, growth)
    if head == "drainage":
        if SURVEY_KEY not in obs:
            return (growth,)
        found = obs[SURVEY_KEY]
        return (np.where(found > 0, 2.0, np.where(found < 0, 1.0, 0.0)), growth)
    raise ValueError(f"ranked heads must be among {list(_KEYS)}, got {head!r}")


def _eligible(masks, n_sections: int) -> np.ndarray:
    """(rows, S, len(CHOICES)) bool from the env's flat masks ((S · 7,) or (rows, S · 7))."""
    return np.asarray(masks, dtype=bool).reshape(-1, n_sections, len(CHOICES))


def ranked_to_choices(k, observation: Mapping[str, np.ndarray], masks, heads: Sequence[str]) -> np.ndarray:
    """The action codes (int64, (n_sections,) or (rows, n_sections)) of the ranked counts ``k`` ((len(heads),)
    or (rows, len(heads))), one per head of ``heads`` (intervention names), decoded on ``observation`` (the
    keys of :func:`score_keys`, (S,) or (rows, S) each) and the env's flat masks ``masks`` ((S · 7,) or
    (rows, S · 7)): see the module docstring. A count outside [0, n_sections] raises ValueError."""
    raw = np.asarray(masks, dtype=bool)
    n_sections = raw.shape[-1] // len(CHOICES)
    eligible = _eligible(raw, n_sections)
    rows = eligible.shape[0]
    keys = [*score_keys(heads), *([SURVEY_KEY] if SURVEY_KEY in observation else [])]
    obs = {key: np.asarray(observation[key]).reshape(rows, n_sections) for key in keys}
    counts = _counts(k, rows, len(heads), n_sections)
    codes = np.zeros((rows, n_sections), dtype=np.int64)
    for head in sorted(heads, key=PRECEDENCE.index, reverse=True):  # the first in precedence written last
        j, choice = list(heads).index(head), CHOICES.index(head)
        marked = rank_mask(choice_scores(obs, head), eligible[:, :, choice], counts[:, j])
        codes = np.where(marked, choice, codes)
    return codes[0] if raw.ndim == 1 else codes


def ranked_choice_masks(masks, heads: Sequence[str], fit: tuple[np.ndarray, float] | None = None) -> np.ndarray:
    """The masks of the ranked choices (bool, (len(heads) · (S + 1),) or (rows, ...)), head after head as
    sb3-contrib reads a MultiDiscrete mask, from the env's flat masks ``masks`` ((S · 7,) or (rows, S · 7)):
    count ``k`` of a head is valid when it does not exceed the number of sections that may get the head's choice
    now (0 always), nor, with ``fit`` (per head each section's work, (heads, S), and the possession's capacity),
    the number of them that fit the possession together, least work first (a larger count of that head alone
    would always be clipped; what the heads ask together, the env still resolves)."""
    raw = np.asarray(masks, dtype=bool)
    n_sections = raw.shape[-1] // len(CHOICES)
    eligible = _eligible(raw, n_sections)
    available = np.stack([eligible[:, :, CHOICES.index(h)].sum(axis=1) for h in heads], axis=1)  # (rows, heads)
    if fit is not None:
        work, capacity = fit
        for i, h in enumerate(heads):
            w = np.sort(np.where(eligible[:, :, CHOICES.index(h)], np.asarray(work)[i], np.inf), axis=1)
            holds = (np.cumsum(w, axis=1) <= capacity + 1e-9).sum(axis=1)
            available[:, i] = np.minimum(available[:, i], holds)
    out = (np.arange(n_sections + 1)[None, None, :] <= available[:, :, None]).reshape(eligible.shape[0], -1)
    return out[0] if raw.ndim == 1 else out
