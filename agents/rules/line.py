"""Rules a railway would use, on every preset of the one environment (the lines and the 60 m track), with SB3's
``predict`` (batched observation dicts).

All act on what the planner observes (measured SD, register, years since tamping, time) and respect the
possession capacity themselves, worst measured SD first, so the env never has to clip them. A section tamped
since the last recording run is known to be fresh: its measured SD and peak are those from before the tamping
(:func:`stale_measurement`), so every rule reads them as 0, not due (without this, a threshold rule tamped
every section a second time two steps later, on the same stale measurement):

* :class:`UniformPeriodic` — the whole line every ``interval_years`` (in capacity-sized campaigns on
  consecutive steps);
* :class:`SectionThreshold` — each section when its measured SD reaches ``threshold_mm``;
* :class:`GroupedThreshold` — a campaign is called when a section reaches ``trigger_mm``; it then takes every
  section above ``include_mm`` (opportunistic grouping, Soleimanmeigouni et al. 2021);
* :class:`RegisterPeriodic` — plain track every ``plain_years``, known zones (register) every ``zone_years``;
* :class:`BudgetedWorstFirst` — every ``every_years`` a campaign of the ``n_worst`` worst sections above
  ``min_sd_mm``.

The per-section hindsight bound is :mod:`trackenv_agents.evaluation.line_hindsight`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from trackenv.envs.line_episode import fit_worst, keep_worst

from .base import Heuristic, as_batch

__all__ = ["BudgetedWorstFirst", "GroupedThreshold", "LINE_HEURISTICS", "RegisterPeriodic", "SectionThreshold",
           "UniformPeriodic", "LineNoMaintenance", "FRESH_SD_MM", "LINE_TUNED_FILE", "line_tuned_params",
           "planner_view", "projected_geometry", "stale_measurement"]


def stale_measurement(obs: Mapping[str, Any]) -> Any:
    """(batch, S) bool: the sections tamped in this episode since their last measurement, whose measured SD and
    peak therefore describe the track *before* that tamping. A tamping at step t comes after the run of step t
    (runs close a step), so a section is stale when its years since tamping are at most the measurement's age:
    each section's own (``section_measurement_age``) where the problem observes it (with inspections, a trolley
    measures single sections), else the recording car's (``measurement_age``); sections not tamped in the
    episode are never stale (their last tamping preceded the first run). Batched observations as numpy arrays
    or torch tensors (the per-section policy reads the same flag)."""
    age = obs["section_measurement_age"] if "section_measurement_age" in obs else obs["measurement_age"]
    return (obs["years_since_tamping"] <= age + STALE_TOLERANCE_YEARS) & (obs["tampings"] > 0)


#: float32 years are quarters (0.25 apart): this tolerance separates equal from one step apart
STALE_TOLERANCE_YEARS = 1e-3


#: The SD a tamping leaves a section at, for the growth estimate: α + β·SD before with the calibrated α = 0.14 mm,
#: β = 0.24 (the documentation's line-problem page, calibration) at a 3 mm SD before.
FRESH_SD_MM = 0.9


def projected_geometry(obs: Mapping[str, Any], lead_years: float = 0.0) -> tuple[np.ndarray, ...]:
    """(growth mm/year, projected SD mm, projected peak mm), each (batch, S) float64, of a batched line
    observation: each section's SD growth since its last tamping as measured (from :data:`FRESH_SD_MM` over the
    years from that tamping to the recording run, at least a quarter), and its SD and mean-to-peak carried on at
    that growth over the measurement's age and ``lead_years`` more (the peak scaled like the SD). A section tamped
    since the recording run (:func:`stale_measurement`) is taken as fresh: no growth, SD :data:`FRESH_SD_MM`,
    peak 0. Why: the recording car runs once a year, so the measured state is up to a year old; the per-section
    policy's features and the network's dispatch by value read the track from the same projection."""
    o = {k: np.asarray(obs[k], dtype=np.float64) for k in ("section_sd", "section_peak", "years_since_tamping",
                                                          "measurement_age")}
    sd, peak = o["section_sd"], o["section_peak"]
    age = o["measurement_age"].reshape(sd.shape[0], 1)
    stale = np.asarray(stale_measurement(obs), dtype=bool)
    since = np.maximum(o["years_since_tamping"] - age, 0.25)  # from the last tamping to the recording run
    growth = np.where(stale, 0.0, np.maximum(sd - FRESH_SD_MM, 0.0) / since)
    projected = np.where(stale, FRESH_SD_MM, sd + growth * (age + lead_years))
    ratio = np.where(sd > 1e-6, projected / np.maximum(sd, 1e-6), 1.0)
    projected_peak = np.where(stale, 0.0, peak * ratio)
    return growth, projected, projected_peak


def planner_view(obs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The batched observation as the rules read it: the measured SD and peak of a section tamped since the last
    recording run (:func:`stale_measurement`) set to 0 (fresh, not due), everything else as observed."""
    stale = stale_measurement(obs)
    out = dict(obs)
    for key in ("section_sd", "section_peak"):
        if key in obs:
            out[key] = np.where(stale, np.zeros_like(obs[key]), obs[key])
    return out


