"""The paper's holistic loop as a stand-alone simulator: pass → sleeper forces → settlement → new rail level.

One iteration: a vehicle pass over the standing track with the current rail level as irregularity gives the peak
force on every sleeper; the settlement law, with curve shifting, advances every sleeper's settlement by ΔN load
cycles (axle passes) under those forces; the settlement becomes the rail's level irregularity for the next pass.

The track ends. A wheel does not load the sleepers at the ends of a finite rail the way it loads interior ones,
and a vehicle starting on a rail end rocks before it settles down: fed back, those ends would form ramps that
the next pass hits harder, and the loop runs away within a few iterations. So the dynamic model is longer than
the evaluated track: approach and exit zones of ``approach_sleepers`` sleepers (plus the vehicle's axle span) are
added at both ends, each a copy of the end sleeper it continues. Their level is not computed but held at the
level of the nearest evaluated sleeper — they stand for more of the same track — so no ramp forms and the
forces in the evaluated zone are those of a track that goes on. The pass itself ends ``EXIT_RUN_OUT_BAYS`` bays
after the last axle has left the evaluated zone (:attr:`TrackDegradation.pass_end`): the exit zone's track stays
in the model, only the time steps that can no longer change an evaluated sleeper's peak force are not taken.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from functools import cached_property, partial

import numpy as np
import scipy.linalg

from .physics._checks import check_array, check_bool, check_choice, check_int, check_scalar, check_speed
from .physics.dynamics import (
    OVERLOAD_FACTOR,
    SLEEPER_FORCE_MEASURES,
    OverloadWarning,
    PassResult,
    _vehicle_system,
    check_window_bays,
    lapack_lower,
    simulate_passes,
    static_deflection_note,
)
from .physics.engine import CLASSIC_ENGINE, PassEngine, check_engine
from .physics.settlement import (
    MAX_FORCE_N,
    HettlerLaw,
    SettlementLaw,
    SettlementState,
    check_law,
    implicit_settlement_step,
)
from .physics.tamping import TampingModel, TampingResult, tamp
from .physics.timestep import check_dt_option
from .physics.track import Track


@dataclass(frozen=True, eq=False)
class IterationRecord:
    """What one iteration did: the forces of the pass that drove it and the level after it."""

    cycles: float  # load cycles (axle passes) since the start, after this iteration
    settlement: np.ndarray  # (n_sleepers,) rail level after the iteration [m] (downward positive)
    sleeper_force: np.ndarray  # (n_sleepers,) peak sleeper force of the driving pass [N]
    contact_force: np.ndarray  # (n_sleepers,) peak contact force per sleeper bay of the driving pass [N]
    max_contact_force: float  # [N]
    passes: int  # dynamic passes run in the iteration (more than one with adaptive stepping)


@dataclass(eq=False)
class DegradationHistory:
    """The iterations so far, stacked: ``settlement`` and ``sleeper_force`` are (iterations, sleepers)."""

    sleeper_positions: np.ndarray
    records: list[IterationRecord] = field(default_factory=list)

    def _stack(self, name: str) -> np.ndarray:
        if not self.records:
            per_sleeper = name in ("settlement", "sleeper_force", "contact_force")
            return np.zeros((0, self.sleeper_positions.size) if per_sleeper else (0,))
        return np.array([getattr(r, name) for r in self.records])

    @property
    def settlement(self) -> np.ndarray:
        return self._stack("settlement")

    @property
    def sleeper_force(self) -> np.ndarray:
        return self._stack("sleeper_force")

    @property
    def contact_force(self) -> np.ndarray:
        return self._stack("contact_force")

    @property
    def max_contact_force(self) -> np.ndarray:
        return self._stack("max_contact_force")

    @property
    def cycles(self) -> np.ndarray:
        return self._stack("cycles")

    @property
    def passes(self) -> np.ndarray:
        return self._stack("passes")

    def to_dict(self) -> dict:
        """JSON-ready: SI units, lists."""
        return {
            "sleeper_positions_m": self.sleeper_positions.tolist(),
            "cycles": self.cycles.tolist(),
            "settlement_m": self.settlement.tolist(),
            "sleeper_force_N": self.sleeper_force.tolist(),
            "contact_force_N": self.contact_force.tolist(),
            "max_contact_force_N": self.max_contact_force.tolist(),
            "passes": self.passes.tolist(),
        }


FEEDBACKS = ("irregularity", "support")
EXIT_RUN_OUT_BAYS = 3  # bays the last axle runs past the evaluated zone (1 already gave identical peaks on env tracks)
INTERPOLATIONS = ("cubic", "linear")
ON_RUNAWAY = ("warn", "raise", "ignore")
#: Growth ratio of the differential settlement increment, iteration over iteration, and the number of
#: consecutive iterations it must persist, that mark a loop running away (a converging loop's increments
#: shrink: ratios 0.2-0.9 in the paper's scenarios), and the increment below which growth is not yet a concern [m].
RUNAWAY_GROWTH, RUNAWAY_ITERATIONS, RUNAWAY_FLOOR = 1.5, 2, 0.1e-3
#: A single iteration whose differential increment jumps by more than this factor (above the floor) is enough.
RUNAWAY_JUMP = 4.0
#: Contact force, as a multiple of the static wheel load, beyond which a pass is out of any plain track's range
#: (the physics' :data:`~trackenv.physics.dynamics.OVERLOAD_FACTOR`, **[assumption]**): the loop has run away.
RUNAWAY_FORCE_FACTOR = OVERLOAD_FACTOR


class RunawayWarning(RuntimeWarning):
    """The settlement loop is diverging (see :meth:`TrackDegradation.check_runaway`)."""


class RunawayError(RuntimeError):
    """The settlement loop diverged and ``on_runaway="raise"`` was asked for."""


INFLUENCE_BAND = 10  # sleepers: a support's settlement moves the load of sleepers within ~6 m (e^{-βx} < 1e-4)


class TrackDegradation:
    """Settlement of a track under repeated passes of one vehicle (the paper's iterative method).

    ``law``: a settlement law (default :class:`HettlerLaw`, the paper's Eq. 7-8); ``cycles_per_iteration``:
    ΔN axle passes per iteration; ``speed`` [m/s]; ``approach_sleepers``: length of the approach and exit zones
    (see the module docstring); ``adaptive``: split an increment where the largest *differential* settlement
    increment (deviation from the zone's mean increment, which is what changes the dynamics) would exceed
    ``max_increment`` [m], so results do not depend on the step size; ``initial_level``: the rail level at the
    start [m] per sleeper (downward positive, within ±0.5 m); ``rate_factor``: per-sleeper multiplier of the law's
    settlement (ballast condition varies along a track); ``feedback``: how settlement reaches the next pass:
    "irregularity" (the paper's: the per-sleeper settlement, interpolated, is the rail's level irregularity) or
    "support" (the ballast's base under each sleeper is lowered by its settlement and the rail bends over the
    settled supports, so a sleeper that settled more than its neighbours partly hangs and carries less — the
    self-limiting mechanism that keeps short-wave settlement bounded); ``on_runaway``: what to do when the loop
    diverges ("warn": :class:`RunawayWarning`, "raise": :class:`RunawayError`, "ignore"; see
    :meth:`check_runaway`); ``interpolation``: how the per-sleeper level becomes the rail's level between
    sleepers with ``feedback="irregularity"``: "cubic" (natural cubic spline through the sleeper values) or
    "linear" (straight between sleepers: the paper's reading, GENSYS takes a two-column table of position and
    displacement); see :meth:`rail_level`; ``engine``: how each pass runs, a
    :class:`~trackenv.physics.engine.PassEngine` or its name ("classic", the default, or "fast"; its steady start
    falls back to the static one where its window does not fit in the approach zone). Remaining keywords go to
    :func:`simulate_passes` (``dt``, default "auto": the step of :mod:`trackenv.physics.timestep`'s accuracy
    contract; ``contact``, ``sleeper_force_measure``, ``window_bays``).
    """

    def __init__(
        self,
        track: Track,
        vehicle,
        law: SettlementLaw | None = None,
        cycles_per_iteration: float = 50_000,
        speed: float = 80 / 3.6,
        *,
        approach_sleepers: int = 10,
        adaptive: bool = False,
        max_increment: float = 0.1e-3,
        max_passes_per_iteration: int = 64,
        initial_level=None,
        rate_factor=None,
        feedback: str = "irregularity",
        on_runaway: str = "warn",
        interpolation: str = "cubic",
        engine: PassEngine | str = CLASSIC_ENGINE,
        **pass_options,
    ) -> None:
        if not isinstance(track, Track):
            raise ValueError(f"track must be a Track, got {type(track).__name__}")
        self.track = track
        self.vehicle = vehicle
        self.system = _vehicle_system(vehicle)
        self.law = HettlerLaw() if law is None else check_law(law)
        self.cycles_per_iteration = check_scalar("cycles_per_iteration", cycles_per_iteration, low=1.0, high=1e9)
        self.speed = check_speed(speed)
        approach_sleepers = check_int("approach_sleepers", approach_sleepers, low=2, high=200)
        self.adaptive = check_bool("adaptive", adaptive)
        self.max_increment = check_scalar("max_increment", max_increment, low=0.0, high=0.1, low_inclusive=False)
        self.max_passes_per_iteration = check_int(
            "max_passes_per_iteration", max_passes_per_iteration, low=1, high=10_000
        )
        unknown = set(pass_options) - {"dt", "contact", "sleeper_force_measure", "window_bays"}
        if unknown:
            raise ValueError(f"unknown option(s) {sorted(unknown)} for TrackDegradation")
        pass_options.setdefault("dt", "auto")
        check_dt_option(pass_options["dt"])
        self.pass_options = pass_options
        measure = pass_options.get("sleeper_force_measure", "ballast")
        check_choice("sleeper_force_measure", measure, SLEEPER_FORCE_MEASURES)
        check_window_bays(pass_options.get("window_bays", "auto"))
        self.feedback = check_choice("feedback", feedback, FEEDBACKS)
        self.on_runaway = check_choice("on_runaway", on_runaway, ON_RUNAWAY)
        soft = static_deflection_note([track], float(np.max(self.system.static_wheel_loads)))
        if soft is not None:  # the passes run with on_overload="ignore": a track in kN/m is named here, once
            import warnings

            warnings.warn(soft, OverloadWarning, stacklevel=2)
        self.interpolation = check_choice("interpolation", interpolation, INTERPOLATIONS)
        self.engine = check_engine(engine)
        self._differential: list[float] = []  # differential settlement increment per iteration [m]
        n = track.n_sleepers
        self.n_extra = self.zone_sleepers(track.sleeper_spacing, self.system.span, approach_sleepers)
        self.model_track = track.extended(self.n_extra, self.n_extra)
        # [m]: half a metre off the design level is no track (a level in mm lands far beyond it)
        self.offset = (np.zeros(n) if initial_level is None
                       else check_array("initial_level", initial_level, shape=(n,), low=-0.5, high=0.5))
        self.base_rate = (
            np.ones(n)
            if rate_factor is None
            else check_array("rate_factor", rate_factor, shape=(n,), low=0.0, low_inclusive=False)
        )
        self.state = SettlementState(np.zeros(n), np.zeros(n), self.base_rate)
        self.tampings = np.zeros(n, dtype=np.int64)
        self.cycles = 0.0
        self.history = DegradationHistory(track.sleeper_positions.copy())

    def copy(self) -> TrackDegradation:
        """An independent copy of this simulator, exact and cheap: the mutable state (settlement state, level
        offset, tamping counts, cycles, history, runaway series) is copied; the track, the vehicle, the law and
        what is derived from them once (the model track, the support influence) are shared, as they never
        change. The copy advances exactly as this simulator would (the planning state API of the envs rests
        on it)."""
        twin = copy.copy(self)
        twin.offset = self.offset.copy()
        twin.tampings = self.tampings.copy()
        twin.history = DegradationHistory(self.history.sleeper_positions, list(self.history.records))
        twin._differential = list(self._differential)
        return twin

    @staticmethod
    def zone_sleepers(sleeper_spacing: float, span: float, approach_sleepers: int = 10) -> int:
        """Sleepers of the approach (and of the exit) zone added to a track with ``sleeper_spacing`` [m] for a
        vehicle of axle ``span`` [m]."""
        return int(approach_sleepers) + math.ceil(span / sleeper_spacing)

    @classmethod
    def zone_length(cls, sleeper_spacing: float, span: float, approach_sleepers: int = 10) -> float:
        """Length [m] of the approach (and of the exit) zone (see :meth:`zone_sleepers`)."""
        return cls.zone_sleepers(sleeper_spacing, span, approach_sleepers) * sleeper_spacing

    # ------------------------------------------------------------------ state
    @property
    def level(self) -> np.ndarray:
        """Rail level of the evaluated track per sleeper [m], downward positive."""
        return self.offset + self.state.settlement

    def model_irregularity(self, level: np.ndarray | None = None) -> np.ndarray:
        """The level on the modelled track: the evaluated zone, with the approach and exit zones held at the
        level of the end sleepers."""
        lv = self.level if level is None else level
        return np.concatenate([np.full(self.n_extra, lv[0]), lv, np.full(self.n_extra, lv[-1])])

    def rail_level(self, level: np.ndarray | None = None):
        """The irregularity handed to the dynamics for ``feedback="irregularity"``: the per-sleeper level of
        the modelled track (the dynamics interpolate it with a natural cubic spline), or with
        ``interpolation="linear"`` a function z(x) interpolating it linearly between sleepers [m]."""
        z = self.model_irregularity(level)
        if self.interpolation == "cubic":
            return z
        x = self.model_track.sleeper_positions
        return partial(np.interp, xp=x, fp=z)

    def evaluated(self, per_model_sleeper: np.ndarray) -> np.ndarray:
        """The part of a per-sleeper array of the modelled track that belongs to the evaluated track."""
        return per_model_sleeper[..., self.n_extra : self.n_extra + self.track.n_sleepers]

    @property
    def pass_end(self) -> float:
        """Leading-axle position where a pass ends [m]: the trailing axle ``EXIT_RUN_OUT_BAYS`` bays past the
        last evaluated sleeper (or the end of the modelled track). The evaluated peak forces are those of a pass
        to the end of the track, bit for bit (tests/test_degradation.py); the rest of the exit zone would only
        cost time steps."""
        return self.pass_end_position(
            self.track.length, self.track.sleeper_spacing, self.system.span, self.n_extra - self._span_sleepers()
        )

    def _span_sleepers(self) -> int:
        return self.zone_sleepers(self.track.sleeper_spacing, self.system.span, 0)

    @classmethod
    def pass_end_position(
        cls, track_length: float, sleeper_spacing: float, span: float, approach_sleepers: int = 10
    ) -> float:
        """:attr:`pass_end` for an evaluated track of ``track_length`` [m] (the leading axle starts at ``span``):
        the pass covers the approach zone, the evaluated track and ``EXIT_RUN_OUT_BAYS`` bays more."""
        zone = cls.zone_length(sleeper_spacing, span, approach_sleepers)
        return float(min(track_length + 2 * zone, zone + track_length + span + EXIT_RUN_OUT_BAYS * sleeper_spacing))

    # ------------------------------------------------------------------ loop
    def simulate(self) -> PassResult:
        """One pass over the current level (on the modelled track with its approach and exit zones)."""
        return simulate_batch([self])[0]

    def settle(self, result: PassResult, cycles: float, *, split: bool = True) -> float:
        """Advance the settlement under the forces of ``result`` by ``cycles`` axle passes, or by fewer where
        adaptive stepping (and ``split``) cuts the increment; return the cycles taken."""
        cycles = check_scalar("cycles", cycles, low=0.0)
        force = np.maximum(self.evaluated(result.sleeper_force), 0.0)
        self.check_sleeper_forces(force)
        step = self._adaptive_step(force, cycles) if self.adaptive and split else cycles
        if self.feedback == "support":
            self.state = self._implicit_advance(force, step)
        else:
            self.state = self.state.advance(self.law, force, step)
        self.cycles += step
        return step

    @cached_property
    def support_influence(self) -> np.ndarray:
        """S[i, j]: change of the static ballast force of evaluated sleeper i per metre of settlement of
        evaluated sleeper j [N/m] (from the track's statics; negative on the diagonal: a settling sleeper
        sheds load onto its neighbours)."""
        t = self.model_track
        lay = t.dof_layout
        _, _, kband = t.banded_matrices()
        ev = np.arange(self.n_extra, self.n_extra + self.track.n_sleepers)
        rhs = np.zeros((t.n_dof, ev.size))
        rhs[lay.sleeper[ev], np.arange(ev.size)] = t.ballast_stiffness[ev]
        # the approach and exit zones are held at the level of the end sleepers: they settle with them
        for zone, col in ((np.arange(self.n_extra), 0), (np.arange(ev[-1] + 1, t.n_sleepers), ev.size - 1)):
            rhs[lay.sleeper[zone], col] = t.ballast_stiffness[zone]
        du = scipy.linalg.solveh_banded(lapack_lower(kband), rhs, lower=True)
        kb = t.ballast_stiffness[ev]
        return kb[:, None] * (du[lay.sleeper[ev]] - np.eye(ev.size))

    def _implicit_advance(self, force: np.ndarray, cycles: float) -> SettlementState:
        """Advance with the static load redistribution taken implicitly (backward Euler over the step): see
        :func:`trackenv.physics.settlement.implicit_settlement_step`, here for a batch of one."""
        return _implicit_states([self], force[None], cycles)[0]

    def _adaptive_step(self, force: np.ndarray, cycles: float) -> float:
        """The largest ΔN <= cycles whose differential settlement increment stays within max_increment."""

        def differential(dn: float) -> float:
            inc = self.state.advance(self.law, force, dn).settlement - self.state.settlement
            return float(np.max(np.abs(inc - inc.mean())))

        if differential(cycles) <= self.max_increment:
            return cycles
        if differential(min(cycles, 1.0)) > self.max_increment:
            # the law settles more than max_increment within one cycle (a restart's initial settlement after a
            # partial tamping): no split bounds it, and 63 passes of one cycle each would leave the rest of the
            # iteration to one step taken on their forces; take the step whole, as without adaptive stepping
            return cycles
        lo, hi = 0.0, math.log(cycles + 1.0)
        for _ in range(40):  # bisection on log(1 + ΔN)
            mid = 0.5 * (lo + hi)
            if differential(math.expm1(mid)) <= self.max_increment:
                lo = mid
            else:
                hi = mid
        return max(math.expm1(lo), min(cycles, 1.0))

    def advance(self, cycles: float | None = None) -> IterationRecord:
        """One iteration of ``cycles`` axle passes (default ``cycles_per_iteration``); returns its record."""
        total = self.cycles_per_iteration if cycles is None else check_scalar("cycles", cycles, low=0.0, high=1e10)
        level_before = self.level.copy()
        done, passes, first = 0.0, 0, None
        while done < total * (1 - 1e-12):
            res = self.simulate()
            first = first or res
            remaining = total - done
            step = self.settle(res, remaining, split=passes + 1 < self.max_passes_per_iteration)
            done += step
            passes += 1
        if first is None:
            first = self.simulate()
        rec = IterationRecord(
            cycles=self.cycles,
            settlement=self.level.copy(),
            sleeper_force=self.evaluated(first.sleeper_force).copy(),
            contact_force=self.evaluated(first.contact_force_profile()).copy(),
            max_contact_force=float(self.evaluated(first.contact_force_profile()).max()),
            passes=passes,
        )
        self.history.records.append(rec)
        self.check_runaway(level_before, rec)
        return rec

    def check_sleeper_forces(self, force: np.ndarray) -> str | None:
        """Warn, raise or ignore (``on_runaway``) when a sleeper force exceeds :data:`RUNAWAY_FORCE_FACTOR`
        times the static wheel load: no track geometry puts that on one sleeper (it carries about half the
        wheel load), so the loop has run away or, with ``feedback="support"``, the differential settlement
        between neighbours has outgrown the linear supports (a lifted sleeper next to settled ones is pressed
        into its ballast by the bent rail instead of lifting off). Called on every settlement step: the env
        settles without :meth:`advance`. Returns the message, or None."""
        static = float(np.max(self.system.static_wheel_loads))
        peak = float(np.max(force, initial=0.0))
        beyond = peak > MAX_FORCE_N  # the laws cannot take it: the loop stops, whatever on_runaway says
        if not beyond and (static <= 0 or peak <= RUNAWAY_FORCE_FACTOR * static or self.on_runaway == "ignore"):
            return None
        k = int(np.argmax(force))
        step = float(np.max(np.abs(np.diff(self.level)), initial=0.0))
        msg = (
            f"sleeper {k} carries {peak / 1e3:.4g} kN, {peak / max(static, 1.0):.3g} times the static wheel load, "
            f"after {self.cycles:.4g} cycles (largest level step between neighbouring sleepers {step * 1e3:.3g} mm): "
            "the settlement loop is outside its validity. Reduce the cycles per step, tamp less aggressively "
            "(a design-line lift next to settled track), or check the inputs"
        )
        if beyond or self.on_runaway == "raise":
            raise RunawayError(msg + (f" (beyond the settlement laws' range of {MAX_FORCE_N:.3g} N: the loop stops)"
                                      if beyond else ""))
        import warnings

        warnings.warn(msg, RunawayWarning, stacklevel=3)
        return msg

    def check_runaway(self, level_before: np.ndarray, record: IterationRecord) -> str | None:
        """Detect a diverging loop after an iteration; warn, raise or ignore as ``on_runaway`` says.

        Three signs, any one enough: the differential settlement increment (the largest deviation of the
        iteration's increment from its mean, what changes the next pass) exceeds :data:`RUNAWAY_FLOOR` and grew
        by more than :data:`RUNAWAY_GROWTH` times in each of the last :data:`RUNAWAY_ITERATIONS` iterations or
        by more than :data:`RUNAWAY_JUMP` times in the last one; the pass's contact force exceeds
        :data:`RUNAWAY_FORCE_FACTOR` times the static wheel load; adaptive stepping ran out of passes and its
        last, unsplit step exceeded ``max_increment``. Tamping starts a new series of increments. The explicit
        loop overshoots when ΔN is too large for the feedback (fast, heavy traffic): scenario B under a 200 kN
        wheel load at 200 km/h goes 0.26, 0.44, 1.8, 8.9, 186 mm of differential increment per 100 000
        cycles, every number finite (warned at the third). Returns the message, or None."""
        inc = record.settlement - level_before
        self._differential.append(float(np.max(np.abs(inc - inc.mean()))))
        d = self._differential[-(RUNAWAY_ITERATIONS + 1) :]
        ratios = [b / a if a > 0 else math.inf for a, b in zip(d[:-1], d[1:])]
        static = float(np.max(self.system.static_wheel_loads))
        factor = record.max_contact_force / static if static > 0 else 0.0
        why = None
        growing = len(ratios) == RUNAWAY_ITERATIONS and min(ratios) > RUNAWAY_GROWTH
        jump = bool(ratios) and ratios[-1] > RUNAWAY_JUMP and d[-2] > 0.1 * RUNAWAY_FLOOR  # not from a flat start
        if (growing or jump) and d[-1] > RUNAWAY_FLOOR:
            why = (
                "differential settlement increments grow geometrically (x"
                + ", x".join(f"{r:.3g}" for r in ratios)
                + f" per iteration, now {d[-1] * 1e3:.3g} mm)"
            )
        elif factor > RUNAWAY_FORCE_FACTOR:
            why = f"the contact force reached {factor:.3g} times the static wheel load"
        elif self.adaptive and record.passes >= self.max_passes_per_iteration and d[-1] > self.max_increment:
            why = (
                f"adaptive stepping ran out of passes (max_passes_per_iteration {self.max_passes_per_iteration}) and "
                f"took the rest of the iteration in one step: differential increment {d[-1] * 1e3:.3g} mm"
            )
        if why is None or self.on_runaway == "ignore":
            return None
        smaller = (f"raise max_passes_per_iteration (now {self.max_passes_per_iteration}) or max_increment (now "
                   f"{self.max_increment:.3g} m)" if self.adaptive
                   else f"use adaptive=True (max_increment {self.max_increment:.3g} m)")
        msg = (
            f"settlement loop diverging after {self.cycles:.4g} cycles: {why}. Reduce cycles_per_iteration "
            f"(now {self.cycles_per_iteration:.4g}), {smaller}, "
            "or feedback='support' (the settled supports carry less: self-limiting)"
        )
        if self.on_runaway == "raise":
            raise RunawayError(msg)
        import warnings

        warnings.warn(msg, RunawayWarning, stacklevel=3)
        return msg

    def tamp(self, mask, model: TampingModel | None = None, rng: np.random.Generator | None = None) -> TampingResult:
        """Tamp the sleepers where ``mask`` is True: the level is restored but for a residual, consolidation
        restarts there and the ballast damage raises their settlement rate (see :mod:`physics.tamping`)."""
        model = TampingModel() if model is None else model
        rng = np.random.default_rng(0) if rng is None else rng
        level = self.level
        res = tamp(level, mask, model, rng, self.tampings)
        restarted = res.restarted_mask
        self.state = self.state.restarted(restarted, rate_factor=self.base_rate * res.rate_factor)
        self.offset = np.where(restarted, res.level, self.offset)
        self.tampings = res.tampings.astype(np.int64)
        self._differential.clear()  # increments before and after tamping are not one series
        return res

    def run(self, iterations: int, progress=None) -> DegradationHistory:
        """Run ``iterations`` iterations of ``cycles_per_iteration``; ``progress`` is called after each with
        (i, record) (e.g. to update a progress bar). Returns the whole history."""
        for i in range(check_int("iterations", iterations, low=0, high=1_000_000)):
            rec = self.advance()
            if progress is not None:
                progress(i, rec)
        return self.history


def _implicit_states(sims: list[TrackDegradation], force: np.ndarray, cycles: float) -> list[SettlementState]:
    """The implicit settlement step of every simulator (same law) under ``force`` (n_sims, n) in one batched
    call; the new states, in order."""
    st = [s.state for s in sims]
    u, c = implicit_settlement_step(
        sims[0].law,
        np.stack([x.settlement for x in st]),
        np.stack([x.cycles for x in st]),
        np.stack([x.rate_factor for x in st]),  # type: ignore[misc]  # never None once the state is built
        force,
        np.stack([s.support_influence for s in sims]),
        cycles,
        band=INFLUENCE_BAND,
    )
    return [SettlementState(u[b], c[b], x.rate_factor) for b, x in enumerate(st)]


def simulate_batch(sims: list[TrackDegradation]) -> list[PassResult]:
    """One pass for each simulator, all in one batched call of the dynamics (same vehicle, speed and options;
    tracks may differ in their supports)."""
    if not sims:
        return []
    s0 = sims[0]
    for s in sims[1:]:
        if (
            s.vehicle != s0.vehicle
            or s.speed != s0.speed
            or s.pass_options != s0.pass_options
            or s.engine != s0.engine
            or (s.model_track.n_sleepers != s0.model_track.n_sleepers)
        ):
            raise ValueError("simulate_batch needs simulators with the same vehicle, speed, options, engine and length")
    if any(s.feedback != s0.feedback for s in sims):
        raise ValueError("simulate_batch needs simulators with the same feedback")
    groups: dict = {}  # rows whose engine options differ (a steady start that does not fit) run apart
    for b, s in enumerate(sims):
        options = s.engine.options_for(s.model_track, s.vehicle, s.n_extra)
        groups.setdefault(tuple(sorted(options.items())), []).append(b)
    results: list = [None] * len(sims)
    for key, rows in groups.items():
        for b, res in zip(rows, _simulate_group([sims[b] for b in rows], dict(key))):
            results[b] = res
    return results


def _simulate_group(sims: list[TrackDegradation], engine_options: dict) -> list[PassResult]:
    """One batched pass for simulators that share every option (:func:`simulate_batch`)."""
    s0 = sims[0]
    options = {**s0.pass_options, **engine_options}
    if s0.feedback == "irregularity":
        rails = [s.rail_level() for s in sims]
        return simulate_passes([s.model_track for s in sims], s0.vehicle, s0.speed, rails, x_end=s0.pass_end,
                               on_overload="ignore", **options)  # (the loop checks its own: check_runaway)
    profiles = np.stack([s.model_irregularity() for s in sims])
    return simulate_passes([s.model_track for s in sims], s0.vehicle, s0.speed, None, support_settlement=profiles,
                           x_end=s0.pass_end, on_overload="ignore", **options)  # (the loop checks its own)
