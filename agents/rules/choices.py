"""Rules that use every choice of a track manager (``action_type="choices"``: one action code per section,
:data:`trackenv.envs.choices.CHOICES`), built on the best tamping rule, the grouped threshold
(:class:`~.line.GroupedThreshold`).

:class:`ChoiceThreshold` calls and fills its tamping campaigns as the grouped threshold does and adds, each
switched off by a zero:

* **spot tamping** of a section whose measured D1 mean-to-peak is at least ``spot_peak_mm`` while its SD is
  below the campaign trigger (a local defect on otherwise sound track);
* **drainage** of a section where a survey found a wet cause (``drain_surveyed``), or, without a survey that
  says dry, after ``drain_after_tampings`` tampings in the episode with fast regrowth;
* **surveys** of a section not yet surveyed whose regrowth since its last tamping is fast (``survey_fast``) or
  that has been tamped ``survey_after_tampings`` times in the episode, or of every section not yet surveyed
  (``survey_all``: a survey costs little against a wet spot left to work);
* **renewal**, instead of the tamping a campaign gives it, of a section with ``renew_after_tampings`` tampings
  since its last renewal and fast regrowth;
* **extra inspections** of a section whose last measurement is at least ``inspect_age_years`` old and whose SD,
  projected at its growth rate, is within ``inspect_margin_mm`` of the trigger, or whose measured peak is at
  least ``inspect_peak_mm``; and of a section just tamped whose peak before the tamping was at least
  ``check_peak_mm`` (a tamping may leave a local defect standing: the fresh peak then asks for a spot tamping).

"Fast regrowth" is a measured SD growth of at least ``fast_growth_mm_per_year`` since the section's last
tamping in the episode (:func:`regrowth_mm_per_year`). :class:`ChoiceThresholdNoLooking` is the same family
without inspections and surveys (it still reads the surveys made before the start): the two give the value of
information. :class:`ChoiceThresholdSpotOnly` keeps only the tamping campaigns and spot tamping: against the
grouped threshold it gives what spot tamping alone is worth. A family's ``uses`` (choice names) says which
choices it may ask for, and so which parameters it takes (:data:`CHOICE_OFF`).

Each rule respects what the env would otherwise clip or mask, so its requests are applied as asked: choices the
config does not enable are never asked for, no track work within ``min_steps_between_tampings`` steps of the
section's last track work, and the step's work (``LineConfig.choice_work``) within ``capacity``, worst measured
SD first (the env's own order). The rules do not plan against an annual budget (none of the choice scenarios
has one; with one, the env drops the mildest requests). A spot tamping or a drainage leaves no trace in the
observation, so the rules remember their own track work in SB3's recurrent ``state`` (the harness hands it back
each step; without it, ``predict`` acts on the observation alone).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from trackenv.envs.choices import (
    CHOICES,
    DRAINAGE,
    INSPECT,
    IS_TRACK_WORK,
    RENEW,
    SPOT_TAMP,
    SURVEY,
    TAMP,
    enabled_codes,
    work_on_sections,
    work_per_code,
)
from trackenv.envs.line_config import LineConfig
from trackenv.envs.line_episode import fit_worst

from .base import as_batch
from .line import GroupedThreshold, stale_measurement

__all__ = ["CHOICE_OFF", "CHOICE_RULES", "SPOT_PEAKS_MM", "ChoiceThreshold", "ChoiceThresholdNoLooking",
           "ChoiceThresholdSpotOnly", "choice_grid", "choice_view", "choices_off", "choices_on", "fresh_memory",
           "regrowth_mm_per_year", "remember_work"]

#: the shortest time between a tamping and the measurement that a growth rate is read over [year]
MIN_GROWTH_YEARS = 0.25
#: each parameter of the choice rules: the choices that read it, and its value with them off (0 or False: off;
#: the growth threshold and the inspection age only qualify a choice that is on)
CHOICE_OFF: dict[str, tuple[frozenset[str], Any]] = {
    "spot_peak_mm": (frozenset({"spot_tamp"}), 0.0),
    "drain_surveyed": (frozenset({"drainage"}), False),
    "drain_after_tampings": (frozenset({"drainage"}), 0),
    "fast_growth_mm_per_year": (frozenset({"drainage", "renew", "survey"}), 1.5),
    "renew_after_tampings": (frozenset({"renew"}), 0),
    "survey_fast": (frozenset({"survey"}), False),
    "survey_after_tampings": (frozenset({"survey"}), 0),
    "survey_all": (frozenset({"survey"}), False),
    "inspect_margin_mm": (frozenset({"inspect"}), 0.0),
    "inspect_age_years": (frozenset({"inspect"}), 0.5),
    "inspect_peak_mm": (frozenset({"inspect"}), 0.0),
    "check_peak_mm": (frozenset({"inspect"}), 0.0),
}
#: the spot-tamping peaks searched for :class:`ChoiceThresholdSpotOnly` [mm] (with spot tamping off as well)
SPOT_PEAKS_MM = (5.0, 6.0, 7.0, 8.0, 9.0)


def _measurement_age(obs: Mapping[str, np.ndarray]) -> np.ndarray:
    """(batch, S) years since each section's last measurement: ``section_measurement_age`` where the config
    observes it (with ``inspect``), else the recording car's ``measurement_age`` for every section."""
    if "section_measurement_age" in obs:
        return np.asarray(obs["section_measurement_age"], dtype=float)
    return np.broadcast_to(np.asarray(obs["measurement_age"], dtype=float), np.shape(obs["section_sd"]))


