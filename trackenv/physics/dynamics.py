"""One pass of a vehicle over the standing track, and the track's static and harmonic responses.

:func:`simulate_passes` is the one implementation of the time integration; it takes a leading batch axis (many
tracks with the same mesh, many irregularities) and :func:`simulate_pass` is its batch of one. The integration
is implicit (Newmark average acceleration), the Hertz contact is solved every step, and the track is integrated
in a window that follows the axles (see :mod:`trackenv.physics._kernel`); ``window_bays=None`` integrates the
whole track.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.interpolate
import scipy.linalg

from . import _kernel, _step
from ._checks import check_array, check_instance, check_scalar, check_speed, check_time_steps
from .contact import HertzContact, LinearContact
from .timestep import DT_REFERENCE_S, auto_time_step, check_dt_option, check_time_step, contact_period
from .track import HALF_BANDWIDTH, Track, add_supports, hermite_shape, rail_bands
from .vehicle import Car, Train, VehicleSystem, Wheelset

Irregularity = np.ndarray | Callable[[np.ndarray], np.ndarray] | None
SLEEPER_FORCE_MEASURES = ("ballast", "pad_plus_ballast")


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


def _rail_bands(lay, element_length: float, ei: float, mass: float):
    """M, C, K of the bare rail (no supports), assembled once per mesh."""
    return tuple(
        b.copy() for b in _rail_bands_cached(lay.sleeper.size, int(lay.sleeper_node[1]), element_length, ei, mass)
    )


def batched_bands(tracks: Sequence[Track]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """M, C, K bands of every track, shape (batch, n_dof, 5): the rail is assembled once, the supports of all
    tracks added at once (each row is ``Track.banded_matrices``, the same numbers)."""
    t0 = tracks[0]
    lay = t0.dof_layout
    rail = _rail_bands(lay, t0.element_length, t0.rail_bending_stiffness, t0.rail_mass)
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
    since finding each position's interval and building the spline's system are shared (64 rows of the seed
    pass: 21 -> 5 ms). A row whose irregularity is the same object as an earlier row's shares its levels."""
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


@functools.lru_cache(maxsize=256)
def _track_window_factors(track: Track, windows: tuple) -> list[tuple[int, int, np.ndarray]]:
    """:func:`_window_factors` of ``track``'s stiffness, kept per track and windows."""
    return _window_factors(_track_stiffness(track), windows)


_NO_REUSE = _step.Reuse(np.zeros((0, 2 * _step.B + 3, 0)), np.zeros((0, 2), dtype=np.int64),
                          np.zeros((0, 2, 0)), np.zeros((0, 2), dtype=np.int64))
"""What a batch of several rows passes the kernel: nothing kept (see :class:`_step.Reuse`)."""


def _store_shapes(track: Track, m_cap: int) -> tuple[tuple[int, int, int], tuple[int, int, int]]:
    """Shapes of a store's factors and bay columns (:class:`_step.Reuse`) for ``track``, windows of up to
    ``m_cap`` DOFs."""
    n = track.n_sleepers
    return (n, 2 * _step.B + 3, m_cap), (n, 2 * (track.elements_per_bay + 1), m_cap)


@functools.lru_cache(maxsize=16)
def _kept_factors(track: Track, dt: float, m_cap: int) -> _step.Reuse:
    """The kernel's store of window factors and bay columns for one-row passes over ``track`` at ``dt`` (windows
    of up to ``m_cap`` DOFs), kept per track object, dt and window size: the effective stiffness K + a0 M + a1 C
    is the same in every such pass, so each window's factor and each bay's columns are computed once, by the
    same arithmetic, and read back in later passes (bit-identical; an episode's or the paper loop's passes run
    over one model track). ~1.5 MB for the env's 60 m track; 16 tracks at most, of up to 8 MB each."""
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
                   margin: int) -> _step.Reuse:
    """What a one-row pass over ``track`` keeps for the next one (:func:`_kept_factors`), or nothing
    (``_NO_REUSE``) where its windows or its store would exceed the bounds above."""
    m_cap = _window_dof_bound(track, axle_offsets, cluster, margin)
    store_bytes = 8 * sum(math.prod(shape) for shape in _store_shapes(track, m_cap))
    if m_cap > _REUSE_MAX_DOFS or store_bytes > _REUSE_MAX_BYTES:
        return _NO_REUSE
    return _kept_factors(track, float(dt), m_cap)


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


