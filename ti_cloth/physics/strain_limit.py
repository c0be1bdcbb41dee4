"""Strain limiting (Provot 1995): after a step, springs stretched beyond (1 + max_strain) x
rest are pulled back to that length, mass-weighted, for a few Gauss-Seidel passes (the PBD
relaxation kernel, one-sided), colour by colour, so deterministic. The standard cure for "too
stretchy" cloth without tiny steps or stiff springs. A Fabric's triangle edges are limited
the same way, as stretch springs (Model.edge_colouring)."""

from dataclasses import dataclass

import taichi as ti

from ..body.material import SpringKind
from ..energies.springs import relax
from ..inputs import limits
from ..inputs.validation import count, finite_number, keyword_only, require
from ..runtime import backend, plan
from ..runtime.plan import ITEM, NOW, STATE, Loop, Phase, Repeat, Sweep


@keyword_only
@dataclass(frozen=True, kw_only=True)
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
    """The strain-limiting stage of one simulation (stages.STEP_ORDER), with the positions
    before the correction, so velocities can follow it. tearable: springs may be torn."""

    def __init__(self, limit: StrainLimit, particle_count: int, tearable: bool):
        self.tearable = tearable
        fields = backend.FieldGroup()
        self.before = fields.vector(3, backend.real(), particle_count)
        fields.finalize(self)
        self.load(limit, particle_count, tearable)

    @staticmethod
    def structure(limit: StrainLimit, particle_count: int, tearable: bool) -> tuple:
        """What the kernels of a StrainLimiter read at compile time (pool.py): the limit
        too (its strain, passes and kinds are constants of the phases)."""
        return ("StrainLimiter", limit, particle_count, tearable)

    def load(self, limit: StrainLimit, particle_count: int, tearable: bool) -> None:
        """Limit strains to `limit` (equal to the one it was built with: structure)."""
        self.limit = limit
        self.kinds = tuple(self.limit.kind_mask())

    def phases(self, model, forces, work) -> tuple:
        """The stage as phases (runtime/plan.py; `work` is this limiter): keep the positions,
        `passes` of the lecture's relaxation on stretched springs colour by colour
        (energies.springs.relax with stretched_only), then velocities follow the correction."""
        sweeps = ()
        if model.spring_count:
            colours = model.spring_colouring()
            sweeps += (Sweep(colours, relax_stretched, model, STATE, work, ITEM, colours),)
        if model.face_count:
            edges = model.edge_colouring()
            sweeps += (Sweep(edges, relax_stretched, model, STATE, work, ITEM, edges),)
        return (Phase(Loop(model.particle_count, keep_position, STATE, work, ITEM)),
                Repeat(self.limit.passes, *sweeps),
                Phase(Loop(model.particle_count, follow_velocity, STATE, work, ITEM, NOW)))

    @property
    def launched(self):
        """The object a many-steps launch runs this stage's phases on: itself (stages.py)."""
        return self

    def after_step(self, model, state, t: float, dt: float, step_index: int) -> None:
        """The strain-limiting stage of a step (stages.STEP_ORDER), a launch of its
        phases."""
        plan.run(self, model, state, None, self, dt, step_index, False)


@ti.func
def keep_position(state: ti.template(), limiter: ti.template(), i):
    limiter.before[i] = state.particle_position[i]


@ti.func
def relax_stretched(model: ti.template(), state: ti.template(), limiter: ti.template(), t,
                    colours: ti.template()):
    """The spring at position t of the colour order `colours`, pulled back to
    (1 + max_strain) x rest if longer (and of a limited kind)."""
    relax(model, state, colours, t, ti.Vector(limiter.kinds),
          limiter.tearable, limiter.limit.max_strain, True)


@ti.func
def follow_velocity(state: ti.template(), limiter: ti.template(), i, now: ti.template()):
    """v += correction / dt, so force-based integrators carry on from the corrected motion
    (Verlet-type history already does: it differences positions)."""
    state.particle_velocity[i] = (state.particle_velocity[i]
                                  + (state.particle_position[i] - limiter.before[i]) / now.dt)
