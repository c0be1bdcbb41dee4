"""Explicit (forward) Euler, Stuyck eq. 4.8-4.9."""


import taichi as ti

from ..state import store_particle
from .base import Integrator


class ExplicitEuler(Integrator):
    """x_{n+1} = x_n + h v_n, v_{n+1} = v_n + h M^-1 f(x_n, v_n) (Stuyck eq. 4.8-4.9).

    Order 1. Stability: an undamped spring mode gains energy by the factor (1 + h^2 w^2) every
    step at any h, so undamped cloth always blows up eventually; a mode of angular frequency
    w and damping rate g is stable only for h < g / w^2.
    """

    name = "explicit_euler"
    order = 1
    fused = True

    @ti.func
    def move(self, model: ti.template(), state: ti.template(), i, f, dt, step, start):
        x = state.particle_position[i]                     # f = f(x_n, v_n)
        v = state.particle_velocity[i]
        dv = dt * model.particle_inv_mass[i] * f           # eq. 4.8: h M^-1 f(x_n, v_n)
        store_particle(state, i, x + dt * v, v + dv, step)  # eq. 4.9, dx = h v_n
