"""TampingEnv: decide every planning period which sections of a ballasted track to tamp.

Every step is physics: a vehicle pass over the standing track with its current level (implicit Newmark, Hertz
contact), the per-sleeper forces through a settlement law with curve shifting for a quarter-year of traffic,
and the new level fed back for the next pass (:class:`trackenv.TrackDegradation`). The Gymnasium layer is
:class:`~trackenv.envs.env.TrackEnv` over the 60 m track's engine (:class:`~trackenv.envs.episode.TrackEpisodes`).
"""

from __future__ import annotations

from typing import Any

from .config import TampingEnvConfig
from .env import TrackEnv
from .episode import Episode, observation_space

__all__ = ["TampingEnv", "observation_space"]


class TampingEnv(TrackEnv):
    """Plan tamping of a ballasted track over a horizon of years.

    **Description.** The track (default 60 m of UIC60 on concrete sleepers, 6 sections of 10 m) settles under
    traffic; settlement varies along the track with the ballast condition and with the dynamic forces, which the
    growing irregularity raises in turn. Each step is a planning period (default a quarter of a year, 500 000
    axle passes): the agent picks the sections to tamp at the start of the period, then one vehicle pass is
    simulated over the (tamped) geometry and the settlement advanced by the period's axle passes. Tamping
    restores the level but for a residual that keeps part of the old shape, restarts the fast consolidation
    phase, and damages the ballast so the section settles faster afterwards.

    **Action space.** ``MultiBinary(n_sections)``: 1 = tamp this section now (``trackenv/Tamping-v0``); or
    ``Discrete(n_sections + 1)``: 0 = nothing, k = tamp section k (``trackenv/TampingDiscrete-v0``). A section
    tamped within the last ``min_steps_between_tampings`` steps is masked (:meth:`action_masks`) and a request
    to tamp it is ignored (``info["tamped_sections"]`` says what was done). Malformed actions raise ValueError.

    **Observation** (``Dict``, float32):

    =====================  ====================================================  ======  ============
    key                    quantity                                              unit    bounds
    =====================  ====================================================  ======  ============
    level                  rail level per sleeper (downward +, vs design line)   mm      [-100, 200]
    contact_force          peak wheel/rail force per sleeper bay, last pass      kN      [0, 2000]
    section_sd             SD of the D1 (3-25 m) level per section               mm      [0, 100]
    section_peak           D1 mean-to-peak per section (isolated defects)        mm      [0, 200]
    tampings               tampings per section this episode                     -       [0, 1000]
    years_since_tamping    per section                                           year    [0, H+1]
    time                   fraction of the horizon elapsed                       -       [0, 1]
    =====================  ====================================================  ======  ============

    Values beyond a bound are clipped to it, never silently: ``info["observation_clipped"]`` counts them
    (``years_since_tamping`` of a never-tamped section is clipped by design and not counted). With the default
    "smoothing" tamping the level keeps its settlement (a tamper in that mode does not lift the track back to
    the design line), so under heavy traffic or over long horizons ``level`` can reach its 200 mm bound
    (seed 1, 10 years at 1e7 axle passes a year, tamping sections above 0.8 × the SD alert value: 5 of 40
    steps). ``tamping={"reference": "design", "max_lift_m": 0.02}`` models the lift instead (toward the
    design line, at most ``max_lift_m`` per pass): over 30 years of the default traffic the same rule then
    ends at a mean level of 4 mm instead of 82.

    **Info** (per step; units in the key where they are not obvious): track geometry in mm, like the
    observation and the EN 13848-5 limits; the physics inside is SI.

    ============================  ==================================================================  ====
    key                           quantity                                                            unit
    ============================  ==================================================================  ====
    costs, cost                   the period's cost in named parts, and their sum (= -reward)         k€
    section_costs                 each section's own costs: its tamping and quality costs (with the   k€
                                  campaign's mobilisation they add up to ``cost``; 0 at a reset)
    tamped_sections               sections tamped this step (bool, n_sections)                        -
    section_sd_mm                 SD of the D1 level per section (unclipped)                          mm
    section_peak_mm               D1 mean-to-peak per section (unclipped)                             mm
    section_sd_m, section_peak_m  the same in metres (kept for v0; prefer the mm keys)                m
    section_class                 EN 13848-5 class per section: 0 ok, 1 alert, 2 intervention, 3 IAL  -
    immediate_action_exceedances  sections at or above the immediate-action limit                     -
    year                          time at the end of the step                                         year
    max_contact_force_N           largest wheel/rail force of the step's pass                         N
    ============================  ==================================================================  ====

    **Reward.** Minus the period's cost (k€), returned in named parts in ``info["costs"]``: ``tamping``
    (mobilisation per campaign + per section), ``geometry`` (per section-year, ∝ (SD/SD_alert)²),
    ``alert``, ``intervention``, ``immediate_action`` (per section at or above the EN 13848-5 style limit of
    its speed band; the last a large penalty). reward = −Σ parts.

    **Episode end.** No terminal state: truncation at the horizon (default 10 years = 40 steps). The
    life-cycle cost counts the horizon only and ``time`` is observed, so a learner scored on that cost should
    treat the horizon as the end of the problem and not bootstrap past it (else it values tamping in the last
    year for benefits no evaluation counts); the SB3 adapter in ``trackenv_agents.learning.sb3_vec`` does so by
    default.

    **Arguments.** ``config`` (:class:`TampingEnvConfig` or dict) or its fields as keywords;
    ``action_type``; ``render_mode`` ("rgb_array").

    **Randomness.** Everything random (track supports, transition zone, voided sleepers, ballast condition,
    initial level, tamping residual) draws from ``self.np_random``, seeded by ``reset(seed=...)``.

    **Episode end** is enforced: ``step`` after the horizon raises RuntimeError until ``reset``; ``reset``
    refuses a seed that is not a non-negative integer and any ``options`` key (it takes none).

    **Versions.** v0: first release. Since then, without a change of dynamics or reward (same seeds and
    actions give the same observations, rewards and costs, so v0 is kept): ``step`` after the horizon raises,
    ``reset`` checks its seed and options, ``info["observation_clipped"]`` was added, and tamping gained the
    opt-in ``max_lift_m``; ``info`` reports the
    geometry in mm (``section_sd_mm``, ``section_peak_mm``) beside the metre keys; the numbers that draw a
    track (sleeper spacing, ballast-stiffness correlation, where a transition may sit, a voided sleeper's
    residual support) became config fields with the values they had.
    """

    def __init__(
        self,
        config: TampingEnvConfig | dict | None = None,
        *,
        action_type: str = "multibinary",
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        config = TampingEnvConfig.coerce(config)
        super().__init__(config.replace(**overrides) if overrides else config, action_type=action_type,
                         render_mode=render_mode)

    @property
    def episode(self) -> Episode | None:
        """The current episode (its simulator, level, counts), or None before the first reset."""
        return None if self.engine is None else self.engine.episodes[0]
