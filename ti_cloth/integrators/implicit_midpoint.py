"""Implicit midpoint: second order, symplectic, no numerical damping, stable at any step.

    x_{n+1} = x_n + h v_{n+1/2},   v_{n+1} = v_n + h M^-1 f(x_{n+1/2}, v_{n+1/2}),

with x_{n+1/2} = (x_n + x_{n+1}) / 2 and v_{n+1/2} = (v_n + v_{n+1}) / 2. The midpoint is a
backward Euler step of h/2 from (x_n, v_n), solved to convergence by Newton's method
(newton.py), and the step its extrapolation, x_{n+1} = 2 x_{n+1/2} - x_n (Hairer, Lubich &
Wanner, Geometric Numerical Integration, 2006, sec. II.1 and VI.3). On linear springs it keeps
every mode's amplitude exactly (|R(ih w)| = 1) and delays its phase by about (h w)^2 / 12 per
radian: the stiff membrane modes a large step cannot follow ring on instead of dying out.
"""

import taichi as ti

from ..runtime.plan import ITEM, NOW, STATE, Loop, Phase, substep
from ..state import store_particle
from . import newton


@ti.func
def _origin(model: ti.template(), state: ti.template(), ws: ti.template(), i,
            now: ti.template()):
    """The half step's origin (x_n, v_n), and its predictor."""
    ws.origin_position[i] = state.particle_position[i]
    ws.origin_velocity[i] = state.particle_velocity[i]
    newton.predict(model, state, ws, i, now)


@ti.func
def _extrapolate(state: ti.template(), ws: ti.template(), i, now: ti.template()):
    """x_{n+1} = 2 x_{n+1/2} - x_n, v_{n+1} = 2 v_{n+1/2} - v_n."""
    x = 2.0 * state.particle_position[i] - ws.origin_position[i]
    v = 2.0 * state.particle_velocity[i] - ws.origin_velocity[i]
    store_particle(state, i, x, v, now.step)


class ImplicitMidpoint(newton.NewtonIntegrator):
    """Implicit midpoint (module doc), its half step solved by Newton's method.

    tolerance, most_newton, cg_tolerance, most_cg: the Newton solve's (newton.NewtonSettings).
    last_newton and last_cg report the latest solve's iterations.
    Order 2. Stable at any step on linear springs, without numerical damping.
    """

    name = "implicit_midpoint"
    order = 2
    solves = 1

    def phases(self, model, forces, ws):
        """The origin and predictor, the half step's Newton solve, the extrapolation."""
        n = model.particle_count
        return substep(0.5, (Phase(Loop(n, _origin, model, STATE, ws, ITEM, NOW)),)
                       + newton.solve(model, forces, ws)
                       + (Phase(Loop(n, _extrapolate, STATE, ws, ITEM, NOW)),))
