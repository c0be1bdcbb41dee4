"""Extended position-based dynamics (Macklin, Mueller & Chentanez 2016): springs as compliant
constraints with compliance 1 / k, so the cloth has its material stiffness in N/m."""


import taichi as ti

from .. import backend, limits
from .._validate import count
from ..constraints import damp_springs, sweep, xpbd_springs
from ..forces import compute_forces
from .base import Integrator
from .pbd import update_velocity


@ti.kernel
def _predict(model: ti.template(), state: ti.template(), dt: float):
    """x~ = x_n + h (v_n + h M^-1 f_ext); x_n is kept in particle_prev_position."""
    for i in range(model.particle_count):
        x = state.particle_position[i]
        v = state.particle_velocity[i] + dt * model.particle_inv_mass[i] * state.particle_force[i]
        state.particle_prev_position[i] = x
        state.particle_position[i] = x + dt * v


class _Multipliers:
    """One Lagrange multiplier per spring and per altitude spring [N s^2], reset every step."""

    def __init__(self, spring_count: int, altitude_count: int):
        fields = backend.FieldGroup()
        self.value = fields.scalar(backend.real(), max(spring_count, 1))
        self.altitude = fields.scalar(backend.real(), max(altitude_count, 1))
        fields.finalize(self)


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

    def __init__(self, *, iterations: int = 10):
        self.iterations = count("XPBD.iterations", iterations, limits.ITERATIONS)

    def options(self):
        return {"iterations": self.iterations}

    def step(self, model, state, dt, forces, step_index):
        compute_forces(model, state, forces, springs=False)   # external forces only
        _predict(model, state, dt)
        if model.spring_count + model.altitude_count:
            multipliers = self.buffers(state, lambda: _Multipliers(model.spring_count,
                                                                   model.altitude_count))
            multipliers.value.fill(0)
            multipliers.altitude.fill(0)
            sweep(xpbd_springs, model, state, self.iterations, multipliers.value,
                  multipliers.altitude, dt, forces.tearable)
        update_velocity(model, state, dt, step_index)
        if model.spring_count and model.relative_damping:
            sweep(damp_springs, model, state, 1, dt, forces.tearable)
        state.prev_valid = False
