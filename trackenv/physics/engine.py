"""How a vehicle pass is run: what it starts from, how far its moving windows reach and what their ends stand on.

One frozen value, :class:`PassEngine`, read by everything that runs passes over a model track (the settlement
loop, the envs), so that switching the engine is one argument. Two engines are named:

* :data:`CLASSIC_ENGINE` (``PassEngine()``): static equilibrium of the vehicle and the track at the start, the
  approach integrated from there, windows of :data:`~trackenv.physics.dynamics.WINDOW_DECAY_LENGTHS` decay
  lengths either side of the axles with clamped ends. The passes of every saved result ran with it.
* :data:`FAST_ENGINE`: the periodic steady state at the start, :data:`~trackenv.physics.dynamics.STEADY_LEAD_BAYS`
  bays before the evaluated track (no approach to integrate from rest), and windows of
  :data:`FAST_DECAY_LENGTHS` decay lengths whose ends carry the static stiffness and damping of the track beyond
  them (:mod:`trackenv.physics.window_ends`). On the soft/stiff sweep of that module's tests the shorter window
  keeps the peak forces within 0.4 % of the whole track's, and the steady start within 0.03 % of a 40-sleeper
  approach (``tests/physics/test_steady_start.py``), where the classic 10-sleeper approach is up to 0.65 % off.

The steady start needs its moving window inside the track at the start: :meth:`PassEngine.approach_sleepers`
says how many sleepers of approach a track needs, and :meth:`PassEngine.options_for` falls back to the static
start for a track whose window does not fit its approach (a row's options depend on its own track only, so a
row's result never depends on its batch).
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from dataclasses import dataclass

from ._checks import check_choice, check_scalar
from .dynamics import (
    START_OPTIONS,
    STEADY_LEAD_BAYS,
    WINDOW_DECAY_LENGTHS,
    _vehicle_system,
    steady_approach_sleepers,
    window_margin,
)
from .track import Track
from .window_ends import check_window_ends

#: the window margin of :data:`FAST_ENGINE` in decay lengths: within 0.4 % of the whole track's peak forces with
#: static ends on the sweep of ``tests/physics/test_window_ends.py`` (experiments/physics_window_ends.py)
FAST_DECAY_LENGTHS = 3.0


@dataclass(frozen=True)
class PassEngine:
    """How a pass runs (the options of :func:`~trackenv.physics.dynamics.simulate_passes` it sets).

    ``start``: what the pass starts from, one of ``START_OPTIONS`` ("static", "rest", "steady");
    ``window_ends``: "rest" (clamped) or "static" (:mod:`trackenv.physics.window_ends`); ``decay_lengths``: the
    window's margin either side of the axles in the track's decay lengths, 0.5-100 (the passes' "auto" window,
    :func:`~trackenv.physics.dynamics.window_margin`); ``lead_bays``: with the steady start, bays (0-1000) the
    leading axle runs before the evaluated track, from the steady state to the first evaluated sleeper.
    """

    start: str = "static"
    window_ends: str = "rest"
    decay_lengths: float = WINDOW_DECAY_LENGTHS
    lead_bays: float = STEADY_LEAD_BAYS

    def __post_init__(self) -> None:
        check_choice("start", self.start, START_OPTIONS)
        check_window_ends(self.window_ends)
        object.__setattr__(self, "decay_lengths", check_scalar("decay_lengths", self.decay_lengths,
                                                               low=0.5, high=100.0))
        object.__setattr__(self, "lead_bays", check_scalar("lead_bays", self.lead_bays, low=0.0, high=1000.0))

    @property
    def pass_options(self) -> dict:
        """The options of every pass of this engine (``simulate_passes(..., **engine.pass_options)``); a pass over
        a model track with an approach zone takes :meth:`options_for` instead."""
        return {"start": self.start, "window_ends": self.window_ends, "window_decay_lengths": self.decay_lengths}

    def approach_sleepers(self, tracks: Track | Sequence[Track], vehicle) -> int:
        """Sleepers of approach the steady start needs before an evaluated track (the most ``tracks`` need: the
        vehicle's span, the window behind it and the lead bays; see
        :func:`~trackenv.physics.dynamics.steady_approach_sleepers`); 0 for the other starts, which need none
        of their own. ValueError where a track is too soft for a moving window."""
        if self.start != "steady":
            return 0
        return steady_approach_sleepers(tracks, vehicle, self.lead_bays, self.decay_lengths)

    def options_for(self, model_track: Track, vehicle, approach_sleepers: int) -> dict:
        """The options of a pass of ``vehicle`` over ``model_track``, whose evaluated track starts after
        ``approach_sleepers`` sleepers of approach: :attr:`pass_options`, and with the steady start the leading
        axle's start ``x_start``, ``lead_bays`` before the evaluated track. Where the steady start's window does
        not fit in the approach (or the track is too soft for a moving window) the pass starts from static
        equilibrium at the track's start instead. Kept per track object while it lives (with the engine, vehicle and
        approach): the envs ask for every segment's options at every step."""
        kept = _OPTIONS.setdefault(model_track, {})
        key = (self, vehicle, approach_sleepers)
        if key not in kept:
            kept[key] = self._options_for(model_track, vehicle, approach_sleepers)
        return dict(kept[key])

    def _options_for(self, model_track: Track, vehicle, approach_sleepers: int) -> dict:
        """:meth:`options_for`, worked out."""
        options = self.pass_options
        if self.start != "steady":
            return options
        s = model_track.sleeper_spacing
        span = _vehicle_system(vehicle).span
        margin = window_margin(model_track, self.decay_lengths)
        if margin is None or span / s + margin + 1.5 + self.lead_bays > approach_sleepers + 1e-9:
            return {**options, "start": "static"}
        return {**options, "x_start": (approach_sleepers - self.lead_bays) * s}


#: model track -> {(engine, vehicle, approach sleepers): its pass options}, while the track lives
_OPTIONS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

CLASSIC_ENGINE = PassEngine()
FAST_ENGINE = PassEngine(start="steady", window_ends="static", decay_lengths=FAST_DECAY_LENGTHS)
#: the engines by name (``LineConfig.engine``)
ENGINES = {"classic": CLASSIC_ENGINE, "fast": FAST_ENGINE}


def check_engine(engine) -> PassEngine:
    """``engine`` as a :class:`PassEngine`: one, or the name of one of :data:`ENGINES`."""
    if isinstance(engine, PassEngine):
        return engine
    if isinstance(engine, str) and engine in ENGINES:
        return ENGINES[engine]
    raise ValueError(f"engine must be a PassEngine or one of {tuple(ENGINES)}, got {engine!r}")
