"""TampingVectorEnv: many episodes of the 60 m track (:class:`~trackenv.envs.tamping.TampingEnv`) stepped
together, their passes in one batched call of the dynamics: the one vector env of trackenv
(:class:`~trackenv.envs.line.TampingLineVectorEnv`) with the preset ``"track60"``.
"""

from __future__ import annotations

from typing import Any

from gymnasium.vector import AutoresetMode

from .line import TampingLineVectorEnv
from .line_config import LineConfig


class TampingVectorEnv(TampingLineVectorEnv):
    """``num_envs`` independent :class:`~trackenv.envs.tamping.TampingEnv` episodes with batched physics (same
    config: the preset ``"track60"`` unless ``config`` or ``scenario`` says otherwise; fields as keywords).
    ``autoreset_mode``, seeds and rendering as :class:`~trackenv.envs.line.TampingLineVectorEnv`."""

    def __init__(self, num_envs: int = 8, config: LineConfig | dict | str | None = None, *,
                 scenario: str | None = None, action_type: str = "multibinary",
                 autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP,
                 render_mode: str | None = None, **overrides: Any) -> None:
        super().__init__(num_envs, config, scenario="track60" if config is None and scenario is None else scenario,
                         action_type=action_type, autoreset_mode=autoreset_mode, render_mode=render_mode,
                         **overrides)
