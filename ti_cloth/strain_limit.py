"""Strain limiting (Provot 1995): after a step, springs stretched beyond (1 + max_strain) x
rest are pulled back to that length, mass-weighted, for a few Gauss-Seidel passes. The standard
cure for "too stretchy" cloth without tiny steps or stiff springs."""

from dataclasses import dataclass

import taichi as ti

from . import backend
from ._validate import finite_number, require
from .material import SpringKind


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
        require(isinstance(self.passes, int) and not isinstance(self.passes, bool) and self.passes >= 1,
                "StrainLimit.passes", self.passes, "an int >= 1")
        names = {k.name.lower() for k in SpringKind}
        kinds = tuple(self.kinds)
        require(len(kinds) > 0 and set(kinds) <= names, "StrainLimit.kinds", self.kinds,
                f"a non-empty subset of {sorted(names)}")
        object.__setattr__(self, "kinds", kinds)

    def kind_mask(self) -> ti.math.vec3:
        return ti.math.vec3(*(float(k.name.lower() in self.kinds) for k in SpringKind))


@ti.data_oriented
class StrainLimiter:
    """Positions before the correction, so velocities can follow it."""

    def __init__(self, limit: StrainLimit, particle_count: int):
        self.limit = limit
        self.before = ti.Vector.field(3, backend.real(), shape=particle_count)

    def apply(self, model, state, dt: float, tearing: bool) -> None:
        order, offsets = model.spring_colouring()
        _record(state, self)
        for _ in range(self.limit.passes):
            _limit_pass(model, state, order, offsets, self.limit.max_strain,
                        self.limit.kind_mask(), tearing)
        _follow_velocity(state, self, dt)


@ti.kernel
def _record(state: ti.template(), limiter: ti.template()):
    for i in limiter.before:
        limiter.before[i] = state.particle_position[i]


@ti.kernel
def _limit_pass(model: ti.template(), state: ti.template(), order: ti.template(),
                offsets: ti.template(), max_strain: float, kinds: ti.math.vec3,
                tearing: ti.template()):
    """One sweep, colour by colour (springs of a colour share no particle: deterministic):
    a spring longer than (1 + max_strain) L is shortened to it, each end moving by its share
    of the inverse mass (pins do not move)."""
    for c in ti.static(range(len(offsets) - 1)):
        for t in range(offsets[c], offsets[c + 1]):
            s = order[t]
            alive = True
            if ti.static(tearing):
                alive = state.spring_alive[s] != 0
            p, q = model.spring_indices[s][0], model.spring_indices[s][1]
            wp, wq = model.particle_inv_mass[p], model.particle_inv_mass[q]
            d = state.particle_position[q] - state.particle_position[p]
            length = d.norm()
            longest = (1.0 + max_strain) * model.spring_rest_length[s]
            if alive and kinds[model.spring_kind[s]] > 0 and wp + wq > 0 and length > longest:
                dx = (length - longest) / length * d
                state.particle_position[p] += wp / (wp + wq) * dx
                state.particle_position[q] -= wq / (wp + wq) * dx


@ti.kernel
def _follow_velocity(state: ti.template(), limiter: ti.template(), dt: float):
    """v += correction / dt, so force-based integrators carry on from the corrected motion
    (Verlet-type history already does: it differences positions)."""
    for i in limiter.before:
        state.particle_velocity[i] += (state.particle_position[i] - limiter.before[i]) / dt
