"""TampingLine: when and where to tamp a railway line of 200 m sections, with the physics in every step.

One class does the work, :class:`TampingLineVectorEnv` (natively batched over lines: every segment of every
line runs in one batched pass per vehicle type); :class:`TampingLine` is its batch of one behind the
``gymnasium.Env`` API. The rules live in :mod:`trackenv.envs.line_episode`, the parameters and the scenario
suite in :mod:`trackenv.envs.line_config`.
"""

from __future__ import annotations

import copy
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode

from .batched import BatchedVectorEnv
from .common import action_mask, check_render_mode, check_reset_arguments, decode_action, observation_space
from .line_config import LineConfig
from .line_episode import LineBatch, line_observation_bounds
from .state import EnvState, checked, snapshot

__all__ = ["TampingLine", "TampingLineVectorEnv", "line_observation_space"]


def line_observation_space(config: LineConfig) -> spaces.Dict:
    """The Dict space of TampingLine's observation table (its bounds: :func:`line_observation_bounds`)."""
    bounds = line_observation_bounds(config)
    per_line = {"measurement_age": (1,), "time": (1,), "budget_left": (1,),
                "level": (config.n_sections, config.n_sleepers)}
    return observation_space(bounds, {key: per_line.get(key, (config.n_sections,)) for key in bounds})


def line_config(config: LineConfig | dict | str | None, scenario: str | None, overrides: dict[str, Any]) -> LineConfig:
    """The config of a TampingLine env from its arguments: ``config`` (a config, a dict or a scenario name),
    else ``scenario``, else the default line, with the field ``overrides`` (``max_episode_steps``, which
    ``gym.make`` may pass, is dropped: the env truncates itself at its horizon)."""
    overrides.pop("max_episode_steps", None)
    out = LineConfig.coerce(scenario if config is None and scenario is not None else config)
    return out.replace(**overrides) if overrides else out


