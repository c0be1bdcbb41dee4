"""Explicit (forward) Euler, Stuyck eq. 4.8-4.9."""


import math

import numpy as np
import taichi as ti

from ..body.modes import row_bounds, stiffest_mode
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

    def stable_step(self, cloth, drag, pinned):
        """h < g / w^2 per mode (the smaller root (g - sqrt(g^2 - 4 w^2)) / w^2 when
        overdamped), and h < 2 / g for a mode damped but barely sprung (relative damping damps
        sideways motion that the springs do not resist: v' = (1 - h g) v). The worst sprung
        mode is the least damped relative to its stiffness, not the stiffest, so the first
        takes the smallest ratio over the per-particle Gershgorin bounds (modes.row_bounds);
        the second the largest damping rate (modes.stiffest_mode). 0 when some stiff particle
        has no damping. On demos/stuyck_explicit.toml: 4.3e-4 s, measured 5.2e-4 s (the
        first rule alone said 6.3e-4 s, where it diverges)."""
        omega2, gamma = row_bounds(cloth, drag, pinned)
        stiff = omega2 > 0
        if not stiff.any():
            return math.inf
        w2, g = omega2[stiff], gamma[stiff]
        sprung = float(np.min((g - np.sqrt(np.maximum(g * g - 4.0 * w2, 0.0))) / w2))
        _, most_damped = stiffest_mode(cloth, drag, pinned)
        return min(sprung, 2.0 / most_damped) if most_damped > 0 else sprung
