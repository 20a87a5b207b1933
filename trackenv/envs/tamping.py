"""TampingEnv: when and where to tamp a 60 m track of six 10 m sections, with the physics in every step.

It is the one environment of trackenv (:class:`~trackenv.envs.line.TampingLine`, over the one episode engine
:class:`~trackenv.envs.line_episode.LineBatch`) with the preset ``"track60"`` of
:class:`~trackenv.envs.line_config.LineConfig`: ``trackenv/Tamping-v1`` and its learners' variants.
"""

from __future__ import annotations

from typing import Any

from .line import TampingLine
from .line_config import LineConfig

__all__ = ["TampingEnv"]


class TampingEnv(TampingLine):
    """Plan tamping of a 60 m track: which of its six 10 m sections to tamp, and when.

    **Description.** The :class:`~trackenv.envs.line.TampingLine` environment (its spaces, reward, info,
    episode end, state API and arguments apply as written there) with the preset ``"track60"``:

    The 60 m track is the same engine with one physics
    segment of 60 m that carries six 10 m sections (``sections_per_segment=6``): the sections share one pass,
    so a section feels its neighbours through the rail; tamping a section lifts its sleepers to the chord
    through the untamped neighbours, ramped in and out over 3 sleepers, and restarts consolidation on them only.
    One wheelset type (20 t axles, 2 million axle passes a year = 40 MGT), a stiffness transition (ratio 2, in
    the middle) on 30 % of the tracks, on average 0.3 hanging sleepers, no switches or wet spots; the track is
    measured without error after every step, and the observation adds the level and the wheel/rail force over
    every sleeper bay (``profiles``: ``level`` and ``contact_force``, shape (1, 101)). Costs per 10 m section
    **[assumption]** (a short site's tamping is mostly the machine's set-up, not the line's per-metre price):
    10 k€ per campaign, 2 k€ per section tamped, 0.5 / 3 / 50 k€ per section-step in the alert class, at the
    intervention limit and at the immediate-action limit, 4 k€ per section-year at the alert SD, 1.5 k€ per
    ballast renewal (at the 9th tamping). Rendering (``render_mode="rgb_array"``) draws the level, the D1 level
    and the contact force along the track (:func:`trackenv.render.segment_frame`).

    **Ids.** ``trackenv/Tamping-v1`` (``MultiBinary(6)``), ``trackenv/TampingDiscrete-v1`` (``Discrete(7)``: one
    section or none per step), and for learners (:mod:`trackenv.envs.wrappers`) ``trackenv/TampingRanked-v1``
    (ranked actions: ``k`` = tamp the ``k`` worst sections by measured SD, the section-level observation) and
    ``trackenv/TampingRankedFlat-v1`` (the same with one flat ``Box`` observation).

    **Version history.** v1: the 60 m track moved onto the one engine (above). v0 had an engine of its own
    (gone): a vehicle pass per step over a ``TrackDegradation``, tamping residuals drawn at the tamping, no
    renewal cost, the transition anywhere in 20-80 % of the track, and no tamping history before the start.
    What that moved, measured with the rules on 16 held-out episodes (seeds 0-15): no maintenance cost 185.9 k€
    on v0 and 259.2 k€ on v1 (the 0-2 years of settlement since the last tamping that v1 starts with, and the
    renewal cost); the best tuned rule 115.1 k€ on v0 (periodic, every 3.5 years) and 138.0 k€ on v1 (grouped
    threshold; 200 episodes).
    """

    def __init__(self, config: LineConfig | dict | str | None = None, *, scenario: str | None = None,
                 action_type: str = "multibinary", render_mode: str | None = None, **overrides: Any) -> None:
        super().__init__(config, scenario="track60" if config is None and scenario is None else scenario,
                         action_type=action_type, render_mode=render_mode, **overrides)
