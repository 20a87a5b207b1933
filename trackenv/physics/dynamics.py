"""One pass of a vehicle over the standing track, and the track's static and harmonic responses.

:func:`simulate_passes` is the one implementation of the time integration; it takes a leading batch axis (many
tracks with the same mesh, many irregularities) and :func:`simulate_pass` is its batch of one. The integration
is implicit (Newmark average acceleration), the Hertz contact is solved every step, and the track is integrated
in a window that follows the axles (see :mod:`trackenv.physics._kernel`); ``window_bays=None`` integrates the
whole track.
"""

from __future__ import annotations

import collections
import functools
import math
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from . import _kernel, _side_by_side, _step
from ._checks import (
    caller_stacklevel,
    check_array,
    check_choice,
    check_instance,
    check_scalar,
    check_speed,
    check_time_steps,
)
from .contact import HertzContact, LinearContact
from .timestep import (
    DT_REFERENCE_S,
    MAX_SLOPE_CHANGE_PER_STEP,
    auto_time_step,
    check_dt_option,
    check_time_step,
    contact_period,
    slope_change_per_step,
)
from .track import HALF_BANDWIDTH, Track, add_supports, hermite_shape, rail_bands
from .vehicle import Car, Train, VehicleSystem, Wheelset
from .window_ends import check_window_ends, static_ends

Irregularity = np.ndarray | Callable[[np.ndarray], np.ndarray] | None
SLEEPER_FORCE_MEASURES = ("ballast", "pad_plus_ballast")
ON_OVERLOAD = ("warn", "raise", "ignore")
#: Peak contact force, as a multiple of the static wheel load, beyond which a pass is out of any plain track's
#: range (dynamic factors from track geometry stay below about 2; a load dropped onto the track at rest gives 2)
#: **[assumption]**: a wrong unit (stiffness in kN/m, a level in mm) or an irregularity far beyond service limits.
OVERLOAD_FACTOR = 3.0
#: [m] the rail's static deflection under the largest static wheel load (a Winkler beam on the track's mean
#: supports) above which no ballasted track stands: 0.5-3 mm in service, 25 mm with pads and ballast of 1 MN/m
#: (the softest the window's validation covers); stiffnesses in kN/m give some 100-200 mm **[assumption]**
MAX_STATIC_DEFLECTION_M = 0.05


class OverloadWarning(RuntimeWarning):
    """A pass's contact force exceeded :data:`OVERLOAD_FACTOR` times the static wheel load."""


class UnloadedTrackWarning(UserWarning):
    """A pass left a stretch of track between two axles under no wheel (:func:`simulate_passes`)."""


class OverloadError(RuntimeError):
    """A pass's contact force exceeded :data:`OVERLOAD_FACTOR` times the static wheel load and
    ``on_overload="raise"`` was asked for."""


@dataclass(frozen=True, eq=False)
class PassResult:
    """What one pass produced. Arrays over time have shape (n_steps + 1, n_axles).

    ``sleeper_force`` is the peak downward force each sleeper puts into the ballast (ballast spring + damper)
    during the pass [N], or, with ``sleeper_force_measure="pad_plus_ballast"``, the paper's measure: the peak of
    the railpad and ballast forces on the sleeper added together. Both exclude the track's own dead weight.
    """

    time: np.ndarray  # (n_steps + 1,) [s]
    wheel_position: np.ndarray  # (n_steps + 1, n_axles) [m]
    contact_force: np.ndarray  # (n_steps + 1, n_axles) [N]
    rail_displacement: np.ndarray  # (n_steps + 1, n_axles) rail deflection under each wheel [m]
    wheel_displacement: np.ndarray  # (n_steps + 1, n_axles) [m]
    irregularity: np.ndarray  # (n_steps + 1, n_axles) rail level under each wheel [m]
    sleeper_force: np.ndarray  # (n_sleepers,) [N]
    ballast_force: np.ndarray  # (n_sleepers,) peak ballast force [N]
    pad_plus_ballast_force: np.ndarray  # (n_sleepers,) peak of pad + ballast force [N]
    static_wheel_load: np.ndarray  # (n_axles,) [N]
    sleeper_positions: np.ndarray  # (n_sleepers,) [m]
    speed: float  # [m/s]
    dt: float  # [s]
    bay_contact_force: np.ndarray | None = None  # (n_sleepers,) contact_force_profile(), when the batch found it

    @property
    def max_contact_force(self) -> float:
        return float(self.contact_force.max())

    def contact_force_profile(self, positions: np.ndarray | None = None) -> np.ndarray:
        """Peak contact force of any axle within each sleeper bay (bay k spans ±s/2 around sleeper k) [N]."""
        if positions is None and self.bay_contact_force is not None:
            return self.bay_contact_force.copy()
        pos = self.sleeper_positions if positions is None else np.asarray(positions)
        out = np.zeros(pos.size)
        for j, (starts, bays) in enumerate(_bay_runs(self.wheel_position, pos)):
            np.maximum.at(out, bays, np.maximum.reduceat(self.contact_force[:, j], starts))
        return out


