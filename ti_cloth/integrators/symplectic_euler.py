"""Symplectic (semi-implicit) Euler."""


import taichi as ti

from ..forces import compute_forces
from ..state import store_particle
from .base import Integrator


@ti.kernel
def _advance(model: ti.template(), state: ti.template(), dt: float, step: ti.i32):
    for i in range(model.particle_count):
        v = state.particle_velocity[i] + dt * model.particle_inv_mass[i] * state.particle_force[i]
        store_particle(state, i, state.particle_position[i] + dt * v, v, step)


class SymplecticEuler(Integrator):
    """v_{n+1} = v_n + h M^-1 f(x_n, v_n), then x_{n+1} = x_n + h v_{n+1}.

    Order 1. Symplectic: for conservative forces energy oscillates but does not drift.
    Stability: an undamped mode of angular frequency w needs h < 2 / w; with damping rate g,
    h < (sqrt(g^2 + 4 w^2) - g) / w^2.
    """

    name = "symplectic_euler"
    order = 1

    def step(self, model, state, dt, forces, step):
        compute_forces(model, state, forces)   # gravity, springs, damping, drag at (x_n, v_n)
        _advance(model, state, dt, step)       # velocity first, then position with the new velocity
