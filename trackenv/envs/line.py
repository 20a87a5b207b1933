"""TampingLine: when and where to tamp a railway line of 200 m sections, with the physics in every step.

:class:`TampingLine` (one line) and :class:`TampingLineVectorEnv` (many, every segment of every line in one
batched pass per vehicle type) are :class:`~trackenv.envs.env.TrackEnv` and
:class:`~trackenv.envs.env.TrackVectorEnv`, the Gymnasium layer of every problem, over the line's engine
(:class:`~trackenv.envs.line_episode.LineBatch`, which holds the rules); the parameters and the scenario suite
are in :mod:`trackenv.envs.line_config`.
"""

from __future__ import annotations

from typing import Any

from gymnasium.vector import AutoresetMode

from .env import TrackEnv, TrackVectorEnv
from .line_config import LineConfig
from .line_episode import LineBatch, line_observation_space

__all__ = ["TampingLine", "TampingLineVectorEnv", "line_observation_space"]


def line_config(config: LineConfig | dict | str | None, scenario: str | None, overrides: dict[str, Any]) -> LineConfig:
    """The config of a TampingLine env from its arguments: ``config`` (a config, a dict or a scenario name),
    else ``scenario``, else the default line, with the field ``overrides`` (``max_episode_steps``, which
    ``gym.make`` may pass, is dropped: the env truncates itself at its horizon)."""
    overrides.pop("max_episode_steps", None)
    out = LineConfig.coerce(scenario if config is None and scenario is not None else config)
    return out.replace(**overrides) if overrides else out


class TampingLineVectorEnv(TrackVectorEnv):
    """``num_envs`` TampingLine episodes (same config), stepped together: every segment of every line in one
    batched pass per vehicle type. See :class:`TampingLine` for the spec.

    The Gymnasium conventions are those of every native vector env of trackenv (:mod:`trackenv.envs.batched`):
    ``autoreset_mode`` ``AutoresetMode.SAME_STEP`` (default: a line resets in the step it ends, the last
    observation and info of the old episode in ``infos["final_obs"]`` and ``infos["final_info"]``) or
    ``NEXT_STEP`` (the ending step keeps them in place; the next step resets the line and ignores its action),
    each giving what ``gymnasium.vector.SyncVectorEnv`` over :class:`TampingLine` gives in that mode, infos with
    their ``_key`` masks; ``reset(seed=s)`` seeds line ``i`` with ``s + i`` (or a list of one seed per line);
    ``render_mode="rgb_array"``: :meth:`render` draws the first line."""

    def __init__(self, num_envs: int = 4, config: LineConfig | dict | str | None = None, *,
                 scenario: str | None = None, action_type: str = "multibinary",
                 autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP,
                 render_mode: str | None = None, **overrides: Any) -> None:
        super().__init__(num_envs, line_config(config, scenario, overrides), action_type=action_type,
                         autoreset_mode=autoreset_mode, render_mode=render_mode)

    @property
    def batch(self) -> LineBatch | None:
        """The engine: every line's segments as rows (:class:`~trackenv.envs.line_episode.LineBatch`), or None
        before the first reset."""
        return self.engine