def _bay_runs(wheel_position: np.ndarray, pos: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """For each axle: the first time step of every run of steps with its wheel over one sleeper bay (bay k
    spans ±s/2 around sleeper k, the ends taking whatever lies beyond them), and that bay."""
    s = pos[1] - pos[0]
    idx = np.clip(np.rint(wheel_position / s).astype(int), 0, pos.size - 1)
    runs = []
    for j in range(idx.shape[1]):
        col = idx[:, j]
        starts = np.flatnonzero(np.concatenate(([True], col[1:] != col[:-1])))
        runs.append((starts, col[starts]))
    return runs


def _bay_peaks(force: np.ndarray, wheel_position: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """:meth:`PassResult.contact_force_profile` of every row of a contact-force history in the kernel's layout
    (chunks, n_steps + 1, n_axles, width), read once in that layout: (chunks, n_sleepers, width)."""
    out = np.zeros((pos.size,) + force.shape[:1] + force.shape[3:])
    for j, (starts, bays) in enumerate(_bay_runs(wheel_position, pos)):
        np.maximum.at(out, bays, np.moveaxis(np.maximum.reduceat(force[:, :, j], starts, axis=1), 1, 0))
    return np.moveaxis(out, 0, 1)


def _vehicle_system(vehicle) -> VehicleSystem:
    if isinstance(vehicle, VehicleSystem):
        return vehicle
    if isinstance(vehicle, (Wheelset, Car, Train)):
        return _assembled_system(vehicle)
    raise ValueError(f"vehicle must be a Wheelset, Car, Train or VehicleSystem, got {type(vehicle).__name__}")


@functools.lru_cache(maxsize=32)
def _assembled_system(vehicle: Wheelset | Car | Train) -> VehicleSystem:
    """``vehicle.system()``, assembled once per vehicle and shared by its passes (with its statics, which the
    static start and the auto time step read every pass): vehicles are frozen values, and the shared system's
    arrays are made read-only so that no pass can change another's vehicle."""
    system = vehicle.system()
    for arr in (system.mass, system.damping, system.stiffness, system.force, system.wheel_dofs, system.axle_offsets):
        arr.flags.writeable = False
    return system


def _contact_law(contact):
    if contact is None:
        return HertzContact()
    if isinstance(contact, (HertzContact, LinearContact)):
        return contact
    raise ValueError(f"contact must be a HertzContact or LinearContact, got {type(contact).__name__}")


def _as_tracks(tracks) -> list[Track]:
    if isinstance(tracks, Track):
        return [tracks]
    tracks = list(tracks) if isinstance(tracks, (list, tuple)) else []
    if not tracks or not all(isinstance(t, Track) for t in tracks):
        raise ValueError("track(s) must be a Track or a non-empty sequence of Track")
    t0 = tracks[0]
    for t in tracks[1:]:
        if (t.n_sleepers, t.sleeper_spacing, t.elements_per_bay, t.rail_bending_stiffness, t.rail_mass) != (
            t0.n_sleepers,
            t0.sleeper_spacing,
            t0.elements_per_bay,
            t0.rail_bending_stiffness,
            t0.rail_mass,
        ):
            raise ValueError(
                "tracks in one batch must share sleepers, spacing, mesh and rail; only support properties may differ"
            )
    return tracks


@functools.lru_cache(maxsize=16)
def _rail_bands_cached(n_sleepers: int, epb: int, element_length: float, ei: float, mass: float):
    from .track import DofLayout

    return rail_bands(DofLayout.build(n_sleepers, epb), element_length, ei, mass)


def _rail_bands(lay, element_length: float, ei: float, mass: float, *, copy: bool = True):
    """M, C, K of the bare rail (no supports), assembled once per mesh: copies, or with ``copy=False`` the kept
    arrays themselves, for callers that only read them."""
    kept = _rail_bands_cached(lay.sleeper.size, int(lay.sleeper_node[1]), element_length, ei, mass)
    return tuple(b.copy() for b in kept) if copy else kept


def batched_bands(tracks: Sequence[Track]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """M, C, K bands of every track, shape (batch, n_dof, 5): the rail is assembled once, the supports of all
    tracks added at once (each row is ``Track.banded_matrices``, the same numbers)."""
    t0 = tracks[0]
    lay = t0.dof_layout
    rail = _rail_bands(lay, t0.element_length, t0.rail_bending_stiffness, t0.rail_mass, copy=False)
    m, c, k = (np.repeat(band[None], len(tracks), axis=0) for band in rail)
    names = ("pad_stiffness", "pad_damping", "sleeper_mass", "ballast_stiffness", "ballast_damping")
    add_supports(m, c, k, lay, *(np.stack([getattr(t, name) for t in tracks]) for name in names))
    return m, c, k


def lapack_lower(band: np.ndarray) -> np.ndarray:
    """Our lower band storage ``band[i, k] = A[i, i-k]`` as LAPACK's ``ab[k, j] = A[j+k, j]``."""
    n, b1 = band.shape
    ab = np.zeros((b1, n), dtype=band.dtype)
    for k in range(b1):
        ab[k, : n - k] = band[k:, k]
    return ab


def _point_load_vector(track: Track, x: float) -> tuple[np.ndarray, np.ndarray]:
    """DOF indices and Hermite weights of a point on the rail at position x."""
    le = track.element_length
    e = int(np.clip(np.floor(x / le), 0, track.n_nodes - 2))
    lay = track.dof_layout
    dofs = np.array([lay.node_w[e], lay.node_theta[e], lay.node_w[e + 1], lay.node_theta[e + 1]])
    return dofs, hermite_shape(x / le - e, le)


def static_deflection(track: Track, load: float = 100e3, x: float | None = None) -> float:
    """Rail deflection [m] under a static point ``load`` [N] at position ``x`` [m] (default mid-track)."""
    check_instance("track", track, Track)
    load = check_scalar("load", load, low=0.0, high=1e7)
    x = track.length / 2 if x is None else check_scalar("x", x, low=0.0, high=track.length)
    _, _, k = track.banded_matrices()
    dofs, shp = _point_load_vector(track, x)
    f = np.zeros(track.n_dof)
    f[dofs] = shp * load
    u = scipy.linalg.solveh_banded(lapack_lower(k), f, lower=True)
    return float(shp @ u[dofs])


def receptance(track: Track, x: float | None = None, frequencies=None) -> np.ndarray:
    """Complex rail receptance w/F [m/N] at position ``x`` [m] for ``frequencies`` [Hz]: the direct
    frequency response of the full track, (K + iωC − ω²M)⁻¹ at the load point."""
    check_instance("track", track, Track)
    x = track.length / 2 if x is None else check_scalar("x", x, low=0.0, high=track.length)
    default = np.logspace(1, np.log10(3000), 200)
    f = check_array("frequencies", default if frequencies is None else frequencies, low=0.0, high=1e5)
    m, c, k = track.banded_matrices()
    dofs, shp = _point_load_vector(track, x)
    rhs = np.zeros(track.n_dof, dtype=complex)
    rhs[dofs] = shp
    b = HALF_BANDWIDTH
    out = np.empty(f.size, dtype=complex)
    for i, fi in enumerate(np.ravel(f)):
        w = 2 * np.pi * fi
        low = lapack_lower(k + 1j * w * c - w * w * m)
        full = np.zeros((2 * b + 1, track.n_dof), dtype=complex)
        full[b:] = low
        for kk in range(1, b + 1):
            full[b - kk, kk:] = low[kk, : track.n_dof - kk]
        u = scipy.linalg.solve_banded((b, b), full, rhs)
        out[i] = shp @ u[dofs]
    return out.reshape(np.shape(f))


def newmark_constants(dt: float, beta: float = 0.25, gamma: float = 0.5) -> np.ndarray:
    """a0..a7 of the Newmark scheme in its effective-stiffness form (Bathe's notation)."""
    return np.array(
        [
            1 / (beta * dt * dt),
            gamma / (beta * dt),
            1 / (beta * dt),
            1 / (2 * beta) - 1,
            gamma / beta - 1,
            dt / 2 * (gamma / beta - 2),
            dt * (1 - gamma),
            gamma * dt,
        ]
    )


def _clusters(offsets: np.ndarray, gap: float) -> np.ndarray:
    """Group axles (sorted by offset) whose neighbours are closer than ``gap`` into one track window."""
    order = np.argsort(offsets)
    cl = np.zeros(offsets.size, dtype=np.int64)
    c = 0
    for a, b in zip(order[:-1], order[1:]):
        if offsets[b] - offsets[a] > gap:
            c += 1
        cl[b] = c
    return cl


_SPLINE_ROWS = 64  # rows per spline of :func:`_irregularity_levels`


def _irregularity_levels(irrs: list, track: Track, x: np.ndarray, name: str) -> list[np.ndarray | None]:
    """Rail level at positions x for each row's irregularity, None where the row has none (a straight rail): a
    callable of x, or a per-sleeper or per-node profile (natural cubic spline through it). The profiles on one
    grid are interpolated by one spline through all of them (its columns), evaluated once: the same numbers as
    one spline per row (bit-identical; scipy solves and evaluates each column alike) at a fraction of the cost,
    since finding each position's interval and building the spline's system are shared. A row whose irregularity
    is the same object as an earlier row's shares its levels."""
    out: list[np.ndarray | None] = [None] * len(irrs)
    first: dict[int, int] = {}  # id of an irregularity -> the first row that has it
    profiles: dict[str, list[tuple[int, np.ndarray]]] = {"sleeper": [], "node": []}
    for b, irr in enumerate(irrs):
        if irr is None:
            continue
        if id(irr) in first:
            continue
        first[id(irr)] = b
        if callable(irr):
            z = np.asarray(irr(x), dtype=float)
            if z.shape != x.shape or not np.all(np.isfinite(z)):
                raise ValueError(f"{name} callable must return finite values shaped like its input")
            out[b] = z
            continue
        arr = check_array(name, irr)
        if arr.ndim != 1 or arr.size not in (track.n_sleepers, track.n_nodes):
            raise ValueError(
                f"{name} must have one value per sleeper ({track.n_sleepers}) or per rail node "
                f"({track.n_nodes}), got shape {arr.shape}"
            )
        profiles["sleeper" if arr.size == track.n_sleepers else "node"].append((b, arr))
    import scipy.interpolate  # here, not at import: it adds ~0.3 s to `import trackenv`

    xc = np.clip(x, 0.0, track.length)
    for grid_name, rows in profiles.items():
        if not rows:
            continue
        grid = track.sleeper_positions if grid_name == "sleeper" else track.node_positions
        for start in range(0, len(rows), _SPLINE_ROWS):  # blocks of rows: a bounded temporary
            block = rows[start : start + _SPLINE_ROWS]
            spline = scipy.interpolate.CubicSpline(grid, np.stack([a for _, a in block], axis=-1), bc_type="natural")
            levels = spline(xc)  # (*x.shape, rows of the block)
            for k, (b, _) in enumerate(block):
                out[b] = levels[..., k]
    for b, irr in enumerate(irrs):
        if irr is not None and out[b] is None:
            out[b] = out[first[id(irr)]]
    return out


def _window_dofs(track: Track, x_axles: np.ndarray, margin_bays: int) -> tuple[int, int]:
    """DOF range [lo, hi) of the track window around axles at ``x_axles`` (as the kernel places it)."""
    n_s = track.n_sleepers
    # the bay of the element under each axle, as the kernel finds it
    elements = np.clip((x_axles / track.element_length).astype(int), 0, track.n_nodes - 2)
    bays = elements // track.elements_per_bay
    s_lo, s_hi = max(0, bays.min() - margin_bays), min(n_s - 1, bays.max() + 1 + margin_bays)
    lay = track.dof_layout
    return int(lay.node_w[lay.sleeper_node[s_lo]]), int(lay.sleeper[s_hi] + 1)


# LAPACK's banded Cholesky routines, called directly for the pass set-up's per-row solves: the same routines
# (and numbers) as scipy.linalg.solveh_banded / cholesky_banded / cho_solve_banded, without their input checks
# and dispatch, which cost several times the solve on these small systems. Our arrays are finite by construction.
_PBTRF, _PBTRS = scipy.linalg.get_lapack_funcs(("pbtrf", "pbtrs"), (np.zeros(1),))


def _lapack_info(routine: str, info: int) -> None:
    if info > 0:
        raise np.linalg.LinAlgError(f"{routine}: the track's stiffness is not positive definite (minor {info})")
    if info < 0:  # pragma: no cover (our arguments are well-formed)
        raise ValueError(f"{routine}: illegal value in argument {-info}")


@functools.lru_cache(maxsize=256)
def _track_stiffness(track: Track) -> np.ndarray:
    """``track``'s stiffness band as :func:`batched_bands` assembles a row of it (the same numbers), kept per track
    object (immutable, hashed by identity): an episode's passes over one model track build it once."""
    return batched_bands([track])[2][0]


@functools.lru_cache(maxsize=256)
def _stiffness_factor(track: Track) -> np.ndarray:
    """The banded Cholesky factor (LAPACK pbtrf) of ``track``'s stiffness, kept per track: pbtrs with it solves
    K u = f as pbsv (scipy.linalg.solveh_banded) does, which runs the same two routines."""
    factor, info = _PBTRF(lapack_lower(_track_stiffness(track)), lower=1)
    _lapack_info("pbtrf", info)
    return factor


_STATIC_ENDS_CACHE_SIZE = 256  # tracks whose static ends are kept (as the per-track caches above)
_STATIC_ENDS: collections.OrderedDict = collections.OrderedDict()  # track -> its static ends, least recent first


def _track_ends(tracks: Sequence[Track]) -> list[np.ndarray]:
    """The static ends of each track (n_sleepers, 12 + 2 bay_dofs): the outside's stiffness, its condensed damping
    and the static extension onto the next bay (:func:`~trackenv.physics.window_ends.static_ends`), kept per track
    object (read-only; the most recent :data:`_STATIC_ENDS_CACHE_SIZE`): an episode's passes over its model tracks
    compute them once, the tracks missing as one batch."""
    return _kept(_STATIC_ENDS, list(tracks), _STATIC_ENDS_CACHE_SIZE,
                 lambda missing: list(static_ends(missing, batched_bands(missing)[2])))


def _track_outside_stiffness(track: Track) -> np.ndarray:
    """:func:`~trackenv.physics.window_ends.outside_stiffness` of ``track`` (n_sleepers, 6), read-only: the first
    columns of its static ends (:func:`_track_ends`)."""
    return _track_ends([track])[0][:, :6]


def _kept(cache: collections.OrderedDict, keys: list, size: int, compute: Callable[[list], list]) -> list:
    """The value of each of ``keys`` in ``cache`` (an OrderedDict, least recently used first), the keys missing
    computed at once by ``compute`` (their list, without repeats, to their values), made read-only and kept; the
    cache is then cut to its ``size`` most recent entries (after the values are read: a batch may hold more)."""
    missing = list(dict.fromkeys(k for k in keys if k not in cache))
    if missing:
        for key, value in zip(missing, compute(missing), strict=True):
            if isinstance(value, np.ndarray):
                value.flags.writeable = False
            cache[key] = value
    for key in keys:
        cache.move_to_end(key)
    values = [cache[k] for k in keys]
    while len(cache) > size:
        cache.popitem(last=False)
    return values


def _window_ends(tracks: Sequence[Track], ends: str, a1: float) -> np.ndarray:
    """The kernel's window ends per row (see :class:`_step.Rows`): zeros (rows, n_sleepers, 6) for clamped ends
    ("rest"); for "static" (rows, n_sleepers, 12 + 2 bay_dofs) the outside's stiffness plus ``a1`` (Newmark's
    a1) times its damping, that damping, and the extension."""
    if ends == "rest":
        return np.zeros((len(tracks), tracks[0].n_sleepers, 6))
    out = np.stack(_track_ends(tracks))
    out[:, :, :6] += a1 * out[:, :, 6:12]
    return out


@functools.lru_cache(maxsize=256)
def _track_window_factors(track: Track, windows: tuple, ends: str = "rest") -> list[tuple[int, int, np.ndarray]]:
    """:func:`_window_factors` of ``track``'s stiffness, kept per track, windows and ends."""
    k_band = _track_stiffness(track)
    if ends == "rest":
        return _window_factors(k_band, windows)
    outside, lay = _track_outside_stiffness(track), track.dof_layout
    bay_dofs = int(lay.sleeper[1] - lay.sleeper[0])
    out = []
    for lo, hi in windows:
        band = k_band[lo:hi].copy()
        first, last = outside[lo // bay_dofs, :3], outside[(hi - 3) // bay_dofs, 3:]
        band[0, 0] += first[0]  # the window's first rail node (w, θ) and its last (w, θ, then its sleeper)
        band[1, 1] += first[1]
        band[1, 0] += first[2]
        band[-3, 0] += last[0]
        band[-2, 1] += last[1]
        band[-2, 0] += last[2]
        out += _window_factors(band, [(0, hi - lo)])
    return [(lo, hi, factor) for (lo, hi), (_, _, factor) in zip(windows, out)]


_NO_REUSE = _step.Reuse(np.zeros((0, 2 * _step.B + 3, 0)), np.zeros((0, 2), dtype=np.int64),
                          np.zeros((0, 2, 0)), np.zeros((0, 2), dtype=np.int64))
"""What a batch of several rows passes the kernel: nothing kept (see :class:`_step.Reuse`)."""


def _store_shapes(track: Track, m_cap: int) -> tuple[tuple[int, int, int], tuple[int, int, int]]:
    """Shapes of a store's factors and bay columns (:class:`_step.Reuse`) for ``track``, windows of up to
    ``m_cap`` DOFs."""
    n = track.n_sleepers
    return (n, 2 * _step.B + 3, m_cap), (n, 2 * (track.elements_per_bay + 1), m_cap)


@functools.lru_cache(maxsize=16)
def _kept_factors(track: Track, dt: float, m_cap: int, ends: str = "rest") -> _step.Reuse:
    """The kernel's store of window factors and bay columns for one-row passes over ``track`` at ``dt`` (windows
    of up to ``m_cap`` DOFs), kept per track object, dt and window size: the effective stiffness K + a0 M + a1 C
    is the same in every such pass, so each window's factor and each bay's columns are computed once, by the
    same arithmetic, and read back in later passes (bit-identical; an episode's or the paper loop's passes run
    over one model track). ~1.5 MB for the env's 60 m track; 16 tracks at most, of up to 8 MB each. The window
    ends (``ends``, see :func:`simulate_passes`) change the factors: each kind is kept apart."""
    factor_shape, columns_shape = _store_shapes(track, m_cap)
    n = track.n_sleepers
    return _step.Reuse(np.zeros(factor_shape), np.full((n, 2), -1, dtype=np.int64),
                         np.zeros(columns_shape), np.full((n, 2), -1, dtype=np.int64))


def _window_dof_bound(track: Track, axle_offsets: np.ndarray, cluster: np.ndarray, margin: int) -> int:
    """The most DOFs a window of any axle group can span: the group's axles over at most ceil(span/s) + 1 bays,
    ``margin`` bays either side, and the last sleeper's rail node and DOF (see :func:`_window_dofs`)."""
    lay = track.dof_layout
    bay_dofs = int(lay.sleeper[1] - lay.sleeper[0])
    tail = int(lay.sleeper[0] - lay.node_w[lay.sleeper_node[0]]) + 1
    span = max(float(np.ptp(axle_offsets[cluster == c])) for c in range(int(cluster.max()) + 1))
    return (math.ceil(span / track.sleeper_spacing) + 2 + 2 * margin) * bay_dofs + tail


_REUSE_MAX_DOFS = 400  # windows longer than this (a window as long as the track) do not move: nothing to keep
# the most one track's store may hold (~650 sleepers, ~390 m, with the env's window): a pass over a km-long track
# would keep ~100 MB, and 16 of them would stay alive in the lru; such tracks recompute (as batches do)
_REUSE_MAX_BYTES = 8 * 2**20


def _one_row_reuse(track: Track, dt: float, axle_offsets: np.ndarray, cluster: np.ndarray,
                   margin: int, ends: str = "rest") -> _step.Reuse:
    """What a one-row pass over ``track`` keeps for the next one (:func:`_kept_factors`), or nothing
    (``_NO_REUSE``) where its windows or its store would exceed the bounds above."""
    m_cap = _window_dof_bound(track, axle_offsets, cluster, margin)
    store_bytes = 8 * sum(math.prod(shape) for shape in _store_shapes(track, m_cap))
    if m_cap > _REUSE_MAX_DOFS or store_bytes > _REUSE_MAX_BYTES:
        return _NO_REUSE
    return _kept_factors(track, float(dt), m_cap, ends)


def _window_factors(k_band: np.ndarray, windows) -> list[tuple[int, int, np.ndarray]]:
    """The banded Cholesky factor of the stiffness on each window [lo, hi) (LAPACK pbtrf, what solveh_banded
    runs before its solve): factored once for the static start's fixed-point sweeps."""
    out = []
    for lo, hi in windows:
        factor, info = _PBTRF(lapack_lower(k_band[lo:hi]), lower=1)
        _lapack_info("pbtrf", info)
        out.append((lo, hi, factor))
    return out


def _static_in_windows(factors: list[tuple[int, int, np.ndarray]], f: np.ndarray) -> np.ndarray:
    """Static displacements under ``f`` with the track outside the windows (``_window_factors``) at rest
    (LAPACK pbtrs, what scipy.linalg.cho_solve_banded runs)."""
    u = np.zeros_like(f)
    for lo, hi, factor in factors:
        x, info = _PBTRS(factor, f[lo:hi], lower=1)
        _lapack_info("pbtrs", info)
        u[lo:hi] = x
    return u


WINDOW_DECAY_LENGTHS = 6.5  # window margin in decay lengths 1/β (calibrated: tests/physics/test_dynamics.py)
WINDOW_AVERAGING_SLEEPERS = 5  # β from the softest stretch of this many supports
WINDOW_MIN_BETA_SPACING = 0.4  # softer than this (decay length > 2.5 bays): the whole track moves, no window


def window_margin(track: Track, decay_lengths: float = WINDOW_DECAY_LENGTHS) -> int | None:
    """Sleeper bays of track the kernel integrates on each side of an axle group, from the track's decay length.

    The rail's deflection decays like e^{-βx}, β = (k_f / 4EI)^¼, with k_f the pad and ballast in series per
    spacing. β is taken on the softest stretch of WINDOW_AVERAGING_SLEEPERS supports (a transition's soft side,
    a run of voided sleepers; one voided sleeper barely widens the window) and the margin spans
    WINDOW_DECAY_LENGTHS decay lengths: on a sweep of pad and ballast stiffness 1e6-1e9 N/m, a voided sleeper
    and a transition zone this keeps the fast path within 1 % of the full model. Soft track needs more decay
    lengths than stiff (its dynamic response reaches further than the static one): below β·s =
    WINDOW_MIN_BETA_SPACING (1e6 N/m ballast: 2.6 % off with a 22-bay window on 60 m) the whole track is
    integrated. None (the whole track) there and where the window would cover half the track anyway.
    ``decay_lengths`` sets another margin (a shorter one suits ``window_ends="static"``: see
    :mod:`trackenv.physics.window_ends`)."""
    decay_lengths = check_scalar("decay_lengths", decay_lengths, low=0.5, high=100.0)
    beta = _softest_beta(track)
    if beta * track.sleeper_spacing < WINDOW_MIN_BETA_SPACING:
        return None
    margin = max(2, math.ceil(decay_lengths / (beta * track.sleeper_spacing) - 1e-9))
    if 2 * margin + 2 >= track.n_sleepers / 2:
        return None
    return margin


_SOFTEST_BETA: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # track -> β of its softest stretch [1/m]


def _softest_beta(track: Track) -> float:
    """β = (k_f / 4EI)^¼ [1/m] on the softest stretch of WINDOW_AVERAGING_SLEEPERS supports of ``track``
    (:func:`window_margin`), kept while the track object lives: every pass over a model track, and the env's
    choice of each pass's options, read it."""
    beta = _SOFTEST_BETA.get(track)
    if beta is None:
        k = track.support_stiffness
        n = min(WINDOW_AVERAGING_SLEEPERS, k.size)
        k_f = np.convolve(k, np.ones(n) / n, mode="valid").min() / track.sleeper_spacing
        beta = _SOFTEST_BETA[track] = (k_f / (4.0 * track.rail_bending_stiffness)) ** 0.25
    return beta


def check_window_bays(window_bays) -> None:
    """``window_bays`` as every layer takes it: "auto", None or an integer >= 2."""
    if window_bays is None or (isinstance(window_bays, str) and window_bays == "auto"):
        return
    if isinstance(window_bays, bool) or not isinstance(window_bays, (int, np.integer)) or window_bays < 2:
        raise ValueError(f"window_bays must be 'auto', an integer >= 2 or None, got {window_bays!r}")


def _settlement_rows(support_settlement, n_rows: int, track: Track) -> np.ndarray:
    """``support_settlement`` validated as (n_rows, n_sleepers) [m] (one row is shared by every row)."""
    g = check_array("support_settlement", support_settlement)
    if g.ndim == 1:
        g = np.broadcast_to(g, (n_rows, g.size))
    if g.shape != (n_rows, track.n_sleepers):
        raise ValueError(f"support_settlement must have shape ({n_rows}, {track.n_sleepers}), got {g.shape}")
    return g


def _chunking(n_rows: int, max_width: int = _kernel.WIDTHS[-1]) -> tuple[int, int]:
    """How the kernel cuts a batch: (number of chunks, rows per chunk). Enough chunks for every numba thread
    (the chunks run in parallel), no more than ``max_width`` rows per chunk (a chunk's window stays in cache),
    the width rounded up to one the kernel is compiled for; the last rows are padded with copies of the last row.
    A row's result does not depend on this choice."""
    import numba

    threads = numba.get_num_threads()
    n_chunks = max(-(-n_rows // max_width), min(n_rows, threads))
    need = -(-n_rows // n_chunks)
    return n_chunks, min(w for w in _kernel.WIDTHS if w >= need)


def _pack(x: np.ndarray, n_chunks: int, width: int) -> np.ndarray:
    """(rows, ...) -> (chunks, ..., width), contiguous, the batch axis last; padded with the last row."""
    pad = n_chunks * width - x.shape[0]
    if pad:
        x = np.concatenate([x, np.repeat(x[-1:], pad, axis=0)])
    x = x.reshape((n_chunks, width) + x.shape[1:])
    return np.ascontiguousarray(x.transpose(_batch_last(x.ndim)))


@functools.cache
def _batch_last(ndim: int) -> tuple[int, ...]:
    """The axes of ``np.moveaxis(x, 1, -1)`` for an array of ``ndim`` axes, as a transpose takes them (the packing
    runs a dozen times a pass: the axes are worked out once)."""
    return (0, *range(2, ndim), 1)


@functools.cache
def _batch_second(ndim: int) -> tuple[int, ...]:
    """The axes of ``np.moveaxis(x, -1, 1)`` for an array of ``ndim`` axes (the inverse of :func:`_batch_last`)."""
    return (0, ndim - 1, *range(1, ndim - 1))


def _packed_history(first: np.ndarray, n_steps: int, n_chunks: int, width: int) -> np.ndarray:
    """A time history (rows, n_steps + 1, ...) as :func:`_pack` lays it out, zero but for its first step
    ``first`` (rows, ...): allocated in place, not transposed from a zero array."""
    out = np.zeros((n_chunks, n_steps + 1) + first.shape[1:] + (width,))
    out[:, 0] = _pack(first, n_chunks, width)
    return out


def _row(x: np.ndarray, b: int, width: int) -> np.ndarray:
    """Row ``b`` of an array in the kernel's layout (chunks, ..., width): a view, (...)."""
    return x[b // width, ..., b % width]


def _unpack(x: np.ndarray, n_rows: int) -> np.ndarray:
    """The inverse of :func:`_pack`: (chunks, ..., width) -> (rows, ...)."""
    x = x.transpose(_batch_second(x.ndim))
    return np.ascontiguousarray(x.reshape((-1,) + x.shape[2:])[:n_rows])


def _mass_diagonals(mb: np.ndarray) -> np.ndarray:
    """A symmetric matrix in lower band storage (n, B+1) as its 2B+1 full diagonals, diagonal first (the kernel
    runs along the DOFs of one diagonal): out[d, i] = M[i, i + d - B]."""
    n, b1 = mb.shape
    bw = b1 - 1
    out = np.zeros((2 * bw + 1, n))
    for k in range(b1):
        out[bw - k, k:] = mb[k:, k]
        out[bw + k, : n - k] = mb[k:, k]
    return out


START_OPTIONS = ("static", "rest", "steady")
BACKENDS = ("numba", "torch")
STEADY_RUN_BAYS = 40  # sleeper bays the steady state is integrated over, from a static start (see _steady_states)
_STEADY_CACHE_SIZE = 4096  # steady states kept (one per track entry, vehicle, speed, dt, window and start phase;
# about 7 kB each on the line's segments: the long line's 250 segments and two wheelsets, 8 lines, hold 4000)


def simulate_passes(
    tracks: Track | Sequence[Track],
    vehicle,
    speed: float,
    irregularities=None,
    *,
    dt: float | str = DT_REFERENCE_S,
    contact=None,
    start: str = "static",
    x_start: float | None = None,
    x_end: float | None = None,
    window_bays: int | str | None = "auto",
    window_ends: str = "rest",
    window_decay_lengths: float = WINDOW_DECAY_LENGTHS,
    sleeper_force_measure: str = "ballast",
    support_settlement=None,
    backend: str = "numba",
    device=None,
    on_overload: str = "warn",
) -> list[PassResult]:
    """Run one vehicle pass over each of a batch of tracks and/or irregularities (one result per row).

    ``tracks``: one Track (shared by every row) or one per row; ``irregularities``: None, an array (n_rows,
    n_sleepers or n_nodes) of rail level [m] (downward positive; between its points a natural cubic spline, which
    is smooth and swings beside a lone spike: a piecewise-linear or kinked level is given as a callable), or a list
    of such rows or callables z(x).
    ``speed`` [m/s] > 0; ``dt`` [s] within the bounds of :mod:`trackenv.physics.timestep`, or "auto": the
    coarsest step that keeps peak forces within 0.5 % of the reference step (that module's contract; a row whose
    wheel loses contact or whose rail level has a kink is rerun at the reference step, so rows of one batch may
    differ in dt).
    ``start``: "static" (vehicle and track in static equilibrium at the start), "rest" (the paper's transient: the
    vehicle is set on the unloaded track and drops in) or "steady": the periodic steady state of the vehicle
    running at ``speed`` over a track that continues the row's first sleeper (the track's entry) for ever, at the
    rail level under the vehicle at the start. The steady start needs a moving window that lies inside the track
    at the start: its default ``x_start`` is the vehicle's span plus ``window_bays + 1`` bays; a pass that starts
    it there converges on the entry's track without integrating an approach from rest (see :func:`_steady_states`).
    ``x_start``/``x_end``: leading-axle positions [m] where the pass starts/ends (default: the whole vehicle
    on the rail from the first to the last sleeper). ``window_bays``: sleeper bays of track integrated ahead of
    the leading and behind the trailing axle of each axle group; "auto" (default): sized per row from the
    track's decay length (:func:`window_margin`; rows that need different windows run as separate groups, so a
    row's result does not depend on its batch); None: the whole track. ``window_ends``: what the window's ends
    stand on, "rest" (default: the track beyond is held at rest, the ends clamped) or "static" (each end's rail
    node carries the static stiffness of all the track beyond it, :mod:`trackenv.physics.window_ends`: the
    deflection basin is right at any margin, so a shorter window keeps more of the full model's accuracy; the
    numba backend only). ``window_decay_lengths``: the margin "auto" sizes, in the track's decay lengths
    (:func:`window_margin`; :class:`~trackenv.physics.engine.PassEngine` bundles it with the start and the ends).
    ``support_settlement``: None or (n_rows, n_sleepers) permanent settlement of the ballast under each sleeper
    [m]: the base of each ballast spring is lowered by it and the rail bends over the settled supports. By
    superposition (the track is linear) the rail's static sag becomes the wheel's irregularity and the
    supports' static forces are added to the peak sleeper forces; a sleeper that settled more than its
    neighbours hangs partly in the rail and carries less (negative values: the linear model's tension where a
    real sleeper would lift off its ballast).
    ``backend``: "numba", the compiled kernel on the CPU, or "torch": the same integration batched over the rows in
    torch (:mod:`trackenv.physics.torch_pass`) on ``device`` ("cpu", "cuda", ...; None: the CPU), within ~1e-9
    relative of the kernel (its window solves round differently).
    ``on_overload``: "warn" (default, :class:`OverloadWarning`), "raise" (:class:`OverloadError`) or "ignore" when
    a row's peak contact force exceeds :data:`OVERLOAD_FACTOR` times the static wheel load (one message per call,
    naming the worst row): no track geometry in service gives that, so an input is most likely in the wrong unit.
    """
    check_choice("on_overload", on_overload, ON_OVERLOAD)
    with _side_by_side.python_side():  # (see simulate_pass_batches)
        results = _simulate_passes(tracks, vehicle, speed, irregularities, dt=dt, contact=contact, start=start,
                                   x_start=x_start, x_end=x_end, window_bays=window_bays, window_ends=window_ends,
                                   window_decay_lengths=window_decay_lengths,
                                   sleeper_force_measure=sleeper_force_measure,
                                   support_settlement=support_settlement, backend=backend, device=device)
    if on_overload != "ignore":
        check_overload(results, on_overload)
        check_static_deflection(_as_tracks(tracks), results, on_overload)
    return results


def static_deflection_note(tracks: Sequence[Track], load: float) -> str | None:
    """Why ``tracks`` (one, or one per row) are no ballasted track, or None: the rail would deflect statically by
    more than :data:`MAX_STATIC_DEFLECTION_M` under the wheel ``load`` [N] (``Track.winkler_deflection``), as a
    track entered in kN/m does; the worst row is named."""
    deflection = [t.winkler_deflection(load) for t in tracks]
    worst = int(np.argmax(deflection))
    if deflection[worst] <= MAX_STATIC_DEFLECTION_M:
        return None
    t = tracks[worst]
    where = f"row {worst} of {len(tracks)}" if len(tracks) > 1 else "the track"
    return (f"{where}: the rail would deflect {deflection[worst] * 1e3:.4g} mm under the static wheel load of "
            f"{load / 1e3:.4g} kN (a beam on the track's mean supports: pads {float(np.mean(t.pad_stiffness)):.3g} "
            f"N/m, ballast {float(np.mean(t.ballast_stiffness)):.3g} N/m, EI {t.rail_bending_stiffness:.3g} N·m²), "
            f"where a ballasted track deflects 0.5-3 mm. Check the units (stiffness N/m, not kN/m; EI N·m²)")


def check_static_deflection(tracks: Sequence[Track], results: Sequence[PassResult],
                            on_overload: str = "warn") -> str | None:
    """Warn or raise (``on_overload``, as :func:`check_overload`) where :func:`static_deflection_note` finds a row's
    track deflecting too far under its largest static wheel load: a track entered in kN/m, which a pass kept clear
    of the rail's ends shows by no overload. Returns the message, or None."""
    load = max(float(np.max(r.static_wheel_load)) for r in results)
    note = static_deflection_note(tracks, load)
    if note is None:
        return None
    msg = f"{note}; pass on_overload='ignore' where such a track is meant"
    if on_overload == "raise":
        raise OverloadError(msg)
    import warnings

    warnings.warn(msg, OverloadWarning, stacklevel=caller_stacklevel())
    return msg


def check_overload(results: Sequence[PassResult], on_overload: str = "warn") -> str | None:
    """Warn or raise (``on_overload``) when a row's peak contact force exceeds :data:`OVERLOAD_FACTOR` times its
    static wheel load; one message for the batch, naming the worst row. Returns the message, or None."""
    factors = np.array([float(np.max(r.contact_force.max(axis=0) / r.static_wheel_load)) if len(r.time) else 0.0
                        for r in results])
    over = np.flatnonzero(factors > OVERLOAD_FACTOR)
    if over.size == 0:
        return None
    worst = int(over[np.argmax(factors[over])])
    r = results[worst]
    where = f"row {worst} of {len(results)}" + (f" (and {over.size - 1} more)" if over.size > 1 else "")
    msg = (f"{where}: peak contact force {r.max_contact_force / 1e3:.4g} kN, {factors[worst]:.3g} times the static "
           f"wheel load {float(np.max(r.static_wheel_load)) / 1e3:.4g} kN: track geometry in service stays below "
           f"about 2 times. Check the units (stiffness N/m, damping N·s/m, mass kg, speed m/s, levels m) and the "
           f"irregularity's size; pass on_overload='ignore' where such a force is meant (an impact study)")
    if on_overload == "raise":
        raise OverloadError(msg)
    import warnings

    warnings.warn(msg, OverloadWarning, stacklevel=caller_stacklevel())
    return msg


def _simulate_passes(tracks, vehicle, speed, irregularities, *, dt, contact, start, x_start, x_end, window_bays,
                     window_ends, window_decay_lengths, sleeper_force_measure, support_settlement, backend,
                     device) -> list[PassResult]:
    """:func:`simulate_passes`, its Python side held."""
    tracks = _as_tracks(tracks)
    check_choice("backend", backend, BACKENDS)
    system, law, speed = _vehicle_system(vehicle), _contact_law(contact), check_speed(speed)
    auto = isinstance(dt, str)
    check_dt_option(dt)
    check_choice("sleeper_force_measure", sleeper_force_measure, SLEEPER_FORCE_MEASURES)
    check_choice("start", start, START_OPTIONS)
    dt = auto_time_step(tracks[0], system, speed, law) if auto else check_time_step(dt, contact_period(system, law))
    check_window_bays(window_bays)
    check_window_ends(window_ends)
    window_decay_lengths = check_scalar("window_decay_lengths", window_decay_lengths, low=0.5, high=100.0)
    if window_ends != "rest" and backend != "numba":
        raise ValueError(f"window_ends={window_ends!r} needs backend='numba' (the {backend} backend has clamped ends)")
    tracks, irr_rows = _batch_rows(tracks, irregularities)
    settlement = None if support_settlement is None else _settlement_rows(support_settlement, len(tracks), tracks[0])
    margins = _row_margins(tracks, window_bays, window_decay_lengths)
    x_start, x_end = _pass_range(tracks[0], system, start, margins, x_start, x_end)
    _warn_unloaded(system, x_start, x_end)
    options = dict(contact=law, start=start, x_start=x_start, x_end=x_end, sleeper_force_measure=sleeper_force_measure,
                   backend=backend, device=device, window_ends=window_ends)
    groups: dict = {}
    for b, margin in enumerate(margins):
        groups.setdefault(margin, []).append(b)
    if len(groups) > 1:  # rows that need different windows run as batches of their own
        results: list = [None] * len(tracks)
        for margin, rows in groups.items():
            _rerun_rows(results, rows, tracks, irr_rows, settlement, system, speed,
                        dt="auto" if auto else dt, window_bays=margin, **options)
        return results
    batch = _Batch(tracks, irr_rows, settlement, system, law, speed, dt, start, x_start, x_end, margins[0],
                   sleeper_force_measure, backend=backend, device=device, ends=window_ends)
    results, lost = _simulate_batch(batch)
    if auto and dt > DT_REFERENCE_S:
        # the contract covers passes that keep contact over a rail without kinks: the other rows (a wheel left the
        # rail, or the level changes slope within a step) run at the reference step
        unresolved = sorted(set(lost) | set(_kinked_rows(results, irr_rows)))
        if unresolved:
            _rerun_rows(results, unresolved, tracks, irr_rows, settlement, system, speed, dt=DT_REFERENCE_S,
                        window_bays=margins[0], **options)
    return results


def _kinked_rows(results: list[PassResult], irregularities: list) -> list[int]:
    """The rows whose rail level under the wheels changes slope by more than the auto step resolves
    (:data:`~trackenv.physics.timestep.MAX_SLOPE_CHANGE_PER_STEP`; the level after the start, which the static
    sag of settled supports shifts at t = 0). Only a level given as a function can kink: an array is a natural
    cubic spline between its points, smooth in slope and curvature (the envs' rows, which skip the check)."""
    return [b for b, (res, irr) in enumerate(zip(results, irregularities, strict=True)) if callable(irr)
            and slope_change_per_step(res.wheel_position[1:], res.irregularity[1:]) > MAX_SLOPE_CHANGE_PER_STEP]


@dataclass(frozen=True, eq=False)
class _Batch:
    """A validated batch: each row's track, irregularity and settled supports (or None), and the pass every row
    runs: vehicle, contact law, speed [m/s], dt [s], start, leading-axle range [m], window margin in bays (None:
    the whole track), the sleeper-force measure and the window's ends (``window_ends``)."""

    tracks: list[Track]
    irregularities: list
    settlement: np.ndarray | None
    system: VehicleSystem
    law: HertzContact | LinearContact
    speed: float
    dt: float
    start: str
    x_start: float
    x_end: float
    margin: int | None
    measure: str
    keep_factors: bool = True  # a one-row pass keeps its window factors for the next pass over its track
    backend: str = "numba"  # the integration's backend (BACKENDS) and, for torch, its device
    device: object = None
    ends: str = "rest"  # what the windows' ends stand on (window_ends.WINDOW_ENDS)

    @property
    def margin_bays(self) -> int:
        return self.tracks[0].n_sleepers if self.margin is None else int(self.margin)


@dataclass(frozen=True, eq=False)
class _State:
    """A batch's state at the start, one row per row: track u, v, a (rows, n_dof), vehicle q, qd, qdd (rows, nv),
    and the contact forces (rows, n_axles)."""

    u: np.ndarray
    v: np.ndarray
    a: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    force: np.ndarray


def _batch_rows(tracks: list[Track], irregularities) -> tuple[list[Track], list[Irregularity]]:
    """One track and one irregularity per row: a single track or irregularity is shared by every row."""
    if irregularities is None:
        irr_rows: list[Irregularity] = [None] * len(tracks)
    elif callable(irregularities) or (isinstance(irregularities, np.ndarray) and irregularities.ndim == 1):
        irr_rows = [irregularities]
    else:
        if not (isinstance(irregularities, (list, tuple)) or getattr(irregularities, "ndim", 0) >= 1):
            raise ValueError(f"irregularities must be None, an array, a callable or a list, got {irregularities!r}")
        irr_rows = list(irregularities)
    n_rows = max(len(tracks), len(irr_rows))
    if len(tracks) == 1:
        tracks = tracks * n_rows
    if len(irr_rows) == 1:
        irr_rows = irr_rows * n_rows
    if len(tracks) != n_rows or len(irr_rows) != n_rows:
        raise ValueError(f"irregularities has {len(irr_rows)} rows but there are {len(tracks)} tracks")
    return tracks, irr_rows


def _row_margins(tracks: list[Track], window_bays, decay_lengths: float) -> list[int | None]:
    """Each row's window margin in bays (None: the whole track): ``window_bays``, or with "auto" its track's own
    at ``decay_lengths`` decay lengths."""
    if isinstance(window_bays, str):
        return [window_margin(t, decay_lengths) for t in tracks]
    return [None if window_bays is None else int(window_bays)] * len(tracks)


def _pass_range(track: Track, system: VehicleSystem, start: str, margins: list, x_start, x_end) -> tuple[float, float]:
    """The leading axle's start and end [m], validated; the default start puts the whole vehicle on the rail, and
    for the steady start its windows inside the track as well (see :func:`_check_steady_start`)."""
    if system.span >= track.length:
        raise ValueError(f"vehicle (axle span {system.span:.2f} m) is longer than the track ({track.length:.2f} m)")
    if start == "steady":
        if any(m is None for m in margins):
            raise ValueError("start='steady' needs a moving window: window_bays must not be None (and 'auto' gives "
                             "None on track too soft for one: use start='static' there)")
        default = system.span + (max(margins) + 1.5) * track.sleeper_spacing  # half a bay clear of the limit
    else:
        default = system.span
    x_start = default if x_start is None else check_scalar("x_start", x_start, low=system.span, high=track.length)
    if x_end is None:
        return x_start, track.length
    return x_start, check_scalar("x_end", x_end, low=x_start, high=track.length, low_inclusive=False)


def _warn_unloaded(system: VehicleSystem, x_start: float, x_end: float) -> None:
    """Warn where the pass leaves a stretch of track between two axles that no wheel crosses: axle i runs from
    ``x_start`` − d_i to ``x_end`` − d_i (d_i its distance behind the leading axle), so two neighbouring axles
    further apart than the pass is long leave the track between them unloaded (a car on a track little longer
    than its span). Its sleeper forces are then the static track's, not a pass's."""
    d = np.sort(system.axle_offsets)
    run = x_end - x_start
    gaps = [(x_end - b, x_start - a) for a, b in zip(d[:-1], d[1:], strict=True) if b - a > run + 1e-9]
    if not gaps:
        return
    lo, hi = max(gaps, key=lambda g: g[1] - g[0])
    import warnings

    warnings.warn(f"the pass leaves {lo:.4g}-{hi:.4g} m of the track under no wheel: the leading axle runs "
                  f"{run:.4g} m (x_start {x_start:.4g} to x_end {x_end:.4g} m) while neighbouring axles are up to "
                  f"{float(np.diff(d).max()):.4g} m apart, so the sleeper forces there are the static track's. "
                  f"Use a track longer than the vehicle's span ({system.span:.4g} m) plus the stretch of interest",
                  UnloadedTrackWarning, stacklevel=caller_stacklevel())


def _rerun_rows(results: list, rows: list[int], tracks: list[Track], irr_rows: list, settlement, vehicle,
                speed: float, **options) -> None:
    """Simulate ``rows`` of a batch again as a batch of their own (other window or time step in ``options``)
    and put their results in place in ``results``; ``settlement``: the batch's settled supports or None."""
    again = simulate_passes([tracks[b] for b in rows], vehicle, speed, [irr_rows[b] for b in rows],
                            support_settlement=None if settlement is None else settlement[rows],
                            on_overload="ignore", **options)  # (the outer call checks the whole batch)
    for b, res in zip(rows, again):
        results[b] = res


@dataclass(frozen=True, eq=False)
class _Run:
    """What a batch's integration produced: the time grid and axle positions, each row's rail level under the
    wheels, the kernel's outputs and final state (its layout: chunks, ..., width), and the settled supports'
    static forces per row (rows, n_sleepers)."""

    time: np.ndarray
    x_axle: np.ndarray
    z_rows: list[np.ndarray]
    peaks: _step.Peaks
    final: _step.Rows
    width: int
    static_ballast: np.ndarray
    static_total: np.ndarray


def _simulate_batch(batch: _Batch) -> tuple[list[PassResult], list[int]]:
    """Integrate every row of ``batch``; its results, and the rows where a wheel lost contact."""
    run = _integrate(batch)
    n_rows = len(batch.tracks)
    after_start = run.peaks.force[:, 1:]  # (chunks, n_steps, n_axles, width)
    if after_start.min() > 0.0:  # every wheel kept contact (the usual case): one pass over the whole history
        return _results(batch, run), []
    lost = np.flatnonzero(after_start.min(axis=(1, 2)).reshape(-1)[:n_rows] <= 0.0).tolist()
    return _results(batch, run), lost


def _integrate(batch: _Batch) -> _Run:
    """The batch's pass through the kernel (:func:`_prepare`)."""
    run, arguments = _prepare(batch)
    if batch.backend == "torch":
        from . import torch_pass  # (torch is imported only by the passes that ask for it)

        torch_pass.run(*arguments, device=batch.device)
        return run
    from .kernels import announce_compile  # (kernels imports this module's helpers)

    announce_compile(arguments[2].u.shape[0] > 1, arguments[-1])
    with _side_by_side.kernel_outside(arguments[4]):  # (the store of kept factors it writes, or _NO_REUSE)
        _kernel.run(*arguments)
    return run


def _prepare(batch: _Batch) -> tuple[_Run, tuple]:
    """Rail levels, settled supports' statics and the start of the batch's pass, and the kernel's arguments; the
    run's outputs and final state are filled in place by the kernel."""
    t0, system = batch.tracks[0], batch.system
    n_rows = len(batch.tracks)
    # the time grid, checked before anything is allocated
    n_steps = check_time_steps(batch.x_end - batch.x_start, batch.speed, batch.dt, rows=n_rows, axles=system.n_axles)
    time = np.arange(n_steps + 1) * batch.dt
    x_lead = np.minimum(batch.x_start + batch.speed * time, t0.length)
    x_axle = x_lead[:, None] - system.axle_offsets[None, :]
    n_chunks, width = _chunking(n_rows)
    z_packed, z_all = _rail_levels(batch, x_axle, n_chunks, width)
    z_rows = z_all[:n_rows]
    start_points = [_point_load_vector(t0, x) for x in x_axle[0]]  # DOFs and weights of each axle at t = 0
    sag, static_ballast, static_total = _settled_statics(batch, start_points, z_rows)
    for z in z_all[n_rows:]:  # the padding rows copy the last row
        z[...] = z_rows[-1]
    cluster = _clusters(system.axle_offsets, 2 * (batch.margin_bays + 1) * t0.sleeper_spacing)
    state = _start_state(batch, x_axle[0], cluster, start_points, [z[0] for z in z_rows])
    arguments = _kernel_arguments(batch, state, x_axle, z_packed, sag, cluster, start_points, n_chunks, width)
    _, _, rows, peaks, _, _ = arguments
    return _Run(time, x_axle, z_rows, peaks, rows, width, static_ballast, static_total), arguments


def kernel_arguments() -> tuple:
    """The kernel's arguments (mesh, drive, rows, peaks, reuse) for half a metre of a wheelset's pass over the seed
    track: every pass gives its entry arguments of these types (see :mod:`trackenv.physics.kernels`)."""
    track = Track.seed()
    system = _vehicle_system(Wheelset.seed())
    batch = _Batch([track], [None], None, system, HertzContact(), 20.0, DT_REFERENCE_S, "static", 10.0, 10.5,
                   window_margin(track), "ballast", keep_factors=False)
    return _prepare(batch)[1][:5]


def _rail_levels(batch: _Batch, x_axle: np.ndarray, n_chunks: int, width: int) -> tuple[np.ndarray, list]:
    """Each row's rail level under each axle over the pass, allocated in the kernel's layout (chunks, n_steps + 1,
    n_axles, width) and seen through one view per row, padding rows included (no stacking or copying of time
    histories around the kernel)."""
    z_packed = np.zeros((n_chunks,) + x_axle.shape + (width,))
    rows = [_row(z_packed, b, width) for b in range(n_chunks * width)]
    for b, level in enumerate(_irregularity_levels(batch.irregularities, batch.tracks[0], x_axle, "irregularity")):
        if level is not None:
            rows[b][...] = level
    return z_packed, rows


def _settled_statics(batch: _Batch, start_points: list, z_rows: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rail's static sag over settled supports (rows, n_dof), which the kernel adds to the rail level under
    the wheels (and which is added here at t = 0), and the supports' static ballast and pad + ballast forces
    (rows, n_sleepers) that are added to the peak forces; zeros without settlement."""
    t0 = batch.tracks[0]
    n_rows, lay = len(batch.tracks), t0.dof_layout
    sag = np.zeros((n_rows, t0.n_dof))
    static_ballast = np.zeros((n_rows, t0.n_sleepers))
    static_total = np.zeros((n_rows, t0.n_sleepers))
    if batch.settlement is None:
        return sag, static_ballast, static_total
    g = batch.settlement
    ballast, pad = (np.stack([getattr(t, name) for t in batch.tracks]) for name in ("ballast_stiffness",
                                                                                    "pad_stiffness"))
    f = np.zeros((n_rows, t0.n_dof))
    f[:, lay.sleeper] = ballast * g
    for b, t in enumerate(batch.tracks):  # one solve per row: each row's own factor
        u0, info = _PBTRS(_stiffness_factor(t), f[b], lower=1)
        _lapack_info("pbtrs", info)
        sag[b] = u0
        z_rows[b][0] += [shp @ u0[dofs] for dofs, shp in start_points]
    us, uw = sag[:, lay.sleeper], sag[:, lay.node_w[lay.sleeper_node]]
    static_ballast[...] = ballast * (us - g)
    static_total[...] = static_ballast + pad * (uw - us)
    return sag, static_ballast, static_total


def _start_state(batch: _Batch, x0: np.ndarray, cluster: np.ndarray, start_points: list, z0: list) -> _State:
    """The state every row starts from (``batch.start``); ``x0``: the axles' positions at t = 0, ``z0``: each
    row's rail level under them."""
    if batch.start == "steady":
        return _steady_start(batch, x0, z0)
    n_rows, t0, system = len(batch.tracks), batch.tracks[0], batch.system
    state = _State(*(np.zeros((n_rows, n)) for n in (t0.n_dof,) * 3 + (system.n_dof,) * 3 + (system.n_axles,)))
    if batch.start == "rest":
        for b in range(n_rows):
            state.q[b] = system.static_displacements(z0[b])
            state.qdd[b] = np.linalg.solve(system.mass, system.force - system.stiffness @ state.q[b])
        return state
    windows = tuple(_window_dofs(t0, x0[cluster == c], batch.margin_bays) for c in range(int(cluster.max()) + 1))
    if batch.ends == "static":  # the rows' static ends as one batch (each row's start reads its outside stiffness)
        _track_ends(batch.tracks)
    for b in range(n_rows):
        state.u[b], state.q[b], state.force[b] = _static_start(batch, batch.tracks[b], windows, start_points, z0[b])
    return state


def _static_start(batch: _Batch, track: Track, windows: tuple, start_points: list, z0: np.ndarray):
    """Static equilibrium of the vehicle on one row's track at the start, the track outside the windows at rest:
    the loads on a compliant, uneven rail by a few fixed-point sweeps. Returns the track's and the vehicle's
    displacements and the wheel loads."""
    system, law = batch.system, batch.law
    loads = system.static_wheel_loads.copy()
    factors = _track_window_factors(track, windows, batch.ends)
    for _ in range(4):
        f = np.zeros(track.n_dof)
        for (dofs, shp), p in zip(start_points, loads):
            f[dofs] += shp * p
        u = _static_in_windows(factors, f)
        w = np.array([shp @ u[dofs] for dofs, shp in start_points])
        q = system.static_displacements(w + z0 + law.compression(loads))
        new = system.force[system.wheel_dofs] - system.stiffness[system.wheel_dofs] @ q
        if np.all(np.abs(new - loads) <= 1e-9 + 1e-12 * np.abs(loads)):  # np.allclose's test
            break
        loads = new
    return u, q, loads


def _kernel_arguments(batch: _Batch, state: _State, x_axle: np.ndarray, z_packed: np.ndarray, sag: np.ndarray,
                      cluster: np.ndarray, start_points: list, n_chunks: int, width: int) -> tuple:
    """The batch packed for the kernel (its layout: chunks, ..., width; padding rows copy the last row): the
    arguments of :func:`_kernel.run`, (mesh, drive, rows, peaks, reuse, width)."""
    t0, system, lay = batch.tracks[0], batch.system, batch.tracks[0].dof_layout
    consts = newmark_constants(batch.dt)
    track = _track_rows(batch, n_chunks, width)
    ws, ds = lay.node_w[lay.sleeper_node], lay.sleeper
    bal_k, bal_c, pad_k = track.ballast_stiffness, track.ballast_damping, track.pad_stiffness
    peak_ballast = bal_k * state.u[:, ds]
    if batch.start == "steady":  # the supports move at the start: their dampers carry force too
        peak_ballast = peak_ballast + bal_c * state.v[:, ds]
    peak_total = peak_ballast + pad_k * (state.u[:, ws] - state.u[:, ds])
    rail0 = np.stack([[shp @ u[dofs] for dofs, shp in start_points] for u in state.u])
    pack = functools.partial(_pack, n_chunks=n_chunks, width=width)
    history = functools.partial(_packed_history, n_steps=x_axle.shape[0] - 1, n_chunks=n_chunks, width=width)
    mesh = _step.Mesh(track.node_w, track.sleeper_dof, track.sleeper_node, float(t0.element_length),
                      int(t0.elements_per_bay), int(t0.n_sleepers), batch.margin_bays, track.rail_mass)
    drive = _step.Drive(np.ascontiguousarray(x_axle), consts, int(batch.law.code), float(batch.law.parameter),
                        np.array(system.mass, dtype=float), np.array(system.damping, dtype=float),
                        np.linalg.inv(system.stiffness + consts[0] * system.mass + consts[1] * system.damping),
                        system.force.astype(float), system.wheel_dofs.astype(np.int64), cluster,
                        int(cluster.max()) + 1)
    u, v, a, q, qd, qdd = (pack(x) for x in (state.u, state.v, state.a, state.q, state.qd, state.qdd))
    rows = _step.Rows(track.mass_diag, track.keff, track.pad_k, track.pad_c, track.bal_k, track.bal_c, z_packed,
                      pack(sag), u, v, a, q, qd, qdd, track.ends)
    peaks = _step.Peaks(history(state.force), history(rail0), history(state.q[:, system.wheel_dofs]),
                        pack(peak_ballast), pack(peak_total))
    # one row: its window factors and bay columns are kept for the next pass (batches keep nothing)
    one_row = n_chunks == 1 and width == 1
    keep = one_row and batch.keep_factors
    reuse = (_one_row_reuse(t0, batch.dt, system.axle_offsets, cluster, batch.margin_bays, batch.ends) if keep
             else _NO_REUSE)
    if _side_by_side.store_in_use(reuse):  # a pass beside this one writes it now: this one keeps nothing
        reuse = _NO_REUSE
    return mesh, drive, rows, peaks, reuse, width


@dataclass(frozen=True, eq=False)
class _TrackRows:
    """What a batch's tracks give the kernel, whatever runs over them: the rows' mass diagonal, effective stiffness
    K + a0 M + a1 C, pad and ballast stiffness and damping and window ends in the kernel's layout (the fields of
    :class:`_step.Rows` of these names); the DOF layout's node_w, sleeper and sleeper_node (int64) and the rail's
    mass diagonals (those of :class:`_step.Mesh`); and the supports row by row (rows, n_sleepers) that the start's
    peak forces read."""

    mass_diag: np.ndarray
    keff: np.ndarray
    pad_k: np.ndarray
    pad_c: np.ndarray
    bal_k: np.ndarray
    bal_c: np.ndarray
    ends: np.ndarray
    node_w: np.ndarray
    sleeper_dof: np.ndarray
    sleeper_node: np.ndarray
    rail_mass: np.ndarray
    pad_stiffness: np.ndarray
    ballast_stiffness: np.ndarray
    ballast_damping: np.ndarray


_TRACK_ROWS_CACHE_SIZE = 8  # batches of tracks kept (~0.3 MB for a line's 12 segments, ~7 MB for 256 rows)
_TRACK_ROWS: collections.OrderedDict = collections.OrderedDict()  # (tracks, dt, ends, layout) -> _TrackRows


def _track_rows(batch: _Batch, n_chunks: int, width: int) -> _TrackRows:
    """:class:`_TrackRows` of ``batch`` in the layout (``n_chunks``, ``width``), kept per sequence of track objects,
    dt, window ends and layout (the most recent :data:`_TRACK_ROWS_CACHE_SIZE`): an env's passes run over the same
    model tracks step after step, and the kernel only reads these arrays (the torch backend, which hands them to
    torch, gets its own)."""
    if batch.backend != "numba":
        return _build_track_rows(batch, n_chunks, width)
    key = (tuple(batch.tracks), batch.dt, batch.ends, n_chunks, width)
    return _kept(_TRACK_ROWS, [key], _TRACK_ROWS_CACHE_SIZE,
                 lambda missing: [_build_track_rows(batch, n_chunks, width)])[0]


def _build_track_rows(batch: _Batch, n_chunks: int, width: int) -> _TrackRows:
    """:class:`_TrackRows` of ``batch``: its tracks' rows (:func:`_track_row_arrays`) stacked and packed."""
    t0, lay = batch.tracks[0], batch.tracks[0].dof_layout
    stacked = np.stack(_track_row_arrays(batch.tracks, batch.dt, batch.ends))  # (rows, the fields' sizes summed)
    fields = _row_fields(t0.n_sleepers, t0.n_dof, int(lay.sleeper[1] - lay.sleeper[0]), batch.ends)
    mass_diag, keff, pad_k, pad_c, bal_k, bal_c, ends = (stacked[:, a:b].reshape((-1,) + s) for a, b, s in fields)
    pack = functools.partial(_pack, n_chunks=n_chunks, width=width)
    node_w, sleeper, sleeper_node, rail_mass = _mesh_arrays(t0.n_sleepers, t0.elements_per_bay, t0.element_length,
                                                           t0.rail_bending_stiffness, t0.rail_mass)
    return _TrackRows(pack(mass_diag), pack(keff), pack(pad_k), pack(pad_c), pack(bal_k), pack(bal_c), pack(ends),
                      node_w, sleeper, sleeper_node, rail_mass, pad_k, bal_k, bal_c)


@functools.lru_cache(maxsize=16)
def _mesh_arrays(n_sleepers: int, epb: int, element_length: float, ei: float,
                 mass: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The mesh's fields of :class:`_TrackRows` (node_w, sleeper, sleeper_node as int64, the rail's mass
    diagonals), built once per mesh and shared by its passes, which only read them."""
    from .track import DofLayout

    lay = DofLayout.build(n_sleepers, epb)
    return (lay.node_w.astype(np.int64), lay.sleeper.astype(np.int64), lay.sleeper_node.astype(np.int64),
            _mass_diagonals(_rail_bands(lay, element_length, ei, mass, copy=False)[0]))


@functools.lru_cache(maxsize=16)
def _row_fields(n: int, n_dof: int, bay_dofs: int, ends: str) -> list[tuple[int, int, tuple[int, ...]]]:
    """Where each field of a kept row (:func:`_track_row_arrays`) lies in it, for a mesh of ``n`` sleepers,
    ``n_dof`` DOFs and ``bay_dofs`` DOFs a bay, and window ends ``ends``: (start, stop, shape) of the mass
    diagonal, the effective stiffness, the pad and ballast stiffness and damping and the window ends, in order."""
    end_columns = 6 if ends == "rest" else 12 + 2 * bay_dofs
    shapes = [(n_dof,), (n_dof, HALF_BANDWIDTH + 1), (n,), (n,), (n,), (n,), (n, end_columns)]
    stops = np.cumsum([math.prod(shape) for shape in shapes]).tolist()
    return [(stop - math.prod(shape), stop, shape) for stop, shape in zip(stops, shapes, strict=True)]


_ROW_ARRAYS_CACHE_SIZE = 512  # tracks whose rows are kept (~25 kB each on a line's segment: 32 lines of 12 fit)
_ROW_ARRAYS: collections.OrderedDict = collections.OrderedDict()  # (track, dt, ends) -> its row, least recent first


def _track_row_arrays(tracks: Sequence[Track], dt: float, ends: str) -> list[np.ndarray]:
    """Each track's row of :class:`_TrackRows` (mass diagonal, effective stiffness K + a0 M + a1 C, pad and ballast
    stiffness and damping, window ends) as one flat, read-only array (:func:`_row_fields` says where each lies),
    kept per track object, dt and window ends (the most recent :data:`_ROW_ARRAYS_CACHE_SIZE`): a batch whose
    composition changes from pass to pass (pass reuse computes only some segments) assembles its rows from those
    kept, one stack for all the fields; the tracks missing are built as one batch (:func:`batched_bands`,
    :func:`_window_ends`: element by element, the same numbers in any batch)."""
    return _kept(_ROW_ARRAYS, [(t, dt, ends) for t in tracks], _ROW_ARRAYS_CACHE_SIZE,
                 lambda missing: _build_row_arrays([key[0] for key in missing], dt, ends))


def _build_row_arrays(tracks: list[Track], dt: float, ends: str) -> list[np.ndarray]:
    """:func:`_track_row_arrays` of ``tracks``, assembled as one batch."""
    consts = newmark_constants(dt)
    mb, cb, kb = batched_bands(tracks)
    fields = (mb[:, :, 0], kb + consts[0] * mb + consts[1] * cb,
              *(np.stack([getattr(t, name) for t in tracks]) for name in ("pad_stiffness", "pad_damping",
                                                                           "ballast_stiffness", "ballast_damping")),
              _window_ends(tracks, ends, consts[1]))
    rows = np.concatenate([field.reshape(len(tracks), -1) for field in fields], axis=1)
    return [row.copy() for row in rows]  # each its own array: a row kept does not keep its batch's alive


def _results(batch: _Batch, run: _Run) -> list[PassResult]:
    """One PassResult per row, its time histories views into the kernel's outputs."""
    n_rows, t0, peaks = len(batch.tracks), batch.tracks[0], run.peaks
    peak_ballast = _unpack(peaks.ballast, n_rows) + run.static_ballast
    peak_total = _unpack(peaks.total, n_rows) + run.static_total
    bay_force = _bay_peaks(peaks.force, run.x_axle, t0.sleeper_positions)
    row = functools.partial(_row, width=run.width)
    return [
        PassResult(
            time=run.time,
            wheel_position=run.x_axle,
            contact_force=row(peaks.force, b),
            rail_displacement=row(peaks.rail, b),
            wheel_displacement=row(peaks.wheel, b),
            irregularity=run.z_rows[b],
            sleeper_force=peak_ballast[b] if batch.measure == "ballast" else peak_total[b],
            ballast_force=peak_ballast[b],
            pad_plus_ballast_force=peak_total[b],
            static_wheel_load=batch.system.static_wheel_loads.copy(),
            sleeper_positions=t0.sleeper_positions,
            speed=batch.speed,
            dt=batch.dt,
            bay_contact_force=row(bay_force, b),
        )
        for b in range(n_rows)
    ]


# ------------------------------------------------------------------------------------------ the steady start
@dataclass(frozen=True, eq=False)
class _SteadyState(_State):
    """The steady state of one track entry: a :class:`_State` of one row (the track's u, v, a on a uniform track
    (n_dof,), the vehicle's q, qd, qdd on a level rail, the contact forces (n_axles,)) with the leading axle at
    ``x_lead`` [m]."""

    x_lead: float


_STEADY_STATES: collections.OrderedDict = collections.OrderedDict()  # key -> _SteadyState, least recent first


def _steady_start(batch: _Batch, x0: np.ndarray, z0: list) -> _State:
    """Each row's steady state (:func:`_steady_states`) moved onto its track: the track's state shifted by whole
    bays to the axles' position, the vehicle's displaced statically by the rail level under its wheels."""
    t0, system = batch.tracks[0], batch.system
    _check_steady_start(t0, x0, batch.margin_bays)
    steady = _steady_states(batch)
    n_rows, lay = len(batch.tracks), t0.dof_layout
    bay_dofs = int(lay.sleeper[1] - lay.sleeper[0])
    state = _State(*(np.zeros((n_rows, n)) for n in (t0.n_dof,) * 3 + (system.n_dof,) * 3 + (system.n_axles,)))
    level = system.static_displacements(np.zeros(system.n_axles))
    for b, s in enumerate(steady):
        shift = int(round((s.x_lead - batch.x_start) / t0.sleeper_spacing)) * bay_dofs  # DOF i here is i + shift there
        lo, hi = max(0, -shift), min(t0.n_dof, s.u.size - shift)
        for mine, theirs in ((state.u, s.u), (state.v, s.v), (state.a, s.a)):
            mine[b, lo:hi] = theirs[lo + shift : hi + shift]
        state.q[b] = s.q + (system.static_displacements(z0[b]) - level)
        state.qd[b], state.qdd[b], state.force[b] = s.qd, s.qdd, s.force
    return state


STEADY_LEAD_BAYS = 3  # bays a steady start's leading axle runs before the evaluated track (0.03 % from converged)


def steady_approach_sleepers(tracks: Track | Sequence[Track], vehicle, lead_bays: float = STEADY_LEAD_BAYS,
                             decay_lengths: float = WINDOW_DECAY_LENGTHS) -> int:
    """Sleepers of approach to add before an evaluated track (copies of its first sleeper, as
    ``Track.extended``) for passes with ``start="steady"`` at their default ``x_start``: the vehicle's span, the
    window behind its trailing axle (:func:`window_margin` + 1.5 bays) and ``lead_bays`` bays that the leading
    axle runs before the evaluated track, so that the first evaluated sleeper's peak force is that of a converged
    approach. With the default lead the peak forces are within 0.03 % of 40 sleepers of approach on the cases of
    ``tests/physics/test_steady_start.py`` (today's 10 sleepers from static equilibrium: up to 0.65 %, and 5.9 %
    at 200 km/h). For a batch, the most its tracks need; the model track also needs 4 sleepers or more after the
    evaluated track (the window's margin is then the one computed here). ``decay_lengths``: the window's margin
    in decay lengths, as the passes' ``window_decay_lengths``."""
    tracks = _as_tracks(tracks)
    lead = check_scalar("lead_bays", lead_bays, low=0.0, high=1000.0)
    margins = [window_margin(t.extended(20, 20), decay_lengths) for t in tracks]
    widest = max((m for m in margins if m is not None), default=None)
    if widest is None or None in margins:
        raise ValueError("track too soft for a moving window: the steady start needs one (use start='static')")
    span = _vehicle_system(vehicle).span
    return math.ceil(span / tracks[0].sleeper_spacing + widest + 1.5 + lead - 1e-9)


def _check_steady_start(track: Track, x0: np.ndarray, margin: int) -> None:
    """The steady start moves a state computed on a longer, uniform track onto this one: every window must lie
    inside the track at the start, clear of its free rail ends."""
    elements = np.clip((x0 / track.element_length).astype(int), 0, track.n_nodes - 2)
    bays = elements // track.elements_per_bay
    if bays.min() - margin < 1 or bays.max() + 2 + margin > track.n_sleepers - 1:
        raise ValueError(
            f"start='steady' needs the windows ({margin} bays either side of the axles) inside the track at the "
            f"start: x_start must be at least the vehicle's span + {margin + 1} bays, and the track "
            f"{margin + 3} bays longer than that"
        )


def _steady_keys(batch: _Batch) -> list[tuple]:
    """What each row's steady state depends on: its entry's supports, the rail and mesh, the vehicle, the contact
    law, speed, dt, the window and its ends, where the leading axle stands in its bay at the start, and the
    backend. All but the entry are the batch's (its rows share the rail and mesh), built once."""
    t0, system = batch.tracks[0], batch.system
    rail = (t0.sleeper_spacing, t0.rail_bending_stiffness, t0.rail_mass, t0.elements_per_bay)
    vehicle = tuple(np.asarray(x).tobytes() for x in (system.mass, system.damping, system.stiffness, system.force,
                                                       system.wheel_dofs, system.axle_offsets))
    phase = batch.x_start - math.floor(batch.x_start / t0.sleeper_spacing) * t0.sleeper_spacing
    shared = (rail, vehicle, (batch.law.code, batch.law.parameter), batch.speed, batch.dt, batch.margin, phase,
              batch.backend, batch.ends)  # (the backends round differently: each keeps its own)
    return [(tuple(float(getattr(t, name)[0]) for name in _SUPPORT_FIELDS),) + shared for t in batch.tracks]


_SUPPORT_FIELDS = ("pad_stiffness", "pad_damping", "sleeper_mass", "ballast_stiffness", "ballast_damping")


def _steady_states(batch: _Batch) -> list[_SteadyState]:
    """Each row's steady state, computed once per key (:func:`_steady_keys`) and kept.

    The steady state is the periodic response of the vehicle running over a track that continues the row's first
    sleeper for ever. It is found by integrating: the vehicle starts in static equilibrium on a uniform track of
    the entry's supports, clear of its ends, and runs ``STEADY_RUN_BAYS`` bays (with the row's window, dt and
    contact law), ending with its leading axle where the row's pass starts in its bay. The keys missing are
    integrated as one batch."""
    keys = _steady_keys(batch)
    track_of = dict(zip(keys, batch.tracks))  # a track of each key (any: its entry, all the run reads, is in it)
    return _kept(_STEADY_STATES, keys, _STEADY_CACHE_SIZE,
                 lambda missing: _integrate_steady(batch, [track_of[k] for k in missing]))


def _integrate_steady(batch: _Batch, tracks: list[Track]) -> list[_SteadyState]:
    """The steady runs of :func:`_steady_states` for the entries of ``tracks``, as one batch."""
    t0, system = batch.tracks[0], batch.system
    s, margin = t0.sleeper_spacing, batch.margin_bays
    n_steps = math.ceil(STEADY_RUN_BAYS * s / (batch.speed * batch.dt))
    travel = batch.speed * (n_steps * batch.dt)
    # the run ends where the pass starts in its bay, K bays on, with the start's windows clear of the rail's end
    bays_on = math.ceil((system.span + (margin + 2) * s + travel - batch.x_start) / s)
    x_start = batch.x_start + bays_on * s - travel
    n_sleepers = int((x_start + travel) / s) + margin + 4
    scalars = (s, t0.rail_bending_stiffness, t0.rail_mass, t0.elements_per_bay)
    uniform = _uniform_tracks([(n_sleepers, tuple(float(getattr(t, name)[0]) for name in _SUPPORT_FIELDS), scalars)
                               for t in tracks])
    runs = _Batch(uniform, [None] * len(uniform), None, system, batch.law, batch.speed, batch.dt, "static",
                  x_start, x_start + batch.speed * (n_steps * batch.dt), margin, "ballast", keep_factors=False,
                  backend=batch.backend, device=batch.device, ends=batch.ends)
    run = _integrate(runs)
    n = len(uniform)
    u, v, a, q, qd, qdd = (_unpack(x, n) for x in (run.final.u, run.final.v, run.final.a, run.final.q,
                                                    run.final.qd, run.final.qdd))
    force = _unpack(run.peaks.force[:, -1], n)
    x_lead = float(run.x_axle[-1, 0] + system.axle_offsets[0])
    return [_SteadyState(u[b], v[b], a[b], q[b], qd[b], qdd[b], force[b], x_lead) for b in range(n)]


_UNIFORM_CACHE_SIZE = 256  # uniform tracks kept (a line's entries, run over by each of its vehicle types)
_UNIFORM: collections.OrderedDict = collections.OrderedDict()  # (n_sleepers, supports, rail) -> its Track


def _uniform_tracks(keys: list[tuple]) -> list[Track]:
    """The uniform tracks of the steady runs (:func:`_integrate_steady`), one per key (n_sleepers, the supports of
    :data:`_SUPPORT_FIELDS`, (spacing, EI, rail mass, elements per bay)), kept as objects (the most recent
    :data:`_UNIFORM_CACHE_SIZE`): another vehicle's steady run over the same entries finds the same tracks, and
    with them their static ends and kept rows (the per-track caches), instead of building equal tracks anew."""
    return _kept(_UNIFORM, keys, _UNIFORM_CACHE_SIZE, lambda missing: [_uniform_track(*key) for key in missing])


def _uniform_track(n_sleepers: int, supports: tuple, rail: tuple) -> Track:
    spacing, ei, rail_mass, epb = rail
    return Track.uniform(n_sleepers, **dict(zip(_SUPPORT_FIELDS, supports, strict=True)), sleeper_spacing=spacing,
                         rail_bending_stiffness=ei, rail_mass=rail_mass, elements_per_bay=epb)


def simulate_pass(track: Track, vehicle, speed: float, irregularity: Irregularity = None, **options) -> PassResult:
    """One vehicle pass over one track: :func:`simulate_passes` with a batch of one. See there for options."""
    if not isinstance(track, Track):
        raise ValueError(f"track must be a Track, got {type(track).__name__}")
    if irregularity is not None and not callable(irregularity):
        arr = check_array("irregularity", irregularity)
        if arr.ndim != 1:
            raise ValueError(f"irregularity must be one profile (1-D), got shape {arr.shape}")
        return simulate_passes(track, vehicle, speed, [arr], **options)[0]
    return simulate_passes(track, vehicle, speed, None if irregularity is None else [irregularity], **options)[0]


def simulate_pass_batches(batches: Sequence[dict]) -> list[list[PassResult]]:
    """``[simulate_passes(**b) for b in batches]`` for independent batches (e.g. one per vehicle type or speed),
    those of a few rows run side by side on the cores (:mod:`trackenv.physics._side_by_side`): each one's results
    are those of its call alone, bit for bit. A batch is the keyword arguments of :func:`simulate_passes`."""
    import numba

    def rows(b: dict) -> int:
        return len(_batch_rows(_as_tracks(b["tracks"]), b.get("irregularities"))[0])

    threads = numba.get_num_threads() if all(b.get("backend", "numba") == "numba" for b in batches) else 1
    return _side_by_side.run_side_by_side(batches, lambda b: simulate_passes(**b), rows, threads)


KERNEL_ENTRIES = tuple(_kernel._RUNNERS)
"""The kernel's compiled entries, as (runs chunks in parallel, rows per chunk) pairs."""


def warm_kernel(entries=KERNEL_ENTRIES) -> None:
    """Compile now, or load from numba's on-disk cache, the kernel's ``entries`` (pairs of
    :data:`KERNEL_ENTRIES`); parallel ones only where numba may run two threads. Processes that warm different
    widths at once share the cache. :func:`trackenv.physics.kernels.compile_kernels` does the same by width, with
    progress."""
    from .kernels import KernelEntry, build_entries, kernel_entries

    unknown = [e for e in entries if e not in KERNEL_ENTRIES]
    if unknown:
        raise ValueError(f"entries must be among {KERNEL_ENTRIES}, got {unknown}")
    reachable = kernel_entries()
    build_entries([KernelEntry(p, w) for p, w in entries if KernelEntry(p, w) in reachable], load=True)