class TampingLineVectorEnv(BatchedVectorEnv):
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
                 scenario: str | None = None, autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP,
                 render_mode: str | None = None, **overrides: Any) -> None:
        self.config = config = line_config(config, scenario, overrides)
        super().__init__(num_envs, line_observation_space(config), spaces.MultiBinary(config.n_sections),
                         autoreset_mode=autoreset_mode, render_mode=render_mode)
        self.batch: LineBatch | None = None

    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        self.batch = LineBatch(self.config, self.num_envs)
        return super().reset(seed=seed, options=options)

    def _lines(self) -> LineBatch:
        if self.batch is None:
            raise RuntimeError("call reset() before step()")
        return self.batch

    def _start(self, idx: list[int]) -> None:
        self._lines().reset_lines(idx, self._rngs)

    def _observation(self, i: int) -> dict[str, np.ndarray]:
        return self._lines().observation(i)

    def _reset_info(self, i: int) -> dict:
        return self._lines().reset_info(i)

    def _step_envs(self, actions: np.ndarray, stepping: list[int],
                   resetting: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[int, dict]]:
        S = self.config.n_sections
        want = np.zeros((self.num_envs, S), dtype=bool)
        for b in stepping:
            want[b] = decode_action(actions[b], "multibinary", S)
        rewards, truncated, infos = self._lines().step_lines(want, stepping)
        if resetting:
            self._start(resetting)
        return rewards, np.zeros(self.num_envs, dtype=bool), truncated, infos

    def get_state(self, index: int) -> EnvState:
        """A snapshot of line ``index`` (:mod:`trackenv.envs.state`), the same as :meth:`TampingLine.get_state`
        gives: it can be restored here, in another row, or in a single env of this config."""
        i = self._env_index(index)
        return snapshot(self.config, self._lines().get_state(i), self._rngs[i], self._infos[i])

    def set_state(self, index: int, state: EnvState) -> None:
        """Continue line ``index`` from ``state`` (a snapshot of this config); a pending NEXT_STEP reset of that
        line is dropped."""
        i = self._env_index(index)
        state = checked(state, self.config)
        self._lines().set_state(i, state.episode)
        self._restore_row(i, state)

    def _frame(self, info: dict) -> np.ndarray:
        from ..render import line_frame

        return line_frame(self._lines(), 0, info)

    def action_masks(self) -> np.ndarray:
        """(num_envs, 2·S) [may-not-tamp, may-tamp] pairs per section (sb3-contrib's MultiBinary convention).
        The capacity (at most ``capacity`` sections per campaign) is a cardinality limit that per-section masks
        cannot express: see ``over_capacity``."""
        shape = (self.num_envs, self.config.n_sections)
        return action_mask(self.batch.allowed() if self.batch is not None else np.ones(shape, bool), "multibinary")


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
    ``info["section_costs"]``: each section's own costs of the step (k€: its tamping or renewal, geometry,
    speed restriction, immediate action); with the line's possession they add up to the step's cost (a
    learner can credit each section's choice with its own costs).

    **Reward.** −Σ of the step's cost parts (k€) in ``info["costs"]``: ``possession`` (per campaign),
    ``tamping`` (per metre × 200 m per section), ``renewal``, ``geometry`` (per section-year ∝
    (SD/SD_alert)²), ``speed_restriction`` (per section-step at or above the intervention limit),
    ``immediate_action`` (per section-step at the immediate-action limit). Defaults and sources:
    :class:`~trackenv.envs.line_config.LineConfig`.

    **Episode end.** No terminal state; truncation at the horizon (default 10 years = 40 steps), enforced:
    ``step`` after the horizon raises RuntimeError until ``reset``; ``reset`` refuses a seed that is not a
    non-negative integer and any ``options`` key (it takes none), as ``Tamping-v0`` does.

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
    keywords; ``render_mode`` (None or "rgb_array"). **Randomness**: everything is drawn at reset from
    ``self.np_random`` (see :mod:`~trackenv.envs.line_episode`).

    **Versions.** v0: first release. Since then, without a change of dynamics or reward: ``render_mode=
    "rgb_array"``; the vector env's two autoreset modes and Gymnasium's info layout (``final_info`` a dict of
    arrays, as ``SyncVectorEnv`` gives it, where it was an object array of per-line dicts); the settlement's
    Newton iteration stops per segment and the least-squares lines are summed row by row, so a line's numbers
    no longer depend on the other lines of a batch (costs moved by ~1e-9 relative, within the Newton tolerance);
    ``info["section_costs"]``.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(self, config: LineConfig | dict | str | None = None, *, scenario: str | None = None,
                 render_mode: str | None = None, **overrides: Any) -> None:
        self.config = line_config(config, scenario, overrides)
        self.render_mode = check_render_mode(render_mode)
        self.observation_space = line_observation_space(self.config)
        self.action_space = spaces.MultiBinary(self.config.n_sections)
        self.batch: LineBatch | None = None  # the engine, a batch of one line, made by reset()
        self._last_info: dict = {}

    def _line(self) -> LineBatch:
        if self.batch is None:
            raise RuntimeError("call reset() before step()")
        return self.batch

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=check_reset_arguments(seed, options))
        self.batch = LineBatch(self.config, 1)
        self.batch.reset_lines([0], [self.np_random])  # drawn from this env's generator (reset() continues it)
        self._last_info = self.batch.reset_info(0)
        return self.batch.observation(0), self._last_info

    def step(self, action):
        bt = self._line()
        bt.check_not_truncated(0)
        want = decode_action(action, "multibinary", self.config.n_sections)[None, :]
        rewards, truncated, infos = bt.step_lines(want, [0])
        self._last_info = infos[0]
        return bt.observation(0), float(rewards[0]), False, bool(truncated[0]), self._last_info

    def action_masks(self) -> np.ndarray:
        """(2·S,) [may-not-tamp, may-tamp] pairs per section, as :meth:`TampingLineVectorEnv.action_masks`."""
        allowed = self.batch.allowed()[0] if self.batch is not None else np.ones(self.config.n_sections, bool)
        return action_mask(allowed, "multibinary")

    def get_state(self) -> EnvState:
        """A snapshot of the episode (:mod:`trackenv.envs.state`): ``set_state`` on this env, on any env of
        the same config or on a row of its vector env continues it bit for bit."""
        return snapshot(self.config, self._line().get_state(0), self.np_random, self._last_info)

    def set_state(self, state: EnvState) -> None:
        """Continue from ``state`` (from ``get_state`` of an env of this config); the snapshot is not changed."""
        state = checked(state, self.config)
        if self.batch is None:
            self.batch = LineBatch(self.config, 1)
        self.batch.set_state(0, state.episode)
        self.np_random.bit_generator.state = copy.deepcopy(state.rng_state)
        self._last_info = copy.deepcopy(state.last_info)

    def render(self):
        """The line's state as an RGB array (``render_mode="rgb_array"``; :func:`trackenv.render.line_frame`),
        else None."""
        if self.render_mode != "rgb_array" or self.batch is None:
            return None
        from ..render import line_frame

        return line_frame(self.batch, 0, self._last_info)