class TampingLine(TrackEnv):
    """Plan tamping of a railway line: which 200 m sections to tamp, and when, from recording-car data.

    **Description.** A line of ``n_sections`` sections of 200 m (default 12: 2.4 km) at 100 km/h carrying
    15 MGT a year (60 % passenger coaches at 11.1 t per axle, 40 % freight at 22.5 t). Each section is one
    physics *segment* of 30 m of standing track (ballast stiffness field, settlement-rate field, special zone)
    whose D1 SD stands for the section's. Every step (a quarter of a year) is physics: the tamping chosen at
    its start, then one pass of each vehicle type over every segment of every line in one batched
    :func:`~trackenv.physics.dynamics.simulate_passes` call per type, the peak sleeper forces combined into
    the equivalent force of the traffic mix, and the settlement advanced by the quarter's axle passes with
    the static load redistribution of settled supports (implicit), the new level feeding the next pass.
    Sections differ: plain-track rates lognormal and correlated along the line, transition zones and
    switches/level crossings (in the register), hidden wet spots that start mid-episode (in no register).
    Tamping restores less on worse track (SD after rises with SD before), restarts consolidation and damages
    the ballast (faster settlement after each tamping) until the 9th tamping, which is a ballast renewal.

    **Scenarios** (registered ids; ``LineConfig`` fields in :data:`~trackenv.envs.line_config.SCENARIOS`):

    ==================================  ========  ========  ================================================
    id                                  sections  capacity  differences from the default
    ==================================  ========  ========  ================================================
    ``trackenv/TampingLineSmall-v0``    6         3         tests and quick studies
    ``trackenv/TampingLine-v0``         12        6         the default line
    ``trackenv/TampingLineHard-v0``     24        4         more zones and hidden spots, budget 60 k€/year
    ``trackenv/TampingLineLong-v0``     250       25        50 km
    ``trackenv/TampingLine-v1``         12        6         every choice (below), the contact sensor
    ``trackenv/TampingLineWet-v0``      12        6         choices; many wet spots, half the line surveyed
    ``trackenv/TampingLineDefects-v0``  12        6         choices; switches and short local defects
    ``trackenv/Tamping-v1``             6         6         the 60 m track: :class:`~trackenv.envs.tamping.TampingEnv`
    ==================================  ========  ========  ================================================

    **Action space.** ``MultiBinary(n_sections)``: 1 = tamp this section in this step's campaign (one
    possession per step); or, with ``action_type="discrete"``, ``Discrete(n_sections + 1)``: 0 = nothing,
    k = tamp section k. Sections tamped within ``min_steps_between_tampings`` steps are masked
    (:meth:`action_masks`) and dropped. More than ``capacity`` sections, or a campaign over the remaining
    annual budget: with ``over_capacity="clip"`` (default; the checkers sample unconstrained actions) the
    allowed sections with the worst *measured* SD are kept and ``info["clipped"]`` is True; with
    ``over_capacity="raise"`` a ValueError. Malformed actions raise ValueError.

    With ``action_type="choices"`` (the ids ``TampingLine-v1``, ``TampingLineWet-v0``, ``TampingLineDefects-v0``):
    ``MultiDiscrete([7] * n_sections)``, one choice per section by its code in
    :data:`~trackenv.envs.choices.CHOICES`: 0 nothing, 1 tamp, 2 spot tamp, 3 drainage, 4 ballast renewal,
    5 inspect (an extra measurement by a trolley), 6 survey (does a wet spot lie under the section?); those not
    in ``LineConfig.choices`` act as nothing. ``capacity`` then counts work in tamping-section equivalents
    (``LineConfig.choice_work``), and the masks are ``(n_sections · 7,)``, each section's codes in turn. The
    effects, costs and work of each choice: the documentation's page "What a track manager decides".

    **Observation** (``Dict``, float32; what a planner has):

    ======================  ===============================================================  =====  ========
    key                     quantity                                                         unit   bounds
    ======================  ===============================================================  =====  ========
    section_sd              last measured SD of the D1 (3-25 m) level per section            mm     [0, 100]
    section_peak            last measured D1 mean-to-peak per section                        mm     [0, 200]
    measurement_age         time since that recording-car run                                year   [0, H+1]
    register                asset register: 0 plain, 1 transition zone, 2 switch/crossing    -      [0, 2]
    tampings                tampings per section this episode                                -      [0, 1000]
    tampings_since_renewal  tampings since the last ballast renewal                          -      [0, 1000]
    years_since_tamping     per section (sections start 0-3 years after their last)          year   [0, 100]
    time                    fraction of the horizon elapsed                                  -      [0, 1]
    budget_left             remaining share of the annual budget (1 without a budget)        -      [0, 1]
    level (``profiles``)    measured rail level per sleeper of each segment                  mm     [-100, 200]
    contact_force (same)    largest wheel/rail force over each sleeper bay, this step        kN     [0, 2000]
    section_contact_peak    peak wheel/rail force per section, as an instrumented vehicle    kN     [0, 2000]
    (``contact_sensor``)    reads it (relative error ``contact_sensor_noise``)
    section_dynamic_share   that peak over the static wheel load, minus 1                    -      [-1, 20]
    (``contact_sensor``)
    section_measurement_    time since the section was last measured (recording car or       year   [0, H+1]
    age (``inspect``)       trolley)
    section_survey          what a survey found: -1 not surveyed, 0 no wet cause, 1 one      -      [-1, 1]
    (``survey``)
    ======================  ===============================================================  =====  ========

    The true state is in ``info``: ``section_sd_m``, ``section_peak_m``, ``section_class`` (0 OK, 1 alert,
    2 intervention, 3 immediate action, EN 13848-5 style at 100 km/h), ``wet_spot_active``, ``rate_factor``.
    A value beyond its bound is clipped in the observation, never silently: ``info["observation_clipped"]``
    counts them.
    ``info["section_costs"]``: each section's own costs of the step (k€: its tamping or renewal, or its other
    choice, geometry, speed restriction, immediate action); with the line's possession they add up to the step's
    cost (a learner can credit each section's choice with its own costs). ``info["choices"]``: how many sections
    got each choice this step, by name (``tamp``, ``spot_tamp``, ``drainage``, ``renew``, ``inspect``,
    ``survey``); ``info["section_choices"]``: each section's applied code; ``info["tamped_sections"]``: tamped
    or renewed.

    **Reward.** −Σ of the step's cost parts (k€) in ``info["costs"]``: ``possession`` (per campaign),
    ``tamping`` (per metre × 200 m per section), ``renewal``, ``spot_tamping``, ``drainage``, ``inspection``,
    ``survey`` (the choices'; 0 without them), ``geometry`` (per section-year ∝ (SD/SD_alert)²), ``alert``
    (per section-step in the alert class), ``speed_restriction`` (per section-step at or above the intervention
    limit), ``immediate_action`` (per section-step at the immediate-action limit). Defaults and sources:
    :class:`~trackenv.envs.line_config.LineConfig`.

    **Episode end.** No terminal state; truncation at the horizon (default 10 years = 40 steps), enforced:
    ``step`` after the horizon raises RuntimeError until ``reset``; ``reset`` refuses a seed that is not a
    non-negative integer and any ``options`` key (it takes none).

    **Vector env.** ``gym.make_vec(id, num_envs=n, vectorization_mode="vector_entry_point")`` builds
    :class:`TampingLineVectorEnv` (every segment of every line in one batched pass per vehicle type), with the
    conventions of every native vector env of trackenv (:mod:`trackenv.envs.batched`): ``autoreset_mode``
    ``AutoresetMode.SAME_STEP`` (default; the ended episode's last observation and info in
    ``infos["final_obs"]`` and ``infos["final_info"]``) or ``NEXT_STEP`` (Gymnasium's default: the ending step
    keeps them in place, the next step resets the line), infos as a dict of arrays with ``_key`` masks. Line
    ``i`` gives bit for bit what this env gives for the same seed and actions (``SyncVectorEnv`` over it in the
    same mode gives the same results).

    **Rendering.** ``render_mode="rgb_array"``: :meth:`render` returns an (H, W, 3) uint8 picture of the line
    (:func:`trackenv.render.line_frame`): per section the true and the last measured SD and D1 mean-to-peak
    against their limits, the sections tamped this step shaded (the vector env draws its first line).

    **Arguments.** ``config`` (:class:`LineConfig`, dict or scenario name), ``scenario``, or fields as
    keywords; ``line``: a line file (``gym.make(id, line="my_line.yaml")``: its sections, register, wet zones,
    traffic, state and measured history; :mod:`trackenv.envs.line_file`), which sets the number of sections, their
    length, the speed and the traffic; ``render_mode`` (None or "rgb_array"). **Randomness**: everything is
    drawn at reset from ``self.np_random`` (see :mod:`~trackenv.envs.line_episode`).

    **Versions.** v0: first release. Since then, without a change of dynamics or reward: ``render_mode=
    "rgb_array"``; the vector env's two autoreset modes and Gymnasium's info layout (``final_info`` a dict of
    arrays, as ``SyncVectorEnv`` gives it, where it was an object array of per-line dicts); the settlement's
    Newton iteration stops per segment and the least-squares lines are summed row by row, so a line's numbers
    no longer depend on the other lines of a batch (costs moved by ~1e-9 relative, within the Newton tolerance);
    ``info["section_costs"]``; ``info["observation_clipped"]``; lines from files (``line=``; a line without one is
    drawn as before, bit for bit); ``action_type="choices"`` and the config fields of the choices, with the zero
    cost parts of the choices and ``info["choices"]`` (without the choices, the same draws, rewards and
    observations, bit for bit). v1 (``TampingLine-v1``): the default line with every choice and the contact
    sensor.
    """

    def __init__(self, config: LineConfig | dict | str | None = None, *, scenario: str | None = None,
                 action_type: str = "multibinary", render_mode: str | None = None, **overrides: Any) -> None:
        super().__init__(line_config(config, scenario, overrides), action_type=action_type, render_mode=render_mode)

    @property
    def batch(self) -> LineBatch | None:
        """The engine: a batch of this one line (:class:`~trackenv.envs.line_episode.LineBatch`), or None before
        the first reset."""
        return self.engine
