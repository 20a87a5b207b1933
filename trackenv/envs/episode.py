"""One tamping episode as plain functions over a :class:`TrackDegradation`: what a step does, apart from the
Gymnasium API. The single env and the vector env both call these, so the rules exist once."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np
from gymnasium import spaces
from scipy.ndimage import gaussian_filter1d

from ..degradation import TrackDegradation, settle_batch, simulate_batch
from ..physics.dynamics import PassResult
from ..physics.geometry import (
    classify,
    d1_filter,
    german_psd,
    section_index,
    section_peak,
    section_sd,
    synthesize_profile,
)
from ..physics.track import Track
from .common import SHARED_BOUNDS, clip_observation
from .common import observation_space as common_observation_space
from .config import TampingEnvConfig
from .costs import section_quality_costs
from .info import step_info

COST_KEYS = TampingEnvConfig.cost_keys()


@dataclass(eq=False)
class Episode:
    """The mutable state of one episode."""

    config: TampingEnvConfig
    sim: TrackDegradation
    sections: np.ndarray  # (n_sleepers,) section of each sleeper
    step_count: int = 0
    last_tamped_step: np.ndarray = field(default_factory=lambda: np.zeros(0))
    section_tampings: np.ndarray = field(default_factory=lambda: np.zeros(0))
    contact_force: np.ndarray = field(default_factory=lambda: np.zeros(0))  # per sleeper [N]
    tamped_last: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    transition_sleeper: int = -1
    _quality_cache: tuple | None = field(default=None, repr=False)

    @property
    def n_sections(self) -> int:
        return self.config.n_sections

    def quality(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """D1 level per sleeper, SD and mean-to-peak per section [m] (computed once per geometry: the level
        changes only when the simulator replaces its settlement state or offset)."""
        return self._geometry()[:3]

    def section_classes(self) -> np.ndarray:
        """Quality class per section (:func:`classify` of the section peaks in the config's speed band),
        computed with :meth:`quality`, once per geometry."""
        return self._geometry()[3]

    def _geometry(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        if not self._geometry_current():
            refresh_geometry([self])
        return self._quality_cache[2]  # type: ignore[index]  # set by refresh_geometry

    def _geometry_current(self) -> bool:
        cached = self._quality_cache
        return cached is not None and cached[0] is self.sim.state and cached[1] is self.sim.offset

    def mask(self) -> np.ndarray:
        """Sections that may be tamped now (not tamped within the last min_steps_between_tampings steps)."""
        k = self.config.min_steps_between_tampings
        return (self.step_count - self.last_tamped_step) > k


def copy_episode(ep: Episode) -> Episode:
    """An independent copy of ``ep`` that steps exactly as ``ep`` would (its simulator copied with
    :meth:`~trackenv.TrackDegradation.copy`, its arrays copied, its cached geometry kept): the snapshot behind
    ``TampingEnv.get_state`` / ``set_state``."""
    sim = ep.sim.copy()
    cache = (sim.state, sim.offset, ep._quality_cache[2]) if ep._geometry_current() else None  # type: ignore[index]
    return replace(ep, sim=sim, last_tamped_step=ep.last_tamped_step.copy(),
                   section_tampings=ep.section_tampings.copy(), contact_force=ep.contact_force.copy(),
                   tamped_last=ep.tamped_last.copy(), _quality_cache=cache)


def refresh_geometry(eps: list[Episode]) -> None:
    """Compute the geometry (D1 level, section SD and peak, classes) of every episode among ``eps`` whose level
    changed since it was last computed, all in one call of each function (one config: the vector env's envs).
    An episode's numbers are those it computes alone (the functions work row by row)."""
    stale = [ep for ep in eps if not ep._geometry_current()]
    if not stale:
        return
    ep0 = stale[0]
    if any(ep.config is not ep0.config and ep.config != ep0.config for ep in stale):
        raise ValueError("refresh_geometry needs episodes of one config")
    d1 = d1_filter(np.stack([ep.sim.level for ep in stale]), ep0.sim.track.sleeper_spacing)
    sd = section_sd(d1, ep0.sections, ep0.n_sections)
    peak = section_peak(d1, ep0.sections, ep0.n_sections)
    cls = classify(peak, ep0.config.band_limits)
    for b, ep in enumerate(stale):
        ep._quality_cache = (ep.sim.state, ep.sim.offset, (d1[b], sd[b], peak[b], cls[b]))


def _correlated_lognormal(rng: np.random.Generator, n: int, cv: float, corr_sleepers: float) -> np.ndarray:
    """Positive factors with mean 1 and coefficient of variation cv, correlated over corr_sleepers."""
    if cv == 0:
        return np.ones(n)
    z = rng.standard_normal(n + 40)
    if corr_sleepers > 0:
        z = gaussian_filter1d(z, corr_sleepers, mode="wrap")
    z = z[20:-20]
    z = (z - z.mean()) / (z.std() + 1e-12)
    sigma = np.sqrt(np.log1p(cv * cv))
    return np.exp(sigma * z - sigma * sigma / 2)


def new_episode(config: TampingEnvConfig, rng: np.random.Generator) -> Episode:
    """Draw a track, its ballast condition and its initial level from ``rng``."""
    c = config
    n = c.n_sleepers
    track = Track.realistic(c.track_length_m, sleeper_spacing=c.sleeper_spacing_m)
    spacing = track.sleeper_spacing
    kb = track.ballast_stiffness * _correlated_lognormal(
        rng, n, c.ballast_stiffness_cv, c.ballast_stiffness_correlation_m / spacing
    )
    transition = -1
    if rng.random() < c.transition_probability:
        lo, hi = (int(n * f + 1e-9) for f in c.transition_position)  # whole sleepers; 1e-9: 0.2 * 5 is 1
        transition = int(rng.integers(lo, hi))
        kb[transition:] *= c.transition_stiffness_ratio
    track = track.replace(ballast_stiffness=kb)
    for _ in range(int(rng.poisson(c.voided_sleepers_mean))):  # never the two end sleepers at either end
        track = track.with_voided_sleeper(int(rng.integers(2, n - 2)), residual_support=c.voided_residual_support)
    rate = _correlated_lognormal(rng, n, c.settlement_rate_cv, c.settlement_rate_correlation_m / spacing)
    level = synthesize_profile(track.sleeper_positions, partial(german_psd, quality=c.initial_quality), rng)
    sim = TrackDegradation(
        track,
        c.make_vehicle(),
        law=c.settlement_law,
        cycles_per_iteration=c.cycles_per_step,
        speed=c.speed,
        initial_level=level,
        rate_factor=rate,
        feedback="support",
        dt=c.dt,
    )
    ep = Episode(
        config=c,
        sim=sim,
        sections=section_index(n, c.n_sections),
        last_tamped_step=np.full(c.n_sections, -(10**6)),
        section_tampings=np.zeros(c.n_sections),
        contact_force=np.zeros(n),
        tamped_last=np.zeros(c.n_sections, dtype=bool),
        transition_sleeper=transition,
    )
    return ep


def apply_tamping(ep: Episode, sections_to_tamp: np.ndarray, rng: np.random.Generator) -> tuple[float, np.ndarray]:
    """Tamp the allowed sections among ``sections_to_tamp`` (bool, n_sections); return the tamping cost and
    the sections actually tamped (masked ones are ignored)."""
    c = ep.config
    tamped = sections_to_tamp & ep.mask()
    ep.tamped_last = tamped
    if not tamped.any():
        return 0.0, tamped
    ep.sim.tamp(tamped[ep.sections], c.tamping_model, rng)
    ep.last_tamped_step[tamped] = ep.step_count
    ep.section_tampings[tamped] += 1
    return c.mobilisation_cost + c.section_tamping_cost * int(tamped.sum()), tamped


def traffic_batch(eps: list[Episode], results: list[PassResult]) -> None:
    """The period's traffic for many episodes of one config: settle every sleeper under the forces of its
    episode's pass in ``results`` for the step's axle passes, the settlement steps in one batched call (each
    episode ends exactly as it would alone)."""
    for ep, result in zip(eps, results, strict=True):
        ep.contact_force = ep.sim.evaluated(result.contact_force_profile())
    settle_batch([ep.sim for ep in eps], results, eps[0].config.cycles_per_step)
    for ep in eps:
        ep.step_count += 1


def costs(ep: Episode, tamping_cost: float, tamped: np.ndarray) -> tuple[dict[str, float], np.ndarray]:
    """The period's costs in named parts (k€; the reward is minus their sum), and each section's own costs
    (k€, n_sections: its tamping and its quality costs; the mobilisation is the campaign's)."""
    c = ep.config
    _, sd, _ = ep.quality()
    per_section = section_quality_costs(
        sd, ep.section_classes(), sd_alert_m=c.band_limits.sd_alert_m,
        geometry_cost_per_section_year=c.geometry_cost_per_section_year, steps_per_year=c.steps_per_year,
        class_costs=c.class_costs)
    parts = {"tamping": float(tamping_cost), **{k: float(np.sum(v)) for k, v in per_section.items()}}
    return parts, sum(per_section.values(), c.section_tamping_cost * tamped)


def observation_bounds(config: TampingEnvConfig) -> dict[str, tuple[float, float]]:
    """Bounds of each observation key (the env's observation space is built from these, and the clipping in
    :func:`observation` uses them, so the two cannot drift apart)."""
    shared = SHARED_BOUNDS
    return {
        "level": shared["level"],
        "contact_force": (0.0, 2000.0),
        "section_sd": shared["section_sd"],
        "section_peak": shared["section_peak"],
        "tampings": shared["tampings"],
        "years_since_tamping": (0.0, config.horizon_years + 1.0),
        "time": shared["time"],
    }


def observation_space(config: TampingEnvConfig) -> spaces.Dict:
    """The Dict space of the observation table (its bounds: :func:`~trackenv.envs.episode.observation_bounds`)."""
    n, s = config.n_sleepers, config.n_sections
    bounds = observation_bounds(config)
    size = {"level": n, "contact_force": n, "time": 1}
    return common_observation_space(bounds, {key: (size.get(key, s),) for key in bounds})


def raw_observation(ep: Episode) -> dict[str, np.ndarray]:
    """The observed quantities in the units of TampingEnv's table, before clipping to the space's bounds."""
    c = ep.config
    _, sd, peak = ep.quality()
    return {
        "level": ep.sim.level * 1e3,
        "contact_force": ep.contact_force / 1e3,
        "section_sd": sd * 1e3,
        "section_peak": peak * 1e3,
        "tampings": np.asarray(ep.section_tampings, dtype=float),
        "years_since_tamping": (ep.step_count - ep.last_tamped_step) / c.steps_per_year,
        "time": np.array([min(ep.step_count / c.horizon_steps, 1.0)]),
    }


def observation(ep: Episode) -> dict[str, np.ndarray]:
    """The observation dict (see TampingEnv's table), clipped to its bounds (``info["observation_clipped"]``
    counts the values that were)."""
    return clip_observation(raw_observation(ep), observation_bounds(ep.config))


def observations(eps: list[Episode], keys) -> dict[str, np.ndarray]:
    """:func:`observation` of each of ``eps`` (one config), stacked (n_eps, ...) under ``keys`` (the space's
    order): each key clipped once for the whole batch, the numbers those of every episode alone."""
    bounds = observation_bounds(eps[0].config)
    raws = [raw_observation(ep) for ep in eps]
    return {k: np.clip(np.stack([r[k] for r in raws]), *bounds[k]).astype(np.float32) for k in keys}


def clipped_values(ep: Episode) -> int:
    """How many observed values lie outside their bounds (and are clipped in the observation).

    ``years_since_tamping`` of a never-tamped section counts from far back and is clipped by design; it is not
    counted."""
    bounds = observation_bounds(ep.config)
    raw = raw_observation(ep)
    return sum(
        np.count_nonzero(v < bounds[k][0]) + np.count_nonzero(v > bounds[k][1])
        for k, v in raw.items()
        if k != "years_since_tamping"
    )


def info(ep: Episode, parts: dict[str, float], tamped: np.ndarray, section_costs: np.ndarray | None = None) -> dict:
    """The step's info dict (see TampingEnv's table): track geometry in mm like the observation, each key
    naming its unit; ``section_sd_m`` and ``section_peak_m`` are the same numbers in metres, kept for v0;
    ``section_costs`` (zeros at a reset) as :func:`costs` gives them."""
    _, sd, peak = ep.quality()
    own = np.zeros(ep.n_sections) if section_costs is None else np.asarray(section_costs, dtype=float).copy()
    return step_info(parts, tamped, sd, peak, ep.section_classes(), ep.step_count / ep.config.steps_per_year,
                     ep.contact_force.max(), section_costs=own, observation_clipped=clipped_values(ep))


class TrackEpisodes:
    """The episode engine of the 60 m track: ``n_rows`` episodes of one config, each an :class:`Episode`, their
    passes in one batched call of the dynamics (:func:`~trackenv.degradation.simulate_batch`, which the compiled
    kernel spreads over the cores). The rules of a step are the functions of this module; the engine is what
    every env of the 60 m track (single or vector) steps, with the interface of the line's engine
    (:class:`~trackenv.envs.line_episode.LineBatch`): :meth:`start`, :meth:`advance` (a step), :meth:`observation`,
    :meth:`observations`, :meth:`reset_info`, :meth:`allowed`, :meth:`step_count`, :meth:`get_state`,
    :meth:`set_state`, :meth:`frame`.

    Each row draws from its own generator (``rngs[i]``, the env's): its track at :meth:`start` and the tamping
    residuals as it steps, so a row's numbers depend on its seed and actions only."""

    def __init__(self, config: TampingEnvConfig, n_rows: int) -> None:
        self.config = config
        self.episodes: list[Episode] = [None] * int(n_rows)  # type: ignore[list-item]  # filled by start()

    def _new_episodes(self, idx: list[int], rngs: list[np.random.Generator],
                      others: list[Episode] = ()) -> list[PassResult]:  # type: ignore[assignment]
        """Start new episodes in rows ``idx`` (a traffic-free pass each); the passes of ``others`` (episodes about
        to take their traffic step) run in the same batched call, and their results are returned."""
        eps = [new_episode(self.config, rngs[i]) for i in idx]
        results = simulate_batch([ep.sim for ep in others] + [ep.sim for ep in eps])
        for i, ep, res in zip(idx, eps, results[len(others):]):
            ep.contact_force = ep.sim.evaluated(res.contact_force_profile())
            self.episodes[i] = ep
        return results[:len(others)]

    def start(self, idx: list[int], rngs: list[np.random.Generator]) -> None:
        """New episodes in rows ``idx``, drawn from their generators ``rngs[i]``."""
        self._new_episodes(idx, rngs)
        refresh_geometry([self.episodes[i] for i in idx])

    def advance(self, want: np.ndarray, stepping: list[int], rngs: list[np.random.Generator],
                resetting: list[int] = ()) -> tuple[np.ndarray, np.ndarray, dict[int, dict]]:  # type: ignore[assignment]
        """One step of the rows ``stepping``, which ask to tamp ``want`` (rows, n_sections) bool, and new episodes
        in ``resetting``, their passes in one batch: the rewards and truncation flags (rows,; 0 and False
        elsewhere) and the info of each stepped row."""
        n = len(self.episodes)
        tamping = {i: apply_tamping(self.episodes[i], want[i], rngs[i]) for i in stepping}
        results = self._new_episodes(list(resetting), rngs, [self.episodes[i] for i in stepping])
        if stepping:
            traffic_batch([self.episodes[i] for i in stepping], results)
        refresh_geometry(self.episodes)  # the new levels' D1 (stepped and new episodes), for costs, info, obs
        rewards = np.zeros(n)
        truncated = np.zeros(n, dtype=bool)
        infos: dict[int, dict] = {}
        for i in stepping:
            ep = self.episodes[i]
            cost, tamped = tamping[i]
            parts, section_costs = costs(ep, cost, tamped)
            rewards[i] = -sum(parts.values())
            truncated[i] = ep.step_count >= self.config.horizon_steps
            infos[i] = info(ep, parts, tamped, section_costs)
        return rewards, truncated, infos

    def observation(self, i: int) -> dict[str, np.ndarray]:
        return observation(self.episodes[i])

    def observations(self, keys) -> dict[str, np.ndarray]:
        return observations(self.episodes, keys)

    def reset_info(self, i: int) -> dict:
        return info(self.episodes[i], dict.fromkeys(COST_KEYS, 0.0), np.zeros(self.config.n_sections, dtype=bool))

    def allowed(self) -> np.ndarray:
        """(rows, n_sections) the sections that may be tamped now."""
        return np.array([ep.mask() for ep in self.episodes])

    def step_count(self, i: int) -> int:
        """Steps row ``i`` has taken in its episode."""
        return self.episodes[i].step_count

    def get_state(self, i: int) -> Episode:
        """A copy of row ``i``'s episode that :meth:`set_state` restores exactly."""
        return copy_episode(self.episodes[i])

    def set_state(self, i: int, state: Episode) -> None:
        self.episodes[i] = copy_episode(state)

    def frame(self, i: int, last_info: dict) -> np.ndarray:
        """An RGB picture of row ``i`` (:func:`trackenv.render.episode_frame`)."""
        from ..render import episode_frame

        return episode_frame(self.episodes[i], last_info)
