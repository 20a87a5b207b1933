"""Vertical vehicle models on one rail: a wheelset, a ten-degree-of-freedom car, and trains of cars.

Convention: the track model is one rail carrying half of each axle (the track is symmetric), so every vehicle
here is the half of the real vehicle that stands on the modelled rail. Masses, inertias and the suspension that
act on that rail are half of the whole vehicle's; loads are wheel loads. Vertical is downward positive.

Every model turns into a :class:`VehicleSystem`: its matrices, the constant forces (gravity and any extra static
load), which degree of freedom is each wheel, and the axle offsets behind the leading axle.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.linalg

from ._checks import check_field, check_int, check_scalar

GRAVITY = 9.81


@dataclass(frozen=True, eq=False)
class VehicleSystem:
    """The assembled vertical vehicle: M q'' + C q' + K q = f − Σ_j F_j e_{wheel j} (contact pushes up)."""

    mass: np.ndarray  # (n, n) [kg, kg·m²]
    damping: np.ndarray  # (n, n)
    stiffness: np.ndarray  # (n, n)
    force: np.ndarray  # (n,) constant downward forces: gravity and extra static loads [N]
    wheel_dofs: np.ndarray  # (n_axles,) index of each wheel's vertical DOF
    axle_offsets: np.ndarray  # (n_axles,) distance behind the leading axle [m], leading axle 0
    dof_names: tuple[str, ...]

    @property
    def n_dof(self) -> int:
        return int(self.force.size)

    @property
    def n_axles(self) -> int:
        return int(self.wheel_dofs.size)

    @property
    def span(self) -> float:
        """Distance from the leading to the trailing axle [m]."""
        return float(self.axle_offsets.max())

    @cached_property
    def static_wheel_loads(self) -> np.ndarray:
        """Wheel loads [N] that hold the vehicle still on a rigid, level rail (statics with the wheels fixed)."""
        w = self.wheel_dofs
        free, k_ff, _ = self._free_blocks
        f = self.force
        if free.size:
            q_free = np.linalg.solve(k_ff, f[free])
            return f[w] - self.stiffness[np.ix_(w, free)] @ q_free
        return f[w].copy()

    @cached_property
    def _free_blocks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The DOFs that are not wheels, K on them, and K between them and the wheels (for the statics)."""
        w = self.wheel_dofs
        free = np.setdiff1d(np.arange(self.n_dof), w)
        k = self.stiffness
        return free, k[np.ix_(free, free)], k[np.ix_(free, w)]

    def static_displacements(self, wheel_displacements: np.ndarray) -> np.ndarray:
        """Vehicle displacements in static equilibrium when the wheels stand at ``wheel_displacements`` [m]."""
        w = self.wheel_dofs
        q = np.zeros(self.n_dof)
        q[w] = wheel_displacements
        free, k_ff, k_fw = self._free_blocks
        if free.size:
            q[free] = np.linalg.solve(k_ff, self.force[free] - k_fw @ q[w])
        return q


@dataclass(frozen=True)
class Wheelset:
    """A single wheelset: ``mass`` is the whole wheelset [kg], half of which rides on the modelled rail, and
    ``static_load`` an extra constant wheel load [N] (for example its share of a car body).

    ``Wheelset.seed()`` is the paper's Table 4 (1800 kg, no extra load: 8.8 kN per wheel).
    ``Wheelset(mass=1800.0, static_load=100e3)`` is a loaded wheelset with a 108.8 kN static wheel load.
    """

    mass: float = 1800.0
    static_load: float = 0.0

    def __post_init__(self) -> None:
        check_field(self, "mass", low=10.0, high=20_000.0)
        check_field(self, "static_load", low=0.0, high=500e3)

    @classmethod
    def seed(cls) -> Wheelset:
        return cls(mass=1800.0, static_load=0.0)

    @classmethod
    def carrying(cls, body_mass: float, bogie_mass: float = 0.0, mass: float = 1800.0) -> Wheelset:
        """A wheelset loaded by its share of a car: P0 = (M_body/2 + M_bogie)·g/2 per wheel on top of its own
        weight (a four-axle car on two bogies)."""
        mb = check_scalar("body_mass", body_mass, low=0.0, high=200e3)
        mg = check_scalar("bogie_mass", bogie_mass, low=0.0, high=50e3)
        return cls(mass=mass, static_load=(mb / 2 + mg) * GRAVITY / 2)

    @property
    def wheel_load(self) -> float:
        """Static wheel load on the modelled rail [N]."""
        return self.mass / 2 * GRAVITY + self.static_load

    def system(self) -> VehicleSystem:
        m = self.mass / 2
        return VehicleSystem(
            mass=np.array([[m]]),
            damping=np.zeros((1, 1)),
            stiffness=np.zeros((1, 1)),
            force=np.array([self.wheel_load]),
            wheel_dofs=np.array([0]),
            axle_offsets=np.array([0.0]),
            dof_names=("wheel",),
        )


@dataclass(frozen=True)
class Car:
    """A vertical car on two bogies: body bounce and pitch, each bogie bounce and pitch, four wheelsets; primary
    suspension between bogie and wheelset, secondary between body and bogie (10 DOF).

    All values are for the whole car, as published; :meth:`system` halves masses, inertias and puts one
    primary spring per wheelset and one secondary spring per bogie on the modelled rail (one side of the car).
    """

    body_mass: float
    body_pitch_inertia: float
    bogie_mass: float
    bogie_pitch_inertia: float
    wheelset_mass: float
    primary_stiffness: float  # per axlebox (one side of one wheelset) [N/m]
    primary_damping: float  # per axlebox [N·s/m]
    secondary_stiffness: float  # per bogie side [N/m]
    secondary_damping: float  # per bogie side [N·s/m]
    bogie_wheelbase: float  # [m]
    bogie_centre_distance: float  # [m]
    length_over_buffers: float  # [m]
    name: str = field(default="car", compare=False)

    def __post_init__(self) -> None:
        ranges = {
            "body_mass": (100.0, 200e3),
            "body_pitch_inertia": (1.0, 1e8),
            "bogie_mass": (10.0, 50e3),
            "bogie_pitch_inertia": (1.0, 1e6),
            "wheelset_mass": (10.0, 10e3),
            "primary_stiffness": (1e3, 1e10),
            "primary_damping": (0.0, 1e8),
            "secondary_stiffness": (1e3, 1e10),
            "secondary_damping": (0.0, 1e8),
            "bogie_wheelbase": (0.5, 10.0),
            "bogie_centre_distance": (1.0, 50.0),
            "length_over_buffers": (2.0, 60.0),
        }
        for name, (lo, hi) in ranges.items():
            check_field(self, name, low=lo, high=hi)
        if self.bogie_centre_distance <= self.bogie_wheelbase:
            raise ValueError("bogie_centre_distance must exceed bogie_wheelbase")
        if self.length_over_buffers < self.bogie_centre_distance + self.bogie_wheelbase:
            raise ValueError("length_over_buffers must be at least bogie_centre_distance + bogie_wheelbase")

    @classmethod
    def manchester_coach(cls) -> Car:
        """The Manchester benchmark passenger coach (Iwnicki 1998): body 32 t, 1.97e6 kg·m²; bogie 2615 kg,
        1476 kg·m²; wheelset 1813 kg; primary 1.2 MN/m, 4 kN·s/m per axlebox; secondary 0.43 MN/m, 20 kN·s/m;
        wheelbase 2.56 m; bogie centres 19 m. Length over buffers 24.5 m is our assumption."""
        return cls(
            32_000.0,
            1.97e6,
            2615.0,
            1476.0,
            1813.0,
            1.2e6,
            4e3,
            0.43e6,
            20e3,
            2.56,
            19.0,
            24.5,
            name="manchester-coach",
        )

    @classmethod
    def zhai_coach(cls) -> Car:
        """Zhai's passenger coach: body 29.6 t, 2.139e6 kg·m²; bogie 1700 kg; wheelset 1900 kg; primary
        0.873 MN/m, 30 kN·s/m; secondary 0.41 MN/m, 108.7 kN·s/m; wheelbase 2.4 m; bogie centres 18 m. Bogie
        pitch inertia 1700 kg·m² and length 24.0 m are our assumptions."""
        return cls(
            29_600.0,
            2.139e6,
            1700.0,
            1700.0,
            1900.0,
            0.873e6,
            30e3,
            0.41e6,
            108.7e3,
            2.4,
            18.0,
            24.0,
            name="zhai-coach",
        )

    @classmethod
    def freight_wagon(cls) -> Car:
        """A loaded Dutch SGNS container wagon: body 29.48 t, bogie centres 14.2 m (±7.1 m), bogie 5 t,
        wheelbase 1.82 m, primary 3.27 MN/m and 80.2 kN·s/m. Assumptions (not in the source): body pitch
        inertia of a uniform 19.7 m body (m·L²/12), bogie pitch inertia 2600 kg·m², wheelset 1400 kg, and a
        stiff centre-pivot 'secondary' of 50 MN/m with 100 kN·s/m."""
        return cls(
            29_480.0,
            29_480.0 * 19.7**2 / 12,
            5000.0,
            2600.0,
            1400.0,
            3.27e6,
            80.2e3,
            50e6,
            100e3,
            1.82,
            14.2,
            19.7,
            name="freight-sgns",
        )

    @property
    def wheel_load(self) -> float:
        """Nominal static wheel load on the modelled rail [N]."""
        return (self.body_mass + 2 * self.bogie_mass + 4 * self.wheelset_mass) * GRAVITY / 8

    def system(self) -> VehicleSystem:
        n = 10
        m = np.zeros((n, n))
        diag = [
            self.body_mass / 2,
            self.body_pitch_inertia / 2,
            self.bogie_mass / 2,
            self.bogie_pitch_inertia / 2,
            self.bogie_mass / 2,
            self.bogie_pitch_inertia / 2,
        ]
        diag += [self.wheelset_mass / 2] * 4
        m[np.diag_indices(n)] = diag
        k, c = np.zeros((n, n)), np.zeros((n, n))
        lc, lw = self.bogie_centre_distance / 2, self.bogie_wheelbase / 2

        def connect(t: np.ndarray, stiff: float, damp: float) -> None:
            k[:] += stiff * np.outer(t, t)
            c[:] += damp * np.outer(t, t)

        # Longitudinal offsets a are positive forward; a point at offset a of a body moves z + a·φ.
        for b, a_b in enumerate((lc, -lc)):
            t = np.zeros(n)
            t[2 + 2 * b], t[0], t[1] = 1.0, -1.0, -a_b
            connect(t, self.secondary_stiffness, self.secondary_damping)
            for j, a_w in enumerate((lw, -lw)):
                t = np.zeros(n)
                t[6 + 2 * b + j], t[2 + 2 * b], t[3 + 2 * b] = 1.0, -1.0, -a_w
                connect(t, self.primary_stiffness, self.primary_damping)
        f = GRAVITY * np.array([m[i, i] if i in (0, 2, 4, 6, 7, 8, 9) else 0.0 for i in range(n)])
        offsets = np.array([0.0, 2 * lw, 2 * lc, 2 * lc + 2 * lw])
        names = (
            "body",
            "body_pitch",
            "bogie1",
            "bogie1_pitch",
            "bogie2",
            "bogie2_pitch",
            "wheel1",
            "wheel2",
            "wheel3",
            "wheel4",
        )
        return VehicleSystem(m, c, k, f, np.arange(6, 10), offsets, names)


@dataclass(frozen=True)
class Train:
    """A sequence of uncoupled cars running one behind the other (vertical couplers are neglected)."""

    cars: tuple[Car, ...]

    def __post_init__(self) -> None:
        cars = tuple(self.cars)
        if not cars or not all(isinstance(c, Car) for c in cars):
            raise ValueError("cars must be a non-empty sequence of Car")
        object.__setattr__(self, "cars", cars)

    @classmethod
    def of(cls, car: Car, n_cars: int) -> Train:
        return cls((car,) * check_int("n_cars", n_cars, low=1, high=40))

    def system(self) -> VehicleSystem:
        parts = [c.system() for c in self.cars]
        offsets: list[np.ndarray] = []
        wheel_dofs: list[np.ndarray] = []
        names: list[str] = []
        start, dof0 = 0.0, 0
        for car, s in zip(self.cars, parts):
            overhang = (car.length_over_buffers - s.span) / 2
            offsets.append(start + overhang + s.axle_offsets)
            wheel_dofs.append(dof0 + s.wheel_dofs)
            names += [f"car{len(names) // 10 + 1}.{nm}" for nm in s.dof_names]
            start += car.length_over_buffers
            dof0 += s.n_dof
        axle_offsets = np.concatenate(offsets)
        return VehicleSystem(
            scipy.linalg.block_diag(*[s.mass for s in parts]),
            scipy.linalg.block_diag(*[s.damping for s in parts]),
            scipy.linalg.block_diag(*[s.stiffness for s in parts]),
            np.concatenate([s.force for s in parts]),
            np.concatenate(wheel_dofs),
            axle_offsets - axle_offsets[0],
            tuple(names),
        )


Vehicle = Wheelset | Car | Train
