"""Strain limiting (Provot 1995): after a step, springs stretched beyond (1 + max_strain) x
rest are pulled back to that length, mass-weighted, for a few Gauss-Seidel passes (the PBD
relaxation kernel, one-sided), colour by colour, so deterministic. The standard cure for "too
stretchy" cloth without tiny steps or stiff springs."""

from dataclasses import dataclass

import taichi as ti

from ..body.material import SpringKind
from ..runtime import backend, limits
from ..runtime.validation import count, finite_number, require
from ..state import copy_positions
from .constraints import relax_springs, sweep


@dataclass(frozen=True)
class StrainLimit:
    """max_strain: allowed stretch, > 0 (0.1: no spring longer than 110 % of its rest length).
    passes: relaxation sweeps per step, >= 1 (each sweep visits every spring once).
    kinds: spring kinds limited (Provot limits the structural and shear springs)."""

    max_strain: float = 0.1
    passes: int = 4
    kinds: tuple = ("stretch", "shear")

    def __post_init__(self):
        object.__setattr__(self, "max_strain", finite_number("StrainLimit.max_strain",
                                                             self.max_strain, 0.0, strict=True))
        object.__setattr__(self, "passes", count("StrainLimit.passes", self.passes, limits.ITERATIONS))
        names = {k.name.lower() for k in SpringKind}
        require(isinstance(self.kinds, (list, tuple)), "StrainLimit.kinds", self.kinds,
                f"a list of spring kinds from {sorted(names)}")
        kinds = tuple(self.kinds)
        require(len(kinds) > 0 and all(isinstance(k, str) for k in kinds) and set(kinds) <= names, "StrainLimit.kinds", self.kinds,
                f"a non-empty subset of {sorted(names)}")
        object.__setattr__(self, "kinds", kinds)

    def kind_mask(self) -> ti.math.vec3:
        return ti.math.vec3(*(float(k.name.lower() in self.kinds) for k in SpringKind))


@backend.kernel_argument
class StrainLimiter:
    """The strain-limiting stage of one simulation (simulation.STEP_ORDER), with the positions
    before the correction, so velocities can follow it. tearable: springs may be torn."""

    def __init__(self, limit: StrainLimit, particle_count: int, tearable: bool):
        self.tearable = tearable
        fields = backend.FieldGroup()
        self.before = fields.vector(3, backend.real(), particle_count)
        fields.finalize(self)
        self.load(limit, particle_count, tearable)

    @staticmethod
    def structure(limit: StrainLimit, particle_count: int, tearable: bool) -> tuple:
        """What the kernels of a StrainLimiter read at compile time (pool.py); its `limit`
        is passed to them as arguments, so limiters of one structure take any limit."""
        return ("StrainLimiter", particle_count, tearable)

    def load(self, limit: StrainLimit, particle_count: int, tearable: bool) -> None:
        """Limit strains to `limit` from now on (a limiter of this structure)."""
        self.limit = limit

    def after_step(self, model, state, t: float, dt: float, step_index: int) -> None:
        copy_positions(state, self.before)
        # the lecture's relaxation, for stretched springs only
        sweep(relax_springs, model, state, self.limit.passes, self.limit.kind_mask(), 0.0,
              self.tearable, self.limit.max_strain, True)
        follow_velocity(state, self, dt)


@backend.kernel
def follow_velocity(state: ti.template(), limiter: ti.template(), dt: float):
    """v += correction / dt, so force-based integrators carry on from the corrected motion
    (Verlet-type history already does: it differences positions)."""
    for i in limiter.before:
        state.particle_velocity[i] = (state.particle_velocity[i]
                                      + (state.particle_position[i] - limiter.before[i]) / dt)
