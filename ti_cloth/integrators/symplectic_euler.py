"""Symplectic (semi-implicit) Euler."""


import math

import taichi as ti

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
    def move(self, model: ti.template(), state: ti.template(), i, f, dt, step, start):
        v = state.particle_velocity[i] + dt * model.particle_inv_mass[i] * f   # f = f(x_n, v_n)
        store_particle(state, i, state.particle_position[i] + dt * v, v, step)  # with v_{n+1}

    def mode_stable_step(self, w2, g):
        return leapfrog_stable_step(w2, g)


def leapfrog_stable_step(w2: float, g: float) -> float:
    """h < (sqrt(g^2 + 4 w^2) - g) / w^2 (= 2 / w undamped): where the update matrix of
    symplectic Euler (and of Verlet, the same map) keeps a mode of angular frequency w and
    damping rate g bounded."""
    return (math.sqrt(g * g + 4.0 * w2) - g) / w2
