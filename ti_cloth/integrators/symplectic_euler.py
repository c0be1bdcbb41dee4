"""Symplectic (semi-implicit) Euler."""


import taichi as ti

from ..forces import evaluate_springs, particle_force
from ..state import store_particle
from .base import Integrator


class SymplecticEuler(Integrator):
    """v_{n+1} = v_n + h M^-1 f(x_n, v_n), then x_{n+1} = x_n + h v_{n+1}.

    Order 1. Symplectic: for conservative forces energy oscillates but does not drift.
    Stability: an undamped mode of angular frequency w needs h < 2 / w; with damping rate g,
    h < (sqrt(g^2 + 4 w^2) - g) / w^2.
    """

    name = "symplectic_euler"
    order = 1
    fused = True

    @ti.func
    def advance(self, model: ti.template(), state: ti.template(), forces: ti.template(), dt, step,
                start):
        evaluate_springs(model, state, forces.tearing)   # spring forces at (x_n, v_n)
        for i in range(model.particle_count):             # velocity first, then position with it
            f = particle_force(model, state, forces, i, True)
            state.particle_force[i] = f
            v = state.particle_velocity[i] + dt * model.particle_inv_mass[i] * f
            store_particle(state, i, state.particle_position[i] + dt * v, v, step)
