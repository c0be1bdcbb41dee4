"""The lecture's cloth: Verlet prediction under external forces, then spring relaxation."""


from collections.abc import Mapping

import taichi as ti

from ..body.material import SpringKind
from ..physics.constraints import SweepOrder, relax_pass, relax_springs, sweep
from ..physics.forces import compute_forces, gather_force
from ..runtime import backend, limits
from ..runtime.validation import count, finite_number, require
from ..state import store_particle
from . import fused
from .base import Integrator
from .verlet import verlet_update


@ti.func
def velocity_from_positions(state: ti.template(), i, dt, step):
    """v_{n+1} = (x_{n+1} - x_n) / h for particle i, with x_n in particle_prev_position."""
    x = state.particle_position[i]
    store_particle(state, i, x, (x - state.particle_prev_position[i]) / dt, step)


@backend.kernel
def update_velocity(model: ti.template(), state: ti.template(), dt: float, step: ti.i32):
    for i in range(model.particle_count):
        velocity_from_positions(state, i, dt, step)


@backend.kernel
def _predict(model: ti.template(), state: ti.template(), dt: float, damping: float, start: ti.i32,
             step: ti.i32):
    """Verlet prediction under the external forces in particle_force."""
    for i in range(model.particle_count):
        verlet_update(state, i, model.particle_inv_mass[i] * state.particle_force[i], dt, damping,
                      start, step)


STIFFNESS_KEYS = tuple(k.name.lower() for k in SpringKind) + ("altitude",)


class PBD(Integrator):
    """Position-based dynamics as in the lecture: springs are constraints.

    Each step: (1) Verlet-predict every particle under gravity and drag only (with the lecture's
    damping factor), (2) `iterations` Gauss-Seidel passes of mass-weighted spring relaxation,
    (3) velocity = (x_{n+1} - x_n) / h. Spring constants k and kd are not used: with
    stiffness 1 a spring is projected fully to its rest length each pass, so the cloth's
    apparent stiffness grows with iterations and shrinks with h (use xpbd for a material
    stiffness in N/m).

    iterations: relaxation passes per step, >= 1 (the lecture uses 1-2).
    damping: lecture factor d in [0, 1), as Verlet.
    stiffness: fraction of the correction applied per pass, per kind, {"stretch": 1.0, ...};
        "altitude" for the altitude springs (each a corner projected to its rest height over
        the opposite face of a tetrahedron: constraints._relax_altitude).
    Order 1 (velocity from positions); no step-size stability limit: positions are projected,
    never extrapolated by stiff forces.
    """

    name = "pbd"
    order = 1
    position_based = True
    step_limited = False
    teamed = True
    records_history = True

    def __init__(self, *, iterations: int = 2, damping: float = 0.0, stiffness=None):
        self.iterations = count("PBD.iterations", iterations, limits.ITERATIONS)
        self.damping = finite_number("PBD.damping", damping, 0.0)
        require(self.damping < 1.0, "PBD.damping", damping, "a number in [0, 1)")
        require(stiffness is None or isinstance(stiffness, Mapping), "PBD.stiffness", stiffness,
                "None or a table {stretch = 1.0, shear = ..., bend = ...}")
        stiffness = dict(stiffness or {})
        unknown = set(stiffness) - set(STIFFNESS_KEYS)
        require(not unknown, "PBD.stiffness keys", sorted(unknown),
                ", ".join(repr(k) for k in STIFFNESS_KEYS))
        self.stiffness = {k: 1.0 for k in STIFFNESS_KEYS} | {
            name: finite_number(f"PBD.stiffness[{name!r}]", value, 0.0) for name, value in stiffness.items()}
        for name, value in self.stiffness.items():
            require(value <= 1.0, f"PBD.stiffness[{name!r}]", value, "a fraction in [0, 1]")
        self.kind_stiffness = tuple(self.stiffness[k.name.lower()] for k in SpringKind)

    def options(self):
        return {"iterations": self.iterations, "damping": self.damping, "stiffness": self.stiffness}

    def workspace(self, model, state):
        return self.buffers(state, lambda: SweepOrder(model))

    def step_work(self, model):
        return (self.iterations + 2) * fused.spring_work(model)

    @ti.func
    def team_step(self, model: ti.template(), state: ti.template(), forces: ti.template(),
                  work: ti.template(), stages: ti.template(), team: ti.template(), worker, dt,
                  step, start):
        """step()'s kernels as phases of one worker's share (work: the SweepOrder),
        meeting the team between them and after every colour of a pass."""
        p_begin, p_end = team.share(model.particle_count, worker)
        for i in range(p_begin, p_end):
            f = gather_force(model, state, forces, i, False)
            state.particle_force[i] = f
            verlet_update(state, i, model.particle_inv_mass[i] * f, dt, self.damping, start, step)
        if ti.static(model.spring_count + model.altitude_count > 0):
            team.meet(worker)
            stiffness = ti.Vector(self.kind_stiffness)
            for _ in range(self.iterations):
                relax_pass(model, state, work.colours, work.altitude_colours, stiffness,
                           self.stiffness["altitude"], forces.tearable, 0.0, False, team, worker)
        for i in range(p_begin, p_end):
            velocity_from_positions(state, i, dt, step)
        team.meet(worker)

    def step(self, model, state, dt, forces, step_index):
        compute_forces(model, state, forces, springs=False)   # external forces only
        _predict(model, state, dt, self.damping, not state.prev_valid, step_index)
        state.prev_valid = True
        if model.spring_count + model.altitude_count:
            stiffness = ti.math.vec3(*self.kind_stiffness)
            sweep(relax_springs, model, state, self.iterations, stiffness,
                  self.stiffness["altitude"], forces.tearable, 0.0, False)
        update_velocity(model, state, dt, step_index)
