"""Integrators, one module each, and the registry that maps names to them."""

from __future__ import annotations

from .base import Integrator
from .explicit_euler import ExplicitEuler
from .implicit_euler import ImplicitEuler
from .implicit_midpoint import ImplicitMidpoint
from .pbd import PBD
from .rk4 import RK4
from .stabilized_rk2 import StabilizedRK2
from .symplectic_euler import SymplecticEuler
from .tr_bdf2 import TRBDF2
from .verlet import Verlet
from .xpbd import XPBD

INTEGRATORS: dict[str, type[Integrator]] = {
    cls.name: cls for cls in (ExplicitEuler, SymplecticEuler, Verlet, PBD, XPBD, ImplicitEuler,
                              ImplicitMidpoint, TRBDF2, RK4, StabilizedRK2)
}


def make_integrator(spec) -> Integrator:
    """An Integrator from its name (default options) or an Integrator instance as is."""
    if isinstance(spec, Integrator):
        return spec
    if not isinstance(spec, str) or spec not in INTEGRATORS:
        raise ValueError(f"integrator must be one of {sorted(INTEGRATORS)} or an Integrator "
                         f"instance, got {spec!r}")
    return INTEGRATORS[spec]()


__all__ = ["Integrator", "ExplicitEuler", "SymplecticEuler", "Verlet", "PBD", "XPBD", "ImplicitEuler",
           "ImplicitMidpoint", "TRBDF2", "RK4", "StabilizedRK2", "INTEGRATORS", "make_integrator"]
