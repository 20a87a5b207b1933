"""The standing ballasted track: parameters per sleeper and its finite-element assembly.

The rail is an Euler-Bernoulli beam meshed with Hermite cubic elements (consistent mass), ``elements_per_bay``
elements between two sleepers. Under each sleeper the rail node hangs on a railpad spring-damper; the pad carries
the (half) sleeper mass, which rests on a ballast spring-damper over rigid ground. All properties below the rail
may vary sleeper by sleeper. The model is one rail with half the axle (symmetric track), so sleeper masses are half
sleepers and loads are wheel loads. Vertical displacements are downward positive, SI units throughout.

Degrees of freedom are numbered by position along the track: for each rail node its deflection ``w`` and rotation
``theta = dw/dx``, followed, where the node sits over a sleeper, by that sleeper's deflection. The matrices are
then banded with half-bandwidth 4, and any stretch of track is a contiguous block of them, which the moving-window
integrator in :mod:`trackenv.physics.dynamics` relies on.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from typing import Any

import numpy as np

from ._checks import check_array, check_field, check_int, check_int_field, check_scalar, readonly_array

PER_SLEEPER_FIELDS = ("pad_stiffness", "pad_damping", "sleeper_mass", "ballast_stiffness", "ballast_damping")
HALF_BANDWIDTH = 4
#: Upper bounds of the per-sleeper properties [N/m, N·s/m, kg]: far beyond any track (pads and ballast are
#: 1e7-1e9 N/m) but small enough that the assembled matrices stay well conditioned.
PER_SLEEPER_MAX = {
    "pad_stiffness": 1e12,
    "pad_damping": 1e9,
    "sleeper_mass": 1e5,
    "ballast_stiffness": 1e12,
    "ballast_damping": 1e9,
}

#: The least share of one rail element's bending stiffness (12·EI/l³) that the supports must sum to (pad and
#: ballast in series, over every sleeper): below it the track's stiffness matrix is singular in floating point.
SUPPORT_FLOOR_SHARE = 1e-9


@dataclass(frozen=True, eq=False)
class Track:
    """A straight, standing ballasted track on rigid ground (one rail, half sleepers).

    Scalars: ``sleeper_spacing`` [m], ``rail_bending_stiffness`` EI [N·m²], ``rail_mass`` [kg/m],
    ``elements_per_bay`` (rail elements between two sleepers, >= 2: one element per bay under-predicts the
    sleeper-passing force amplitude). Per-sleeper arrays (length ``n_sleepers``): ``pad_stiffness`` [N/m],
    ``pad_damping`` [N·s/m], ``sleeper_mass`` [kg], ``ballast_stiffness`` [N/m], ``ballast_damping`` [N·s/m].
    The rail runs from the first to the last sleeper (free ends); sleeper k sits at ``k * sleeper_spacing``.
    """

    pad_stiffness: np.ndarray
    pad_damping: np.ndarray
    sleeper_mass: np.ndarray
    ballast_stiffness: np.ndarray
    ballast_damping: np.ndarray
    sleeper_spacing: float = 0.6
    rail_bending_stiffness: float = 6.11e6
    rail_mass: float = 60.0
    elements_per_bay: int = 2
    name: str = field(default="custom", compare=False)

    def __post_init__(self) -> None:
        n = np.asarray(self.pad_stiffness).size
        if n < 3:
            raise ValueError(
                f"pad_stiffness must have one value per sleeper and at least 3 sleepers, got {n}"
            )
        for f in PER_SLEEPER_FIELDS:
            low_inclusive = f in ("pad_damping", "ballast_damping")
            arr = check_array(
                f, np.ravel(getattr(self, f)), shape=(n,), low=0.0, high=PER_SLEEPER_MAX[f], low_inclusive=low_inclusive
            )
            object.__setattr__(self, f, readonly_array(arr))
        check_field(self, "sleeper_spacing", low=0.05, high=5.0)
        # beyond 1e10 N·m² (1600 UIC60 rails) the stiffness matrix loses all precision against the supports
        check_field(self, "rail_bending_stiffness", low=0.0, high=1e10, low_inclusive=False)
        check_field(self, "rail_mass", low=0.0, high=1e4, low_inclusive=False)
        check_int_field(self, "elements_per_bay", low=2, high=64)
        self._check_supports_hold_the_rail()

    def _check_supports_hold_the_rail(self) -> None:
        """Refuse a track whose supports (pad and ballast in series, summed over the sleepers) are below
        SUPPORT_FLOOR_SHARE of the bending stiffness of one rail element, 12·EI/l³: far below any track (a real
        one's are 1e-4 to 1e-1 of it at each sleeper), but without it the rail floats and the assembled
        stiffness matrix is singular in floating point (a Cholesky factorisation fails deep in scipy)."""
        held = float(np.sum(self.support_stiffness))
        element = self.sleeper_spacing / self.elements_per_bay
        floor = SUPPORT_FLOOR_SHARE * 12.0 * self.rail_bending_stiffness / element**3
        if not held >= floor:
            raise ValueError(f"pad_stiffness and ballast_stiffness: the supports in series sum to {held:.3g} N/m over "
                             f"the {self.n_sleepers} sleepers, below {floor:.3g} N/m ({SUPPORT_FLOOR_SHARE:g} of a "
                             f"rail element's bending stiffness 12·EI/l³ with rail_bending_stiffness, sleeper_spacing "
                             f"and elements_per_bay as given): the rail would float on them")

    # ------------------------------------------------------------------ presets
    @classmethod
    def uniform(
        cls,
        n_sleepers: int,
        *,
        pad_stiffness: float,
        pad_damping: float,
        sleeper_mass: float,
        ballast_stiffness: float,
        ballast_damping: float,
        **scalars,
    ) -> Track:
        """A track whose supports are all alike."""
        n = check_int("n_sleepers", n_sleepers, low=3, high=100_000)
        values = dict(
            pad_stiffness=pad_stiffness,
            pad_damping=pad_damping,
            sleeper_mass=sleeper_mass,
            ballast_stiffness=ballast_stiffness,
            ballast_damping=ballast_damping,
        )
        per_sleeper: dict[str, Any] = {
            k: np.full(n, check_scalar(k, v, low=0.0, high=PER_SLEEPER_MAX[k])) for k, v in values.items()
        }
        return cls(**per_sleeper, **scalars)

    @classmethod
    def seed(cls, *, elements_per_bay: int = 2) -> Track:
        """The paper's Table 3: 30 m, 51 sleepers at 0.6 m, EI 6.11e6 N·m², 60 kg/m, pad 200 MN/m and
        30 kN·s/m, half sleeper 157.4 kg, ballast 160 MN/m and 500 kN·s/m."""
        return cls.uniform(
            51,
            pad_stiffness=200e6,
            pad_damping=30e3,
            sleeper_mass=157.4,
            ballast_stiffness=160e6,
            ballast_damping=500e3,
            sleeper_spacing=0.6,
            rail_bending_stiffness=6.11e6,
            rail_mass=60.0,
            elements_per_bay=elements_per_bay,
            name="seed",
        )

    @classmethod
    def realistic(cls, length: float = 60.0, *, elements_per_bay: int = 2, sleeper_spacing: float = 0.6) -> Track:
        """A typical UIC60 ballasted track of ``length`` metres, sleepers every ``sleeper_spacing`` metres.

        Rail UIC60: E = 210 GPa, I = 3055 cm⁴ (EI = 6.42e6 N·m²), 60.2 kg/m (EN 13674-1 profile data).
        Pads and sleeper as in the paper's Table 3 (200 MN/m, 30 kN·s/m, 157.4 kg half sleeper). Ballast
        160 MN/m with 60 kN·s/m damping, the typical value of Zhai's vertical track model, instead of the
        paper's 500 kN·s/m (which makes the sleeper-on-ballast mode heavily overdamped, ζ ≈ 1.6).
        """
        length = check_scalar("length", length, low=3.0, high=10_000.0)
        n = int(round(length / sleeper_spacing)) + 1
        return cls.uniform(
            n,
            pad_stiffness=200e6,
            pad_damping=30e3,
            sleeper_mass=157.4,
            ballast_stiffness=160e6,
            ballast_damping=60e3,
            sleeper_spacing=sleeper_spacing,
            rail_bending_stiffness=210e9 * 3055e-8,
            rail_mass=60.21,
            elements_per_bay=elements_per_bay,
            name=f"realistic-{length:g}m",
        )

    # --------------------------------------------------------------- modifiers
    def replace(self, **changes) -> Track:
        """A copy with some fields changed (validated again)."""
        known = {f.name for f in fields(self)}
        unknown = set(changes) - known
        if unknown:
            raise ValueError(f"unknown Track field(s) {sorted(unknown)}; known: {sorted(known)}")
        return replace(self, **changes)

    def scaled(self, *, from_sleeper: int = 0, to_sleeper: int | None = None, **factors: float) -> Track:
        """A copy with per-sleeper properties multiplied by ``factors`` for sleepers
        ``from_sleeper .. to_sleeper - 1`` (to the end by default).

        ``Track.seed().scaled(ballast_stiffness=1.10, from_sleeper=40)`` is the paper's scenario B: the ballast
        10 % stiffer from sleeper 40 (24 m) on.
        """
        if not factors:
            raise ValueError(f"scaled needs at least one factor among {PER_SLEEPER_FIELDS}")
        unknown = set(factors) - set(PER_SLEEPER_FIELDS)
        if unknown:
            raise ValueError(f"unknown per-sleeper property {sorted(unknown)}; known: {PER_SLEEPER_FIELDS}")
        sl = self._sleeper_slice(from_sleeper, to_sleeper)
        changes = {}
        for name, factor in factors.items():
            f = check_scalar(name, factor, low=0.0, high=1e6, low_inclusive=False)
            arr = np.array(getattr(self, name))
            arr[sl] *= f
            changes[name] = arr
        return self.replace(**changes)

    def with_voided_sleeper(self, index: int, *, residual_support: float = 0.02) -> Track:
        """A copy in which sleeper ``index`` hangs: a gap under it leaves only ``residual_support`` of its ballast
        stiffness and damping.

        This is the linear model of a voided sleeper whose gap stays open under load: a sleeper that closes its
        gap needs a contact law in the ballast, which this linear track does not have.
        """
        r = check_scalar("residual_support", residual_support, low=0.0, high=1.0, low_inclusive=False)
        index = check_int("index", index, low=0, high=self.n_sleepers - 1)
        sl = self._sleeper_slice(index, index + 1)
        kb, cb = np.array(self.ballast_stiffness), np.array(self.ballast_damping)
        kb[sl] *= r
        cb[sl] *= r
        return self.replace(ballast_stiffness=kb, ballast_damping=cb)

    def extended(self, n_before: int, n_after: int) -> Track:
        """A copy with ``n_before`` sleepers added before the first and ``n_after`` after the last, each a copy
        of the end sleeper it continues (approach and exit zones)."""
        n_before = check_int("n_before", n_before, low=0, high=100_000)
        n_after = check_int("n_after", n_after, low=0, high=100_000)
        changes = {
            f: np.concatenate(
                [
                    np.full(n_before, getattr(self, f)[0]),
                    getattr(self, f),
                    np.full(n_after, getattr(self, f)[-1]),
                ]
            )
            for f in PER_SLEEPER_FIELDS
        }
        return self.replace(**changes)

    def _sleeper_slice(self, start: int, stop: int | None) -> slice:
        n = self.n_sleepers
        start = check_int("from_sleeper/index", start, low=0, high=n - 1)
        if stop is not None:
            stop = check_int("to_sleeper", stop, low=start + 1, high=n)
        return slice(start, stop)

    # ------------------------------------------------------------ geometry
    @property
    def n_sleepers(self) -> int:
        return int(self.pad_stiffness.size)

    @property
    def length(self) -> float:
        """Rail length from the first to the last sleeper [m]."""
        return (self.n_sleepers - 1) * self.sleeper_spacing

    @property
    def sleeper_positions(self) -> np.ndarray:
        """Sleeper positions along the track [m]; sleeper k at k·spacing."""
        return np.arange(self.n_sleepers) * self.sleeper_spacing

    @property
    def element_length(self) -> float:
        return self.sleeper_spacing / self.elements_per_bay

    @property
    def n_nodes(self) -> int:
        return (self.n_sleepers - 1) * self.elements_per_bay + 1

    @property
    def node_positions(self) -> np.ndarray:
        return np.arange(self.n_nodes) * self.element_length

    @property
    def n_dof(self) -> int:
        return 2 * self.n_nodes + self.n_sleepers

    @cached_property
    def dof_layout(self) -> DofLayout:
        return DofLayout.build(self.n_sleepers, self.elements_per_bay)

    # ----------------------------------------------------------- closed forms
    @property
    def support_stiffness(self) -> np.ndarray:
        """Pad and ballast in series per support [N/m]."""
        return 1.0 / (1.0 / self.pad_stiffness + 1.0 / self.ballast_stiffness)

    @property
    def foundation_modulus(self) -> float:
        """Mean support stiffness smeared over the spacing, k_f [N/m²] (Winkler foundation)."""
        return float(np.mean(self.support_stiffness) / self.sleeper_spacing)

    @property
    def winkler_beta(self) -> float:
        """β = (k_f / 4EI)^¼ [1/m]."""
        return (self.foundation_modulus / (4.0 * self.rail_bending_stiffness)) ** 0.25

    @property
    def pinned_pinned_frequency(self) -> float:
        """(π/s)²·√(EI/m)/2π [Hz]: the rail's first bending mode between two rigid supports."""
        return (
            (np.pi / self.sleeper_spacing) ** 2
            * np.sqrt(self.rail_bending_stiffness / self.rail_mass)
            / (2 * np.pi)
        )

    def winkler_deflection(self, load: float) -> float:
        """Static deflection under a point load on a Winkler beam, w0 = Pβ/(2k_f) [m]."""
        return load * self.winkler_beta / (2.0 * self.foundation_modulus)

    # ------------------------------------------------------------- assembly
    def banded_matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Mass, damping and stiffness in lower banded storage, ``band[i, k] = A[i, i - k]``, shape
        (n_dof, HALF_BANDWIDTH + 1). Fresh copies of the cached assembly."""
        return tuple(b.copy() for b in self._bands)

    @cached_property
    def _bands(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return assemble_banded(
            self.dof_layout,
            self.element_length,
            self.rail_bending_stiffness,
            self.rail_mass,
            self.pad_stiffness,
            self.pad_damping,
            self.sleeper_mass,
            self.ballast_stiffness,
            self.ballast_damping,
        )

    def matrices(self):
        """Mass, damping and stiffness as scipy CSR matrices (for reference computations)."""
        return tuple(band_to_sparse(b) for b in self.banded_matrices())


@dataclass(frozen=True)
class DofLayout:
    """Where each rail node and sleeper sits in the global vector of unknowns."""

    node_w: np.ndarray  # (n_nodes,) index of each rail node's deflection
    node_theta: np.ndarray  # (n_nodes,) index of each rail node's rotation
    sleeper: np.ndarray  # (n_sleepers,) index of each sleeper's deflection
    sleeper_node: np.ndarray  # (n_sleepers,) rail node above each sleeper
    n_dof: int

    @classmethod
    def build(cls, n_sleepers: int, elements_per_bay: int) -> DofLayout:
        n_nodes = (n_sleepers - 1) * elements_per_bay + 1
        node_w = np.empty(n_nodes, dtype=np.int64)
        node_t = np.empty(n_nodes, dtype=np.int64)
        sleeper = np.empty(n_sleepers, dtype=np.int64)
        sleeper_node = np.arange(n_sleepers, dtype=np.int64) * elements_per_bay
        d = 0
        for i in range(n_nodes):
            node_w[i], node_t[i] = d, d + 1
            d += 2
            if i % elements_per_bay == 0:
                sleeper[i // elements_per_bay] = d
                d += 1
        return cls(node_w, node_t, sleeper, sleeper_node, d)


def hermite_element_matrices(length: float, bending_stiffness: float, mass_per_length: float):
    """Stiffness and consistent mass of a Hermite cubic Euler-Bernoulli element, DOFs (w1, θ1, w2, θ2)."""
    L = length
    k = (
        bending_stiffness
        / L**3
        * np.array(
            [
                [12, 6 * L, -12, 6 * L],
                [6 * L, 4 * L * L, -6 * L, 2 * L * L],
                [-12, -6 * L, 12, -6 * L],
                [6 * L, 2 * L * L, -6 * L, 4 * L * L],
            ]
        )
    )
    m = (
        mass_per_length
        * L
        / 420.0
        * np.array(
            [
                [156, 22 * L, 54, -13 * L],
                [22 * L, 4 * L * L, 13 * L, -3 * L * L],
                [54, 13 * L, 156, -22 * L],
                [-13 * L, -3 * L * L, -22 * L, 4 * L * L],
            ]
        )
    )
    return k, m


def hermite_shape(xi: float, length: float) -> np.ndarray:
    """Hermite cubic shape functions at ξ ∈ [0, 1] of an element of ``length``: w(ξ) = N·(w1, θ1, w2, θ2)."""
    xi2, xi3 = xi * xi, xi * xi * xi
    return np.array(
        [1 - 3 * xi2 + 2 * xi3, length * (xi - 2 * xi2 + xi3), 3 * xi2 - 2 * xi3, length * (xi3 - xi2)]
    )


def rail_bands(layout: DofLayout, element_length: float, ei: float, rail_mass: float):
    """M, C, K of the bare rail (no supports) in lower banded storage (see :meth:`Track.banded_matrices`):
    every element's Hermite stiffness and consistent mass added at its four DOFs, all elements in one
    ``np.add.at`` (unbuffered, in element order: each entry gets the sum a loop over the elements gives)."""
    n, b = layout.n_dof, HALF_BANDWIDTH
    ke, me = hermite_element_matrices(element_length, ei, rail_mass)
    w, theta = layout.node_w, layout.node_theta
    dofs = np.stack([w[:-1], theta[:-1], w[1:], theta[1:]], axis=1)  # (n_elements, 4)
    a, c = np.tril_indices(4)  # each symmetric element matrix's lower triangle, row by row
    i, j = dofs[:, a], dofs[:, c]
    row, col = np.maximum(i, j).ravel(), np.minimum(i, j).ravel()
    m_band, c_band, k_band = (np.zeros((n, b + 1)) for _ in range(3))
    for band, elem in ((k_band, ke), (m_band, me)):
        np.add.at(band, (row, row - col), np.broadcast_to(elem[a, c], i.shape).ravel())
    return m_band, c_band, k_band


def add_supports(m_band, c_band, k_band, layout: DofLayout, pad_k, pad_c, sleeper_m, ballast_k, ballast_c) -> None:
    """Add the railpads, sleepers and ballast to the bands (..., n_dof, HALF_BANDWIDTH + 1) in place: each pad
    couples its rail node and its sleeper, each ballast spring holds a sleeper to the ground. The support
    arrays are (..., n_sleepers), with the bands' leading axes (a batch of tracks on one mesh at once)."""
    w, d = layout.node_w[layout.sleeper_node], layout.sleeper
    for band, pad, bal in ((k_band, pad_k, ballast_k), (c_band, pad_c, ballast_c)):
        pad, bal = np.asarray(pad), np.asarray(bal)
        band[..., w, 0] += pad
        band[..., d, 0] += pad + bal
        band[..., d, d - w] -= pad
    m_band[..., d, 0] += sleeper_m


def assemble_banded(
    layout: DofLayout,
    element_length: float,
    ei: float,
    rail_mass: float,
    pad_k,
    pad_c,
    sleeper_m,
    ballast_k,
    ballast_c,
):
    """Assemble M, C, K of the track in lower banded storage (see :meth:`Track.banded_matrices`): the rail
    (:func:`rail_bands`), then its supports (:func:`add_supports`)."""
    m_band, c_band, k_band = rail_bands(layout, element_length, ei, rail_mass)
    add_supports(m_band, c_band, k_band, layout, pad_k, pad_c, sleeper_m, ballast_k, ballast_c)
    return m_band, c_band, k_band


def band_to_sparse(band: np.ndarray):
    """Lower banded storage to a symmetric scipy CSR matrix."""
    import scipy.sparse as sp

    n, b1 = band.shape
    rows, cols, vals = [], [], []
    for k in range(b1):
        i = np.arange(k, n)
        v = band[k:, k]
        rows.append(i)
        cols.append(i - k)
        vals.append(v)
        if k:
            rows.append(i - k)
            cols.append(i)
            vals.append(v)
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
