"""Wheel/rail normal contact: the non-linear Hertz spring that may lose contact, and a linear option.

Compression δ = y_wheel − (w_rail + z) with z the rail's level irregularity (downward positive, so a settled
rail lowers the contact point). The force pushes wheel and rail apart and is never a pull:
F = (δ/G)^{3/2} for δ > 0, else 0 (Hertz), or F = k·δ for δ > 0, else 0 (linear).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._checks import check_field, check_scalar

HERTZ, LINEAR = 0, 1


def zhai_contact_constant(wheel_radius: float, tread: str = "conical") -> float:
    """Hertz constant G [m/N^(2/3)] from Zhai's empirical fits: conical tread G = 4.57·R^-0.149·1e-8,
    worn tread G = 3.86·R^-0.115·1e-8, with the wheel radius R in metres."""
    r = check_scalar("wheel_radius", wheel_radius, low=0.1, high=2.0)
    if tread == "conical":
        return 4.57 * r**-0.149 * 1e-8
    if tread == "worn":
        return 3.86 * r**-0.115 * 1e-8
    raise ValueError(f"tread must be 'conical' or 'worn', got {tread!r}")


@dataclass(frozen=True)
class HertzContact:
    """Hertz contact F = (δ/G)^{3/2}, zero when δ ≤ 0 (loss of contact).

    The default G = 5.13e-8 m/N^(2/3) makes the linearised stiffness k = 1.5·F0^{1/3}/G equal the paper's
    1.43e9 N/m at a 117 kN wheel load; it is also Zhai's conical-tread value for a 0.46 m wheel.
    """

    G: float = 1.5 * 117e3 ** (1 / 3) / 1.43e9

    def __post_init__(self) -> None:
        check_field(self, "G", low=1e-10, high=1e-5)

    @classmethod
    def from_linear_stiffness(cls, stiffness: float = 1.43e9, reference_load: float = 117e3) -> HertzContact:
        """The Hertz law whose tangent stiffness at ``reference_load`` [N] is ``stiffness`` [N/m]."""
        k = check_scalar("stiffness", stiffness, low=1e6, high=1e12)
        f0 = check_scalar("reference_load", reference_load, low=1.0, high=1e7)
        return cls(G=1.5 * f0 ** (1 / 3) / k)

    @property
    def code(self) -> int:
        return HERTZ

    @property
    def parameter(self) -> float:
        return self.G

    def force(self, compression) -> np.ndarray:
        d = np.maximum(np.asarray(compression, dtype=float), 0.0)
        return (d / self.G) ** 1.5

    def compression(self, force) -> np.ndarray:
        """Compression [m] that carries ``force`` [N] (the inverse law, for static equilibrium)."""
        return self.G * np.maximum(np.asarray(force, dtype=float), 0.0) ** (2.0 / 3.0)

    def stiffness(self, force) -> np.ndarray:
        """Tangent stiffness dF/dδ at ``force`` [N/m]."""
        return 1.5 * np.maximum(np.asarray(force, dtype=float), 0.0) ** (1 / 3) / self.G


@dataclass(frozen=True)
class LinearContact:
    """A linear unilateral spring F = k·δ for δ > 0, else 0: the paper's linearised comparison (k = 1.43e9 N/m)."""

    k: float = 1.43e9

    def __post_init__(self) -> None:
        check_field(self, "k", low=1e6, high=1e12)

    @property
    def code(self) -> int:
        return LINEAR

    @property
    def parameter(self) -> float:
        return self.k

    def force(self, compression) -> np.ndarray:
        return self.k * np.maximum(np.asarray(compression, dtype=float), 0.0)

    def compression(self, force) -> np.ndarray:
        return np.maximum(np.asarray(force, dtype=float), 0.0) / self.k

    def stiffness(self, force) -> np.ndarray:
        return np.full(np.shape(force), self.k)


ContactLaw = HertzContact | LinearContact
