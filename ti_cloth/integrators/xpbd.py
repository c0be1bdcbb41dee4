"""Extended position-based dynamics (Macklin, Mueller & Chentanez 2016): springs as compliant
constraints with compliance 1 / k, so the cloth has its material stiffness in N/m."""


import taichi as ti

from ..physics.constraints import damp_pass, damp_springs, sweep, xpbd_pass, xpbd_springs
from ..physics.forces import compute_forces, gather_force
from ..runtime import backend, limits
from ..runtime.validation import count
from . import fused
from .base import Integrator
from .pbd import update_velocity, velocity_from_positions


@ti.func
def _predict_particle(model: ti.template(), state: ti.template(), i, dt):
    """x~ = x_n + h (v_n + h M^-1 f_ext); x_n is kept in particle_prev_position."""
    x = state.particle_position[i]
    v = state.particle_velocity[i] + dt * model.particle_inv_mass[i] * state.particle_force[i]
    state.particle_prev_position[i] = x
    state.particle_position[i] = x + dt * v


@backend.kernel
def xpbd_predict(model: ti.template(), state: ti.template(), dt: float):
    for i in range(model.particle_count):
        _predict_particle(model, state, i, dt)


@backend.kernel_argument
class _Multipliers:
    """One Lagrange multiplier per spring (in colour order) and per altitude spring [N s^2],
    reset every step, and the model's colourings (read by the team step)."""

    def __init__(self, model):
        fields = backend.FieldGroup()
        self.value = fields.scalar(backend.real(), max(model.spring_count, 1))
        self.altitude = fields.scalar(backend.real(), max(model.altitude_count, 1))
        fields.finalize(self)
        self.colours = model.spring_colouring()
        self.altitude_colours = model.altitude_colouring()


class XPBD(Integrator):
    """XPBD: predict under external forces (gravity, drag, wind), then `iterations`
    Gauss-Seidel passes over the springs in colour order, each updating the spring's Lagrange
    multiplier (constraints.xpbd_springs), then v = (x_{n+1} - x_n) / h.

    Unlike pbd, the result does not depend on the iteration count once converged: it is the
    backward Euler step of the same Hookean springs (compliance 1/k) the force-based
    integrators use, with axial damping kd. On a body with relative damping (Stuyck eq. 4.7)
    the constraints are undamped and one pass of implicit relative damping on the new
    velocities follows (constraints.damp_springs: each spring's backward Euler step in turn,
    stable at any h); positions keep their solve, as in position-based damping (Mueller et al.
    2007), and the next prediction starts from the damped velocities. Unconverged (few
    iterations, stiff springs, large h), the cloth is softer than its material.
    iterations: Gauss-Seidel passes per step, >= 1.
    Order 1. No step-size stability limit.
    """

    name = "xpbd"
    order = 1
    position_based = True
    step_limited = False
    teamed = True

    def __init__(self, *, iterations: int = 10):
        self.iterations = count("XPBD.iterations", iterations, limits.ITERATIONS)

    def options(self):
        return {"iterations": self.iterations}

    def workspace(self, model, state):
        return self.buffers(state, lambda: _Multipliers(model))

    def step_work(self, model):
        return (self.iterations + 2) * fused.spring_work(model)

    @ti.func
    def team_step(self, model: ti.template(), state: ti.template(), forces: ti.template(),
                  work: ti.template(), stages: ti.template(), team: ti.template(), worker, dt,
                  step, start):
        """step()'s kernels as phases of one worker's share, meeting the team between them
        (and after every colour of a pass)."""
        p_begin, p_end = team.share(model.particle_count, worker)
        for i in range(p_begin, p_end):
            state.particle_force[i] = gather_force(model, state, forces, i, False)
            _predict_particle(model, state, i, dt)
        if ti.static(model.spring_count + model.altitude_count > 0):
            s_begin, s_end = team.share(model.spring_count, worker)
            for s in range(s_begin, s_end):
                work.value[s] = 0.0
            a_begin, a_end = team.share(model.altitude_count, worker)
            for a in range(a_begin, a_end):
                work.altitude[a] = 0.0
            team.meet(worker)
            for _ in range(self.iterations):
                xpbd_pass(model, state, work.colours, work.altitude_colours, work.value,
                          work.altitude, dt, forces.tearable, team, worker)
        for i in range(p_begin, p_end):
            velocity_from_positions(state, i, dt, step)
        if ti.static(model.spring_count > 0 and model.relative_damping):
            team.meet(worker)
            damp_pass(model, state, work.colours, dt, forces.tearable, team, worker)
        team.meet(worker)

    def step(self, model, state, dt, forces, step_index):
        compute_forces(model, state, forces, springs=False)   # external forces only
        xpbd_predict(model, state, dt)
        if model.spring_count + model.altitude_count:
            multipliers = self.workspace(model, state)
            multipliers.value.fill(0)
            multipliers.altitude.fill(0)
            sweep(xpbd_springs, model, state, self.iterations, multipliers.value,
                  multipliers.altitude, dt, forces.tearable)
        update_velocity(model, state, dt, step_index)
        if model.spring_count and model.relative_damping:
            sweep(damp_springs, model, state, 1, dt, forces.tearable)
        state.prev_valid = False