class LineHeuristic(Heuristic):
    """Base: knows the line's calendar and capacity once bound to its config."""

    #: each section's length over the line's, where sections differ in length (else None)
    length_factors: np.ndarray | None = None

    def __init__(self, steps_per_year: int = 4, horizon_steps: int = 40, capacity: int = 6,
                 length_factors: Sequence[float] | None = None, **params: Any) -> None:
        super().__init__(**params)
        self.steps_per_year = int(steps_per_year)
        self.horizon_steps = int(horizon_steps)
        self.capacity = int(capacity)
        #: each section's length over the line's (``LineConfig.length_factors``: a tamping's work scales with it);
        #: None where every section has the line's length
        factors = None if length_factors is None else np.asarray(length_factors, dtype=float)
        self.length_factors = None if factors is None or (factors == 1.0).all() else factors

    def bind(self, config: Any) -> LineHeuristic:
        return type(self)(**self.params, steps_per_year=config.steps_per_year,
                          horizon_steps=config.horizon_steps, capacity=config.capacity,
                          length_factors=getattr(config, "length_factors", None))

    def _step(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        return np.rint(obs["time"][:, 0].astype(float) * self.horizon_steps).astype(int)

    def _steps(self, years: float) -> int:
        return max(int(round(years * self.steps_per_year)), 1)

    def _cap(self, want: np.ndarray, obs: dict[str, np.ndarray]) -> np.ndarray:
        """``want`` within the capacity, worst measured SD first: in sections, or in their work where sections
        differ in length."""
        if self.length_factors is None:
            return keep_worst(want, obs["section_sd"], self.capacity)
        work = np.where(want, self.length_factors, 0.0)
        return want & fit_worst(work, np.asarray(obs["section_sd"], dtype=float), self.capacity)

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        b, batched = as_batch(obs)
        b = planner_view(b)
        act = np.asarray(self._cap(self._act(b), b), dtype=np.int8)
        return (act if batched else act[0]), state


class LineNoMaintenance(LineHeuristic):
    name: ClassVar[str] = "no-maintenance"

    def _act(self, obs):
        return np.zeros_like(obs["section_sd"], dtype=bool)


class UniformPeriodic(LineHeuristic):
    """The whole line every ``interval_years``: campaign i of a cycle tamps sections [i·k, (i+1)·k) (k the
    capacity) on consecutive steps, starting at ``offset_years`` into the episode."""

    name: ClassVar[str] = "uniform-periodic"

    def __init__(self, interval_years: float = 3.0, offset_years: float = 0.0, **kw: Any) -> None:
        super().__init__(interval_years=interval_years, offset_years=offset_years, **kw)

    def _act(self, obs):
        S = obs["section_sd"].shape[1]
        # steps since the offset; not _steps, whose floor of one step is for intervals (an offset may be 0)
        t = self._step(obs) - int(round(self.params["offset_years"] * self.steps_per_year))
        phase = np.mod(t, self._steps(self.params["interval_years"]))
        chunk = np.arange(S) // self.capacity
        return (t[:, None] >= 0) & (chunk[None, :] == phase[:, None])

    @classmethod
    def param_grid(cls):
        return [{"interval_years": i, "offset_years": 0.0} for i in (1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0)]


class SectionThreshold(LineHeuristic):
    name: ClassVar[str] = "section-threshold"

    def __init__(self, threshold_mm: float = 2.0, **kw: Any) -> None:
        super().__init__(threshold_mm=threshold_mm, **kw)

    def _act(self, obs):
        return obs["section_sd"] >= self.params["threshold_mm"]

    @classmethod
    def param_grid(cls):
        return [{"threshold_mm": v} for v in (1.5, 2.0, 2.5, 3.0, 3.5)]


class GroupedThreshold(LineHeuristic):
    name: ClassVar[str] = "grouped-threshold"

    def __init__(self, trigger_mm: float = 2.5, include_mm: float = 1.5, **kw: Any) -> None:
        super().__init__(trigger_mm=trigger_mm, include_mm=include_mm, **kw)

    def _act(self, obs):
        sd = obs["section_sd"]
        call = (sd >= self.params["trigger_mm"]).any(axis=1, keepdims=True)
        return call & (sd >= min(self.params["include_mm"], self.params["trigger_mm"]))

    @classmethod
    def param_grid(cls):
        first = [(t, i) for t in (2.5, 3.0, 3.5) for i in (1.25, 1.5, 2.0)]
        refined = [(t, i) for t in (3.5, 4.0, 5.0) for i in (2.0, 2.5, 3.0) if (t, i) not in first]
        lower = [(2.0, 1.0), (2.0, 1.25), (2.0, 1.5), (2.5, 1.0), (3.0, 1.0)]  # rules that read stale data as fresh
        lowest = [(1.5, 0.75), (1.5, 1.0), (1.25, 0.75)]  # lines that settle fast for their limits (a line file's)
        return [{"trigger_mm": t, "include_mm": i} for t, i in first + refined + lower + lowest]


class RegisterPeriodic(LineHeuristic):
    """Plain sections every ``plain_years``, known zones (register > 0) every ``zone_years``, each set in
    capacity-sized campaigns on consecutive steps."""

    name: ClassVar[str] = "register-periodic"

    def __init__(self, plain_years: float = 5.0, zone_years: float = 1.5, **kw: Any) -> None:
        super().__init__(plain_years=plain_years, zone_years=zone_years, **kw)

    def _act(self, obs):
        t = self._step(obs) + 1
        zone = obs["register"] > 0
        out = np.zeros_like(zone)
        for sel, years in ((~zone, self.params["plain_years"]), (zone, self.params["zone_years"])):
            rank = np.cumsum(sel, axis=1) - 1  # order of the section within its set
            phase = np.mod(t, self._steps(years))
            out |= sel & (rank // self.capacity == phase[:, None])
        return out

    @classmethod
    def param_grid(cls):
        return [{"plain_years": p, "zone_years": z}
                for p, z in ((4.0, 1.5), (6.0, 1.0), (6.0, 1.5), (6.0, 2.5), (8.0, 1.5), (10.0, 1.5), (4.0, 1.0),
                             (8.0, 1.0), (6.0, 0.5), (6.0, 0.75))]


class BudgetedWorstFirst(LineHeuristic):
    name: ClassVar[str] = "budgeted-worst-first"

    def __init__(self, every_years: float = 1.0, n_worst: int = 3, min_sd_mm: float = 1.5, **kw: Any) -> None:
        super().__init__(every_years=every_years, n_worst=n_worst, min_sd_mm=min_sd_mm, **kw)

    def _act(self, obs):
        t = self._step(obs)
        due = (np.mod(t, self._steps(self.params["every_years"])) == 0)[:, None]
        want = due & (obs["section_sd"] >= self.params["min_sd_mm"])
        return keep_worst(want, obs["section_sd"], int(self.params["n_worst"]))

    @classmethod
    def param_grid(cls):
        return [{"every_years": e, "n_worst": k, "min_sd_mm": m}
                for e, k, m in ((1.0, 2, 1.5), (1.0, 3, 2.0), (1.0, 4, 2.0), (1.0, 3, 2.5), (0.5, 2, 2.0),
                                (0.5, 3, 2.5), (0.25, 3, 2.5), (0.5, 3, 3.0), (0.5, 4, 2.5), (0.25, 2, 3.0),
                                (0.5, 2, 2.5))]


LINE_HEURISTICS: dict[str, type[LineHeuristic]] = {
    c.name: c for c in (LineNoMaintenance, UniformPeriodic, SectionThreshold, GroupedThreshold, RegisterPeriodic,
                        BudgetedWorstFirst)
}


#: the line heuristics' parameters tuned on training seeds by experiments/line_room.py --save-tuned
LINE_TUNED_FILE = Path(__file__).resolve().parent / "line_tuned_heuristics.json"


def line_tuned_params(path: str | Path | None = None) -> dict[str, dict[str, Any]]:
    """The shipped tuned parameters by heuristic name ({} when none were saved)."""
    p = Path(path) if path is not None else LINE_TUNED_FILE
    return json.loads(p.read_text())["params"] if p.exists() else {}
