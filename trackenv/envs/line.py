"""TampingLine: when and where to tamp a railway line of 200 m sections, with the physics in every step.

One class does the work, :class:`TampingLineVectorEnv` (natively batched over lines: every segment of every
line runs in one batched pass per vehicle type); :class:`TampingLine` is its batch of one behind the
``gymnasium.Env`` API. The rules live in :mod:`trackenv.envs.line_episode`, the parameters and the scenario
suite in :mod:`trackenv.envs.line_config`.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array

from ._seeding import vector_rngs
from .line_config import LineConfig
from .line_episode import COST_KEYS, LineBatch

__all__ = ["TampingLine", "TampingLineVectorEnv", "line_observation_space"]


def line_observation_space(config: LineConfig) -> spaces.Dict:
    S, f32 = config.n_sections, np.float32
    d = {
        "section_sd": spaces.Box(0.0, 100.0, (S,), f32),
        "section_peak": spaces.Box(0.0, 200.0, (S,), f32),
        "measurement_age": spaces.Box(0.0, config.horizon_years + 1.0, (1,), f32),
        "register": spaces.Box(0.0, 2.0, (S,), f32),
        "tampings": spaces.Box(0.0, 1000.0, (S,), f32),
        "tampings_since_renewal": spaces.Box(0.0, 1000.0, (S,), f32),
        "years_since_tamping": spaces.Box(0.0, 100.0, (S,), f32),
        "time": spaces.Box(0.0, 1.0, (1,), f32),
        "budget_left": spaces.Box(0.0, 1.0, (1,), f32),
    }
    if config.profiles:
        d["level"] = spaces.Box(-100.0, 200.0, (S, config.n_sleepers), f32)
    return spaces.Dict(dict(d))


def decode_line_action(action, n_sections: int) -> np.ndarray:
    """(n_sections,) bool from a MultiBinary action; a malformed action raises ValueError."""
    try:
        a = np.asarray(action, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"action must be an array of {n_sections} values in {{0, 1}}, got {action!r}") from None
    if a.shape != (n_sections,):
        raise ValueError(f"action must have shape ({n_sections},) (one 0/1 per section), got {a.shape}")
    if not np.all(np.isfinite(a)) or not np.all((a == 0) | (a == 1)):
        raise ValueError(f"action values must be 0 or 1 (no NaN), got {a.tolist()}")
    return a.astype(bool)


class TampingLineVectorEnv(VectorEnv):
    """``num_envs`` TampingLine episodes (same config), stepped together; see :class:`TampingLine` for the
    spec. Episodes reset in the step they end (SAME_STEP autoreset): ``infos["final_obs"]`` and
    ``infos["final_info"]`` hold the last of the old one. ``reset(seed=s)`` seeds line i with s + i."""

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(self, num_envs: int = 4, config: LineConfig | dict | str | None = None, *,
                 scenario: str | None = None, **overrides: Any) -> None:
        if not isinstance(num_envs, (int, np.integer)) or not 1 <= num_envs <= 4096:
            raise ValueError(f"num_envs must be an integer in [1, 4096], got {num_envs!r}")
        overrides.pop("render_mode", None)
        overrides.pop("max_episode_steps", None)
        config = LineConfig.coerce(scenario if config is None and scenario is not None else config)
        if overrides:
            config = config.replace(**overrides)
        self.config = config
        self.num_envs = int(num_envs)
        self.single_observation_space = line_observation_space(config)
        self.single_action_space = spaces.MultiBinary(config.n_sections)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.batch: LineBatch | None = None
        self._rngs: list[np.random.Generator] = []

    def _observations(self) -> dict:
        out = create_empty_array(self.single_observation_space, self.num_envs)
        assert self.batch is not None, "reset() first"
        obs = [self.batch.observation(b) for b in range(self.num_envs)]
        return concatenate(self.single_observation_space, obs, out)  # type: ignore[return-value]

    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        self._rngs = vector_rngs(seed, self.num_envs)
        self.batch = LineBatch(self.config, self.num_envs)
        self.batch.reset_lines(list(range(self.num_envs)), self._rngs)
        zero = dict.fromkeys(COST_KEYS, 0.0)
        S = self.config.n_sections
        infos = [self.batch.info(b, zero, np.zeros(S, dtype=bool), False) for b in range(self.num_envs)]
        return self._observations(), _stack_infos(infos)

    def step(self, actions):
        if self.batch is None:
            raise RuntimeError("call reset() before step()")
        actions = np.asarray(actions)
        if actions.ndim == 0 or actions.shape[0] != self.num_envs:
            raise ValueError(f"actions must have a leading axis of {self.num_envs}, got shape {actions.shape}")
        S = self.config.n_sections
        want = np.stack([decode_line_action(a, S) for a in actions])
        bt = self.batch
        tamped, clipped = bt.resolve(want)
        campaign = bt.apply(tamped)
        bt.traffic()
        parts = bt.costs(campaign)
        total = sum(parts.values())
        rewards = -np.asarray(total, dtype=float)
        truncated = bt.step >= self.config.horizon_steps
        infos = [bt.info(b, {k: float(v[b]) for k, v in parts.items()}, tamped[b], clipped[b])
                 for b in range(self.num_envs)]
        info = _stack_infos(infos)
        done = np.flatnonzero(truncated).tolist()
        if done:
            final_obs = [bt.observation(b) if b in done else None for b in range(self.num_envs)]
            bt.reset_lines(done, self._rngs)
            info["final_obs"] = np.array(final_obs, dtype=object)
            info["final_info"] = np.array([infos[b] if b in done else None for b in range(self.num_envs)],
                                          dtype=object)
            info["_final_obs"] = truncated.copy()
            info["_final_info"] = truncated.copy()
        return self._observations(), rewards, np.zeros(self.num_envs, dtype=bool), truncated, info

    def action_masks(self) -> np.ndarray:
        """(num_envs, 2·S) [may-not-tamp, may-tamp] pairs per section (sb3-contrib's MultiBinary convention).
        The capacity (at most ``capacity`` sections per campaign) is a cardinality limit that per-section masks
        cannot express: see ``over_capacity``."""
        shape = (self.num_envs, self.config.n_sections)
        allowed = self.batch.allowed() if self.batch is not None else np.ones(shape, bool)
        return np.stack([np.ones_like(allowed), allowed], axis=2).reshape(self.num_envs, -1)


class TampingLine(gym.Env):
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
    the ballast (faster settlement after each tamping) until a renewal at the 8th.

    **Scenarios** (registered ids; ``LineConfig`` fields in :data:`~trackenv.envs.line_config.SCENARIOS`):

    ==================================  ========  ========  ================================================
    id                                  sections  capacity  differences from the default
    ==================================  ========  ========  ================================================
    ``trackenv/TampingLineSmall-v0``    6         3         tests and quick studies
    ``trackenv/TampingLine-v0``         12        6         the default line
    ``trackenv/TampingLineHard-v0``     24        4         more zones and hidden spots, budget 60 k€/year
    ==================================  ========  ========  ================================================

    **Action space.** ``MultiBinary(n_sections)``: 1 = tamp this section in this step's campaign (one
    possession per step). Sections tamped within ``min_steps_between_tampings`` steps are masked
    (:meth:`action_masks`) and dropped. More than ``capacity`` sections, or a campaign over the remaining
    annual budget: with ``over_capacity="clip"`` (default; the checkers sample unconstrained actions) the
    allowed sections with the worst *measured* SD are kept and ``info["clipped"]`` is True; with
    ``over_capacity="raise"`` a ValueError. Malformed actions raise ValueError.

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
    ======================  ===============================================================  =====  ========

    The true state is in ``info``: ``section_sd_m``, ``section_peak_m``, ``section_class`` (0 OK, 1 alert,
    2 intervention, 3 immediate action, EN 13848-5 style at 100 km/h), ``wet_spot_active``, ``rate_factor``.

    **Reward.** −Σ of the step's cost parts (k€) in ``info["costs"]``: ``possession`` (per campaign),
    ``tamping`` (per metre × 200 m per section), ``renewal``, ``geometry`` (per section-year ∝
    (SD/SD_alert)²), ``speed_restriction`` (per section-step at or above the intervention limit),
    ``immediate_action`` (per section-step at the immediate-action limit). Defaults and sources:
    :class:`~trackenv.envs.line_config.LineConfig`.

    **Episode end.** No terminal state; truncation at the horizon (default 10 years = 40 steps).

    **Arguments.** ``config`` (:class:`LineConfig`, dict or scenario name), ``scenario``, or fields as
    keywords. **Randomness**: everything is drawn at reset from ``self.np_random`` (see
    :mod:`~trackenv.envs.line_episode`). **Versions**: v0, first release.
    """

    metadata = {"render_modes": []}

    def __init__(self, config: LineConfig | dict | str | None = None, *, scenario: str | None = None,
                 render_mode: str | None = None, **overrides: Any) -> None:
        if render_mode is not None:
            raise ValueError(f"render_mode must be None (episode plots: trackenv_agents), got {render_mode!r}")
        self._vec = TampingLineVectorEnv(1, config, scenario=scenario, **overrides)
        self.config = self._vec.config
        self.render_mode = render_mode
        self.observation_space = self._vec.single_observation_space
        self.action_space = self._vec.single_action_space
        self._last_info: dict = {}

    @property
    def batch(self) -> LineBatch | None:
        return self._vec.batch

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self._vec._rngs = [self.np_random]
        self._vec.batch = LineBatch(self.config, 1)
        self._vec.batch.reset_lines([0], self._vec._rngs)
        S = self.config.n_sections
        self._last_info = self._vec.batch.info(0, dict.fromkeys(COST_KEYS, 0.0), np.zeros(S, dtype=bool), False)
        return self._vec.batch.observation(0), self._last_info

    def step(self, action):
        bt = self._vec.batch
        if bt is None:
            raise RuntimeError("call reset() before step()")
        want = decode_line_action(action, self.config.n_sections)[None, :]
        tamped, clipped = bt.resolve(want)
        campaign = bt.apply(tamped)
        bt.traffic()
        parts = {k: float(v[0]) for k, v in bt.costs(campaign).items()}
        reward = -float(sum(parts.values()))
        truncated = bool(bt.step[0] >= self.config.horizon_steps)
        self._last_info = bt.info(0, parts, tamped[0], clipped[0])
        return bt.observation(0), reward, False, truncated, self._last_info

    def action_masks(self) -> np.ndarray:
        return self._vec.action_masks()[0]

def _stack_infos(infos: list[dict]) -> dict:
    out: dict[str, Any] = {}
    for key in infos[0]:
        vals = [inf[key] for inf in infos]
        if key == "costs":
            out[key] = {k: np.array([v[k] for v in vals]) for k in vals[0]}
        else:
            out[key] = np.array(vals)
        out["_" + key] = np.ones(len(infos), dtype=bool)
    return out