def choice_view(obs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The batched observation as the choice rules read it: the measured SD and peak of a section tamped since
    its own last measurement (per section, with inspections) set to 0 (fresh, not due), as
    :func:`~.line.planner_view` does (:func:`~.line.stale_measurement`), in float64."""
    stale = stale_measurement(obs)
    out = dict(obs)
    for key in ("section_sd", "section_peak"):
        out[key] = np.where(stale, 0.0, np.asarray(obs[key], dtype=float))
    return out


def regrowth_mm_per_year(obs: Mapping[str, np.ndarray]) -> np.ndarray:
    """(batch, S) measured SD growth since the last tamping [mm/year]: the measured SD over the years between the
    section's last tamping and its measurement (at least :data:`MIN_GROWTH_YEARS`); 0 for a section not tamped in
    the episode (its level before the episode is not known) or measured before its last tamping. Read it on
    :func:`choice_view`."""
    years = np.asarray(obs["years_since_tamping"], dtype=float) - _measurement_age(obs)
    rate = np.asarray(obs["section_sd"], dtype=float) / np.maximum(years, MIN_GROWTH_YEARS)
    return np.where((np.asarray(obs["tampings"]) > 0) & (years > 0), rate, 0.0)



def fresh_memory(state: Any, episode_start: Any, n: int, S: int) -> np.ndarray:
    """The choice rules' memory (n, 3, S) for a step: a copy of ``state`` where it is one, forgotten (-inf) where
    ``episode_start``; all -inf where ``state`` is not one (the first step, or no state handed back)."""
    if not isinstance(state, np.ndarray) or state.shape != (n, 3, S):
        return np.full((n, 3, S), -np.inf)
    memory = np.array(state, dtype=float)
    if episode_start is not None:
        memory[np.asarray(episode_start, dtype=bool).reshape(n)] = -np.inf
    return memory


def remember_work(memory: np.ndarray, codes: np.ndarray, step: np.ndarray | float, peak: np.ndarray) -> np.ndarray:
    """The choice rules' memory (..., 3, S) after the action ``codes`` (..., S) at ``step`` (broadcast to them):
    the step of each section's last track work and last spot tamping, and its measured ``peak`` (as
    :func:`choice_view` reads it) where it is tamped or renewed. Updated in place and returned; any policy that
    answers in choice codes with a choice rule's help keeps its memory this way."""
    codes = np.asarray(codes, dtype=np.int64)
    memory[..., 0, :] = np.where(IS_TRACK_WORK[codes], step, memory[..., 0, :])
    memory[..., 1, :] = np.where(codes == SPOT_TAMP, step, memory[..., 1, :])
    memory[..., 2, :] = np.where((codes == TAMP) | (codes == RENEW), peak, memory[..., 2, :])
    return memory


