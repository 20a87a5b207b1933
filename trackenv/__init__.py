"""trackenv: learn when and where to tamp a ballasted railway track, on real vehicle-track dynamics.

The physics (``trackenv.physics``) runs on its own; :class:`TrackDegradation` is the paper's iterative
settlement loop; ``trackenv.envs`` (its ids registered on import: ``trackenv/TampingLine-v0``, the line, and
``trackenv/Tamping-v1``, the 60 m track) is the Gymnasium environment on top of it.
"""

from importlib import metadata as _metadata

from ._openmp import prefer_passive_wait as _prefer_passive_wait
from .degradation import DegradationHistory, IterationRecord, RunawayError, RunawayWarning, TrackDegradation
from .physics.contact import HertzContact, LinearContact, zhai_contact_constant
from .physics.dynamics import (
    OverloadError,
    OverloadWarning,
    PassResult,
    UnloadedTrackWarning,
    receptance,
    simulate_pass,
    simulate_pass_batches,
    simulate_passes,
    static_deflection,
)
from .physics.settlement import (
    LAWS,
    AlvaHurtadoSeligLaw,
    HettlerLaw,
    IndraratnaLaw,
    SatoLaw,
    SeligWatersLaw,
    SettlementLaw,
    SettlementState,
    ShentonLaw,
    make_law,
)
from .physics.tamping import TampingModel
from .physics.track import Track
from .physics.vehicle import Car, Train, VehicleSystem, Wheelset

_prefer_passive_wait()  # the imports above start no OpenMP runtime (numba starts one at its first parallel call)

try:  # one source for the version: pyproject.toml, read back from the installed distribution's metadata
    __version__ = _metadata.version("trackenv")
except _metadata.PackageNotFoundError:  # pragma: no cover - a source tree that was never installed
    __version__ = "0+unknown"

__all__ = [
    "LAWS",
    "AlvaHurtadoSeligLaw",
    "Car",
    "DegradationHistory",
    "HertzContact",
    "HettlerLaw",
    "IndraratnaLaw",
    "IterationRecord",
    "LinearContact",
    "OverloadError",
    "OverloadWarning",
    "PassResult",
    "SatoLaw",
    "SeligWatersLaw",
    "SettlementLaw",
    "SettlementState",
    "ShentonLaw",
    "TampingModel",
    "Track",
    "TrackDegradation",
    "RunawayError",
    "RunawayWarning",
    "Train",
    "UnloadedTrackWarning",
    "VehicleSystem",
    "Wheelset",
    "make_law",
    "receptance",
    "simulate_pass",
    "simulate_pass_batches",
    "simulate_passes",
    "static_deflection",
    "zhai_contact_constant",
]

try:  # the environment needs gymnasium; the physics does not
    from . import envs as _envs  # noqa: F401  (registers the ids)
except ImportError:  # pragma: no cover
    pass