def window_margin(track: Track) -> int | None:
    """Sleeper bays of track the kernel integrates on each side of an axle group, from the track's decay length.

    The rail's deflection decays like e^{-βx}, β = (k_f / 4EI)^¼, with k_f the pad and ballast in series per
    spacing. β is taken on the softest stretch of WINDOW_AVERAGING_SLEEPERS supports (a transition's soft side,
    a run of voided sleepers; one voided sleeper barely widens the window) and the margin spans
    WINDOW_DECAY_LENGTHS decay lengths: on a sweep of pad and ballast stiffness 1e6-1e9 N/m, a voided sleeper
    and a transition zone this keeps the fast path within 1 % of the full model. Soft track needs more decay
    lengths than stiff (its dynamic response reaches further than the static one): below β·s =
    WINDOW_MIN_BETA_SPACING (1e6 N/m ballast: 2.6 % off with a 22-bay window on 60 m) the whole track is
    integrated. None (the whole track) there and where the window would cover half the track anyway."""
    k = track.support_stiffness
    n = min(WINDOW_AVERAGING_SLEEPERS, k.size)
    k_f = np.convolve(k, np.ones(n) / n, mode="valid").min() / track.sleeper_spacing
    beta = (k_f / (4.0 * track.rail_bending_stiffness)) ** 0.25
    if beta * track.sleeper_spacing < WINDOW_MIN_BETA_SPACING:
        return None
    margin = max(2, math.ceil(WINDOW_DECAY_LENGTHS / (beta * track.sleeper_spacing) - 1e-9))
    if 2 * margin + 2 >= track.n_sleepers / 2:
        return None
    return margin


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
    return np.ascontiguousarray(np.moveaxis(x, 1, -1))


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
    x = np.moveaxis(x, -1, 1)
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
    sleeper_force_measure: str = "ballast",
    support_settlement=None,
) -> list[PassResult]:
    """Run one vehicle pass over each of a batch of tracks and/or irregularities (one result per row).

    ``tracks``: one Track (shared by every row) or one per row; ``irregularities``: None, an array (n_rows,
    n_sleepers or n_nodes) of rail level [m] (downward positive), or a list of such rows or callables z(x).
    ``speed`` [m/s] > 0; ``dt`` [s] within the bounds of :mod:`trackenv.physics.timestep`, or "auto": the
    coarsest step that keeps peak forces within 0.5 % of the reference step (that module's contract; a row whose
    wheel loses contact is rerun at the reference step, so rows of one batch may differ in dt);
    ``start``: "static" (vehicle and track in static equilibrium at the start)
    or "rest" (the paper's transient: the vehicle is set on the unloaded track and drops in).
    ``x_start``/``x_end``: leading-axle positions [m] where the pass starts/ends (default: the whole vehicle
    on the rail from the first to the last sleeper). ``window_bays``: sleeper bays of track integrated ahead of
    the leading and behind the trailing axle of each axle group; "auto" (default): sized per row from the
    track's decay length (:func:`window_margin`; rows that need different windows run as separate groups, so a
    row's result does not depend on its batch); None: the whole track.
    ``support_settlement``: None or (n_rows, n_sleepers) permanent settlement of the ballast under each sleeper
    [m]: the base of each ballast spring is lowered by it and the rail bends over the settled supports. By
    superposition (the track is linear) the rail's static sag becomes the wheel's irregularity and the
    supports' static forces are added to the peak sleeper forces; a sleeper that settled more than its
    neighbours hangs partly in the rail and carries less (negative values: the linear model's tension where a
    real sleeper would lift off its ballast).
    """
    tracks = _as_tracks(tracks)
    sys_ = _vehicle_system(vehicle)
    law = _contact_law(contact)
    speed = check_speed(speed)
    auto = isinstance(dt, str)
    check_dt_option(dt)
    if sleeper_force_measure not in SLEEPER_FORCE_MEASURES:
        raise ValueError(
            f"sleeper_force_measure must be one of {SLEEPER_FORCE_MEASURES}, got {sleeper_force_measure!r}"
        )
    if start not in ("static", "rest"):
        raise ValueError(f"start must be 'static' or 'rest', got {start!r}")
    t0 = tracks[0]
    dt = auto_time_step(t0, sys_, speed, law) if auto else check_time_step(dt, contact_period(sys_, law))
    if sys_.span >= t0.length:
        raise ValueError(f"vehicle (axle span {sys_.span:.2f} m) is longer than the track ({t0.length:.2f} m)")
    x_start = sys_.span if x_start is None else check_scalar("x_start", x_start, low=sys_.span, high=t0.length)
    x_end = (
        t0.length if x_end is None else check_scalar("x_end", x_end, low=x_start, high=t0.length, low_inclusive=False)
    )
    check_window_bays(window_bays)

    # rows
    if irregularities is None:
        irr_rows: list[Irregularity] = [None] * len(tracks)
    elif callable(irregularities):
        irr_rows = [irregularities]
    else:
        if isinstance(irregularities, np.ndarray) and irregularities.ndim == 1:
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

    if isinstance(window_bays, str):  # "auto": each row's window from its own track
        margins = [window_margin(t) for t in tracks]
        groups: dict = {}
        for b, m in enumerate(margins):
            groups.setdefault(m, []).append(b)
        if len(groups) > 1:
            g_all = None if support_settlement is None else _settlement_rows(support_settlement, n_rows, t0)
            results: list = [None] * n_rows
            for m, idx in groups.items():
                _rerun_rows(results, idx, tracks, irr_rows, g_all, vehicle, speed, dt="auto" if auto else dt,
                            contact=contact, start=start, x_start=x_start, x_end=x_end, window_bays=m,
                            sleeper_force_measure=sleeper_force_measure)
            return results
        window_bays = margins[0]
    n_steps = check_time_steps(x_end - x_start, speed, dt, rows=n_rows, axles=sys_.n_axles)  # before allocating
    time = np.arange(n_steps + 1) * dt
    x_lead = np.minimum(x_start + speed * time, t0.length)
    x_axle = x_lead[:, None] - sys_.axle_offsets[None, :]
    # per-row arrays the kernel reads or writes over time are allocated in its layout (chunks, ..., width) and used
    # through one view per row (``_row``): no stacking, transposing or copying of time histories around the kernel
    n_chunks, width = _chunking(n_rows)
    row = functools.partial(_row, width=width)
    z_packed = np.zeros((n_chunks, n_steps + 1, sys_.n_axles, width))
    z_rows = [row(z_packed, b) for b in range(n_rows)]
    for b, level in enumerate(_irregularity_levels(irr_rows, t0, x_axle, "irregularity")):
        if level is not None:
            z_rows[b][...] = level
    # matrices
    consts = newmark_constants(dt)
    mb, cb, kb = batched_bands(tracks)
    keff = kb + consts[0] * mb + consts[1] * cb
    lay = t0.dof_layout
    static_ballast = np.zeros((n_rows, t0.n_sleepers))
    static_total = np.zeros((n_rows, t0.n_sleepers))
    sag = np.zeros((n_rows, t0.n_dof))  # static rail sag over settled supports (the kernel adds it to z)
    start_points = [_point_load_vector(t0, x) for x in x_axle[0]]  # DOFs and weights of each axle at t = 0
    if support_settlement is not None:
        g = settlement_rows = _settlement_rows(support_settlement, n_rows, t0)
        for b, t in enumerate(tracks):
            f = np.zeros(t0.n_dof)
            f[lay.sleeper] = t.ballast_stiffness * g[b]
            u0, info = _PBTRS(_stiffness_factor(t), f, lower=1)
            _lapack_info("pbtrs", info)
            sag[b] = u0
            z_rows[b][0] += [shp @ u0[dofs] for dofs, shp in start_points]
            us, uw = u0[lay.sleeper], u0[lay.node_w[lay.sleeper_node]]
            static_ballast[b] = t.ballast_stiffness * (us - g[b])
            static_total[b] = static_ballast[b] + t.pad_stiffness * (uw - us)
    kv_eff = sys_.stiffness + consts[0] * sys_.mass + consts[1] * sys_.damping
    kv_inv = np.linalg.inv(kv_eff)
    n_axles = sys_.n_axles
    margin = t0.n_sleepers if window_bays is None else int(window_bays)
    cluster = _clusters(sys_.axle_offsets, 2 * (margin + 1) * t0.sleeper_spacing)
    n_clusters = int(cluster.max()) + 1

    # initial state: static equilibrium on the same windows the integration starts with
    windows = [_window_dofs(t0, x_axle[0][cluster == c], margin) for c in range(n_clusters)]
    nb = n_rows
    u = np.zeros((nb, t0.n_dof))
    v = np.zeros_like(u)
    a = np.zeros_like(u)
    q = np.zeros((nb, sys_.n_dof))
    qd = np.zeros_like(q)
    qdd = np.zeros_like(q)
    f0 = np.zeros((nb, n_axles))
    for b in range(nb):
        z0 = z_rows[b][0]
        if start == "static":
            loads = sys_.static_wheel_loads.copy()
            factors = _track_window_factors(tracks[b], tuple(windows))
            for _ in range(4):  # loads on a compliant, uneven rail: a few fixed-point sweeps
                f = np.zeros(t0.n_dof)
                for (dofs, shp), p in zip(start_points, loads):
                    f[dofs] += shp * p
                u[b] = _static_in_windows(factors, f)
                w = np.array([shp @ u[b][dofs] for dofs, shp in start_points])
                q[b] = sys_.static_displacements(w + z0 + law.compression(loads))
                new = sys_.force[sys_.wheel_dofs] - sys_.stiffness[sys_.wheel_dofs] @ q[b]
                if np.all(np.abs(new - loads) <= 1e-9 + 1e-12 * np.abs(loads)):  # np.allclose's test
                    break
                loads = new
            f0[b] = loads
        else:
            q[b] = sys_.static_displacements(z0)
            qdd[b] = np.linalg.solve(sys_.mass, sys_.force - sys_.stiffness @ q[b])

    rail0 = np.zeros((nb, n_axles))  # rail and wheel under each wheel at t = 0
    wheel0 = np.zeros((nb, n_axles))
    for b in range(nb):
        for j, (dofs, shp) in enumerate(start_points):
            rail0[b, j] = shp @ u[b][dofs]
        wheel0[b] = q[b][sys_.wheel_dofs]
    pad_k = np.stack([t.pad_stiffness for t in tracks])
    pad_c = np.stack([t.pad_damping for t in tracks])
    bal_k = np.stack([t.ballast_stiffness for t in tracks])
    bal_c = np.stack([t.ballast_damping for t in tracks])
    ws, ds = lay.node_w[lay.sleeper_node], lay.sleeper
    peak_ballast = bal_k * u[:, ds]
    peak_total = peak_ballast + pad_k * (u[:, ws] - u[:, ds])

    pack = functools.partial(_pack, n_chunks=n_chunks, width=width)
    for b in range(nb, n_chunks * width):  # the padding rows copy the last row, as _pack pads
        row(z_packed, b)[...] = z_rows[-1]
    mesh = _step.Mesh(
        lay.node_w.astype(np.int64),
        lay.sleeper.astype(np.int64),
        lay.sleeper_node.astype(np.int64),
        float(t0.element_length),
        int(t0.elements_per_bay),
        int(t0.n_sleepers),
        int(margin),
        _mass_diagonals(_rail_bands(lay, t0.element_length, t0.rail_bending_stiffness, t0.rail_mass)[0]),
    )
    drive = _step.Drive(
        np.ascontiguousarray(x_axle),
        consts,
        int(law.code),
        float(law.parameter),
        np.ascontiguousarray(sys_.mass, dtype=float),
        np.ascontiguousarray(sys_.damping, dtype=float),
        np.ascontiguousarray(kv_inv),
        sys_.force.astype(float),
        sys_.wheel_dofs.astype(np.int64),
        cluster,
        n_clusters,
    )
    rows = _step.Rows(
        pack(mb[:, :, 0]),  # the diagonal of each row's mass matrix (Mesh holds the rail's off-diagonals)
        pack(keff),
        pack(pad_k),
        pack(pad_c),
        pack(bal_k),
        pack(bal_c),
        z_packed,
        pack(sag),
        pack(u),
        pack(v),
        pack(a),
        pack(q),
        pack(qd),
        pack(qdd),
    )
    history = functools.partial(_packed_history, n_steps=n_steps, n_chunks=n_chunks, width=width)
    peaks = _step.Peaks(history(f0), history(rail0), history(wheel0), pack(peak_ballast), pack(peak_total))
    # one row: its window factors and bay columns are kept for the next pass (batches keep nothing)
    one_row = n_chunks == 1 and width == 1
    reuse = _one_row_reuse(t0, dt, sys_.axle_offsets, cluster, margin) if one_row else _NO_REUSE
    _kernel.run(mesh, drive, rows, peaks, reuse, width)
    unpack = functools.partial(_unpack, n_rows=nb)
    peak_ballast, peak_total = unpack(peaks.ballast), unpack(peaks.total)

    peak_ballast += static_ballast
    peak_total += static_total
    bay_force = _bay_peaks(peaks.force, x_axle, t0.sleeper_positions)
    results = []
    for b in range(nb):
        sf = peak_ballast[b] if sleeper_force_measure == "ballast" else peak_total[b]
        results.append(
            PassResult(
                time=time,
                wheel_position=x_axle,
                contact_force=row(peaks.force, b),
                rail_displacement=row(peaks.rail, b),
                wheel_displacement=row(peaks.wheel, b),
                irregularity=z_rows[b],
                sleeper_force=sf,
                ballast_force=peak_ballast[b],
                pad_plus_ballast_force=peak_total[b],
                static_wheel_load=sys_.static_wheel_loads.copy(),
                sleeper_positions=t0.sleeper_positions,
                speed=speed,
                dt=dt,
                bay_contact_force=row(bay_force, b),
            )
        )
    if auto and dt > DT_REFERENCE_S:
        # the contract covers passes that keep contact: rows where a wheel left the rail run at the reference step
        lost = np.flatnonzero(peaks.force[:, 1:].min(axis=(1, 2)).reshape(-1)[:nb] <= 0.0).tolist()
        if lost:
            _rerun_rows(results, lost, tracks, irr_rows, None if support_settlement is None else settlement_rows,
                        vehicle, speed, dt=DT_REFERENCE_S, contact=contact, start=start, x_start=x_start,
                        x_end=x_end, window_bays=window_bays, sleeper_force_measure=sleeper_force_measure)
    return results