class ChoiceThreshold(GroupedThreshold):
    """The grouped threshold with spot tamping, drainage, surveys, renewal and extra inspections (see the module
    docstring for each parameter; 0 or False switches a choice off)."""

    name: ClassVar[str] = "choice-threshold"
    #: the choices the family may ask for (names of :data:`~trackenv.envs.choices.CHOICES`); it takes the
    #: parameters that these read (:data:`CHOICE_OFF`)
    uses: ClassVar[frozenset[str]] = frozenset(CHOICES[1:])

    def __init__(self, trigger_mm: float = 3.5, include_mm: float = 1.75, spot_peak_mm: float = 0.0,
                 drain_surveyed: bool = True, drain_after_tampings: int = 0, fast_growth_mm_per_year: float = 1.0,
                 survey_fast: bool = False, survey_after_tampings: int = 0, survey_all: bool = False,
                 renew_after_tampings: int = 0,
                 inspect_margin_mm: float = 0.0, inspect_age_years: float = 0.5, inspect_peak_mm: float = 0.0,
                 check_peak_mm: float = 0.0,
                 choices: tuple[str, ...] = CHOICES[1:], choice_work: Mapping[str, float] | None = None,
                 min_steps_between_tampings: int = 1, **kw: Any) -> None:
        every = {"spot_peak_mm": spot_peak_mm, "drain_surveyed": bool(drain_surveyed),
                 "drain_after_tampings": int(drain_after_tampings),
                 "fast_growth_mm_per_year": fast_growth_mm_per_year,
                 "renew_after_tampings": int(renew_after_tampings),
                 "survey_fast": bool(survey_fast), "survey_after_tampings": int(survey_after_tampings),
                 "survey_all": bool(survey_all), "inspect_margin_mm": inspect_margin_mm,
                 "inspect_age_years": inspect_age_years, "inspect_peak_mm": inspect_peak_mm,
                 "check_peak_mm": check_peak_mm}
        params = {key: value for key, value in every.items() if CHOICE_OFF[key][0] & self.uses}
        for key in ("spot_peak_mm", "fast_growth_mm_per_year", "inspect_margin_mm", "inspect_age_years",
                    "inspect_peak_mm", "check_peak_mm"):
            if key in params and not params[key] >= 0:
                raise ValueError(f"{key} must be >= 0 (0: off), got {params[key]!r}")
        for key in ("drain_after_tampings", "survey_after_tampings", "renew_after_tampings"):
            if key in params and params[key] < 0:
                raise ValueError(f"{key} must be >= 0 (0: off), got {params[key]!r}")
        super().__init__(trigger_mm=trigger_mm, include_mm=include_mm, **params, **kw)
        #: per action code: whether the rule may ask for it (the config enables it and the family uses it)
        self.enabled = enabled_codes(set(choices) & self.uses)
        # unbound: the work of the default config's choices
        self.work = work_per_code(choice_work if choice_work is not None else LineConfig().choice_work)
        self.is_work = IS_TRACK_WORK
        self.min_steps = int(min_steps_between_tampings)

    def bind(self, config: Any) -> ChoiceThreshold:
        """A copy that knows ``config``'s calendar, capacity, enabled choices, their work (on each section: its
        length's) and the steps between track work on a section."""
        return type(self)(**self.params, steps_per_year=config.steps_per_year, horizon_steps=config.horizon_steps,
                          capacity=config.capacity, choices=tuple(config.choices),
                          choice_work=config.choice_work, length_factors=tuple(config.length_factors),
                          min_steps_between_tampings=config.min_steps_between_tampings)

    # ------------------------------------------------------------------ the decision
    def _wanted(self, obs: dict[str, np.ndarray], step: np.ndarray, last_spot: np.ndarray,
                peak_at_tamping: np.ndarray) -> np.ndarray:
        """(batch, S) the action code each section is asked for, before capacity and masks."""
        p = self.params
        sd, peak = obs["section_sd"], obs["section_peak"]
        peak = np.where(step[:, None] - last_spot <= _measurement_age(obs) * self.steps_per_year + 1e-6, 0.0, peak)
        growth = regrowth_mm_per_year(obs)
        fast = growth >= p.get("fast_growth_mm_per_year", np.inf)  # no family that reads it: never fast
        survey = np.asarray(obs.get("section_survey", np.full(sd.shape, -1)))
        tampings = np.asarray(obs["tampings"])
        codes = np.where(GroupedThreshold._act(self, obs), TAMP, 0)
        if p.get("renew_after_tampings"):
            renew = (codes == TAMP) & (obs["tampings_since_renewal"] >= p["renew_after_tampings"]) & fast
            codes = np.where(renew, RENEW, codes)
        if p.get("spot_peak_mm"):
            spot = (codes == 0) & (peak >= p["spot_peak_mm"]) & (sd < p["trigger_mm"])
            codes = np.where(spot, SPOT_TAMP, codes)
        drain = np.zeros(sd.shape, dtype=bool)
        if p.get("drain_surveyed"):
            drain |= survey == 1
        if p.get("drain_after_tampings"):
            drain |= (tampings >= p["drain_after_tampings"]) & fast & (survey != 0)
        codes = np.where(drain & (codes != RENEW), DRAINAGE, codes)
        if "inspect" in self.uses:
            inspect = self._inspect(obs) | self._check(obs, peak_at_tamping)
            codes = np.where((codes == 0) & inspect, INSPECT, codes)  # time presses: before a survey
        if "survey" in self.uses:
            codes = np.where((codes == 0) & self._survey(survey, fast, tampings), SURVEY, codes)
        return codes

    def _survey(self, survey: np.ndarray, fast: np.ndarray, tampings: np.ndarray) -> np.ndarray:
        p = self.params
        due = fast if p["survey_fast"] else np.full(fast.shape, bool(p["survey_all"]))
        if p["survey_after_tampings"]:
            due = due | (tampings >= p["survey_after_tampings"])
        return due & (survey == -1)

    def _inspect(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        p = self.params
        age = _measurement_age(obs)
        old = age >= p["inspect_age_years"]
        out = np.zeros(age.shape, dtype=bool)
        if p["inspect_margin_mm"]:
            years = np.maximum(np.asarray(obs["years_since_tamping"], dtype=float) - age, MIN_GROWTH_YEARS)
            projected = obs["section_sd"] + obs["section_sd"] / years * age
            out |= (projected >= p["trigger_mm"] - p["inspect_margin_mm"]) & (obs["section_sd"] < p["trigger_mm"])
        if p["inspect_peak_mm"]:
            out |= obs["section_peak"] >= p["inspect_peak_mm"]
        return out & old

    def _check(self, obs: dict[str, np.ndarray], peak_at_tamping: np.ndarray) -> np.ndarray:
        """The sections tamped since their last measurement whose peak before that tamping was at least
        ``check_peak_mm``."""
        if not self.params["check_peak_mm"]:
            return np.zeros(peak_at_tamping.shape, dtype=bool)
        return stale_measurement(obs) & (peak_at_tamping >= self.params["check_peak_mm"])

    def allowed(self, codes: np.ndarray, obs: dict[str, np.ndarray], step: np.ndarray,
                last_work: np.ndarray) -> np.ndarray:
        """``codes`` (batch, S) with what the env would mask or clip set to nothing: choices not enabled, track
        work too soon after the section's last (from ``years_since_tamping`` and ``last_work``, the step of the
        last track work asked for, at ``step`` (batch,)), and the work over ``capacity`` (worst measured SD first).
        Any policy that asks for choice codes with this rule's help filters them here (the line agent's choice
        mode)."""
        codes = np.where(self.enabled[codes], codes, 0)
        since_tamping = np.rint(np.asarray(obs["years_since_tamping"], dtype=float) * self.steps_per_year)
        since = np.minimum(since_tamping, step[:, None] - last_work)
        codes = np.where(self.is_work[codes] & (since <= self.min_steps), 0, codes)
        work = work_on_sections(self.work, codes, 1.0 if self.length_factors is None else self.length_factors)
        keep = fit_worst(work, np.asarray(obs["section_sd"], dtype=float), self.capacity)
        return np.where(keep, codes, 0)

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        """SB3-style: the action codes (int8 per section; batched if ``obs`` is) and the state, (batch, 3, S): the
        step of each section's last track work and last spot tamping asked for by this rule, and its measured peak
        when the rule last asked for its tamping (reset where ``episode_start``)."""
        b, batched = as_batch(obs)
        b = choice_view(b)
        n, S = b["section_sd"].shape
        memory = fresh_memory(state, episode_start, n, S)
        step = self._step(b).astype(float)
        codes = self.allowed(self._wanted(b, step, memory[:, 1], memory[:, 2]), b, step, memory[:, 0])
        remember_work(memory, codes, step[:, None], b["section_peak"])
        act = codes.astype(np.int8)
        return (act if batched else act[0]), memory

    @classmethod
    def param_grid(cls) -> list[dict[str, Any]]:
        """The default line's tuned grouped threshold with the choices switched on in turn and together
        (:func:`choice_grid`)."""
        return choice_grid(cls, {"trigger_mm": 3.5, "include_mm": 1.75})


class ChoiceThresholdNoLooking(ChoiceThreshold):
    """:class:`ChoiceThreshold` without inspections and surveys: the recording car's runs and the surveys made
    before the start are all it sees."""

    name: ClassVar[str] = "choice-threshold-no-looking"
    uses: ClassVar[frozenset[str]] = frozenset(CHOICES[1:]) - {"inspect", "survey"}


class ChoiceThresholdSpotOnly(ChoiceThreshold):
    """The grouped threshold with spot tamping and no other choice (no drainage, renewal, inspection or survey):
    its campaigns and ``spot_peak_mm`` are its parameters."""

    name: ClassVar[str] = "choice-threshold-spot-only"
    uses: ClassVar[frozenset[str]] = frozenset({"tamp", "spot_tamp"})


def choice_grid(cls: type[ChoiceThreshold], base: Mapping[str, float]) -> list[dict[str, Any]]:
    """The parameter sets searched for ``cls`` around the campaign ``base`` (trigger and include): spot tamping
    alone at :data:`SPOT_PEAKS_MM` for a family that uses no other choice; else drainage where surveyed with spot
    tamping at three peaks and a second-tamping drainage trigger, and for a family that surveys and inspects,
    surveys of every section first, and extra inspections on top (between runs, or of a high peak just tamped).
    With every choice off the family is the grouped threshold itself (:func:`choices_off`): the tuning compares
    against it."""
    off = choices_off(cls)
    drain = {**off, "drain_surveyed": True}
    if cls.uses <= {"tamp", "spot_tamp"}:
        grid = [{**off, "spot_peak_mm": peak} for peak in SPOT_PEAKS_MM]
    elif "survey" not in cls.uses:
        grid = [{**drain, "spot_peak_mm": 12.0}, {**drain, "spot_peak_mm": 9.0},
                {**drain, "spot_peak_mm": 9.0, "drain_after_tampings": 2}, {**drain, "spot_peak_mm": 7.0}]
    else:
        survey = {**drain, "survey_all": True}
        grid = [survey, {**survey, "spot_peak_mm": 12.0}, {**survey, "spot_peak_mm": 9.0},
                {**survey, "spot_peak_mm": 9.0, "inspect_margin_mm": 0.5, "inspect_peak_mm": 7.0},
                {**survey, "spot_peak_mm": 12.0, "check_peak_mm": 12.0},
                {**survey, "spot_peak_mm": 9.0, "check_peak_mm": 12.0},
                {**survey, "spot_peak_mm": 7.0, "check_peak_mm": 12.0}]
    return [{**base, **extra} for extra in grid]


def choices_off(cls: type[ChoiceThreshold]) -> dict[str, Any]:
    """The parameters of ``cls`` with every choice but tamping off (the grouped threshold itself)."""
    return {key: value for key, (readers, value) in CHOICE_OFF.items() if readers & cls.uses}


#: The parameters of :data:`CHOICE_OFF` that tune a choice switched on by another (a growth rate, an age), not a
#: switch themselves.
_MODIFIERS = frozenset({"fast_growth_mm_per_year", "inspect_age_years"})


def choices_on(params: Mapping[str, Any]) -> list[str]:
    """The choices beyond tamping that a choice rule's ``params`` switch on (in the order of
    :data:`~trackenv.envs.choices.CHOICES`): those with a switch of :data:`CHOICE_OFF` away from its off value."""
    on = {choice for key, (readers, off) in CHOICE_OFF.items()
          if key not in _MODIFIERS and key in params and params[key] != off for choice in readers}
    return [c for c in CHOICES[2:] if c in on]


CHOICE_RULES: dict[str, type[ChoiceThreshold]] = {
    c.name: c for c in (ChoiceThreshold, ChoiceThresholdNoLooking, ChoiceThresholdSpotOnly)}
