"""Position Verlet with forces, with the lecture's optional damping factor."""


import taichi as ti

from ..inputs.validation import finite_number, require
from ..state import store_particle
from .base import Integrator
from .symplectic_euler import leapfrog_stable_step


@ti.func
def verlet_update(state: ti.template(), i, a, dt, damping, start, step):
    """Move particle i by x_{n+1} = x_n + (1 - d)(x_n - x_{n-1}) + h^2 a (lecture: 2 -> 1.99,
    1 -> 0.99 at d = 0.01), or with no history (start) by the second-order first step
    x_1 = x_0 + (1 - d) h v_0 + h^2/2 a; keep x_n as history; v = (x_{n+1} - x_n) / h."""
    x = state.particle_position[i]
    x_new = x + (1.0 - damping) * (x - state.particle_prev_position[i]) + dt * dt * a
    if start:
        x_new = x + (1.0 - damping) * dt * state.particle_velocity[i] + 0.5 * dt * dt * a
    state.particle_prev_position[i] = x
    store_particle(state, i, x_new, (x_new - x) / dt, step)


class Verlet(Integrator):
    """Position (Stormer) Verlet driven by all forces.

    damping: d in [0, 1); the lecture's 1.99 / 0.99 factors are d = 0.01. It removes the
        fraction d of the velocity each step, so its effect depends on h.
    Order 2 for forces that depend on positions only; velocity-dependent forces (spring damping,
    drag) see the backward-difference velocity and make it first order. Stability: an undamped
    mode of angular frequency w needs h < 2 / w, as symplectic Euler.
    """

    name = "verlet"
    order = 2
    fused = True
    records_history = True

    def __init__(self, *, damping: float = 0.0):
        self.damping = finite_number("Verlet.damping", damping, 0.0)
        require(self.damping < 1.0, "Verlet.damping", damping, "a number in [0, 1)")

    def options(self):
        return {"damping": self.damping}

    @ti.func
    def move(self, model: ti.template(), state: ti.template(), i, f, dt, step, start):
        # f at x_n and the velocity (x_n - x_{n-1}) / h
        verlet_update(state, i, model.particle_inv_mass[i] * f, dt, self.damping, start, step)

    def mode_stable_step(self, w2, g):
        return leapfrog_stable_step(w2, g)