def _rerun_rows(results: list, rows: list[int], tracks: list[Track], irr_rows: list, settlement_rows, vehicle,
                speed: float, **options) -> None:
    """Simulate ``rows`` of a batch again as a batch of their own (other window or time step in ``options``)
    and put their results in place in ``results``; ``settlement_rows``: the batch's settled supports or None."""
    again = simulate_passes([tracks[b] for b in rows], vehicle, speed, [irr_rows[b] for b in rows],
                            support_settlement=None if settlement_rows is None else settlement_rows[rows], **options)
    for b, res in zip(rows, again):
        results[b] = res


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


KERNEL_ENTRIES = tuple(_kernel._RUNNERS)
"""The kernel's compiled entries, as (runs chunks in parallel, rows per chunk) pairs."""


def warm_kernel(entries=KERNEL_ENTRIES) -> None:
    """Compile now, or load from numba's on-disk cache, the kernel's ``entries`` (pairs of
    :data:`KERNEL_ENTRIES`) by a pass of half a metre with a batch that :func:`simulate_passes` runs on each
    entry. On a fresh install the single pass's entry compiles in ~50-70 s of one core, each other width's chunk
    integrator in ~50-60 s, shared by that width's serial and parallel entries (~2-15 s each on top); processes
    that warm different widths at once share the cache, so two cores warm them in about half the time."""
    import numba

    unknown = [e for e in entries if e not in KERNEL_ENTRIES]
    if unknown:
        raise ValueError(f"entries must be among {KERNEL_ENTRIES}, got {unknown}")
    track, wheel = Track.seed(), Wheelset.seed()
    threads = numba.get_num_threads()
    try:
        for parallel, width in entries:
            if parallel and numba.config.NUMBA_NUM_THREADS < 2:  # type: ignore[attr-defined]
                continue  # one thread can never reach a parallel entry
            # one chunk of `width` rows on one thread; two chunks of `width` rows on two threads
            numba.set_num_threads(2 if parallel else 1)
            rows = 2 * width if parallel else width
            simulate_passes(track, wheel, 20.0, np.zeros((rows, track.n_sleepers)), x_start=10.0, x_end=10.5)
    finally:
        numba.set_num_threads(threads)
