"""TR-BDF2: second order and L-stable, two implicit stages per step (Bank et al. 1985; Hosea &
Shampine 1996, "Analysis and implementation of TR-BDF2").

With gamma = 2 - sqrt(2), the first stage is a second-order step over gamma h (implicit
midpoint here, which is the trapezoidal rule on linear forces: the same stability function),
and the second is BDF2 on the unequally spaced points t_n, t_n + gamma h, t_n + h:

    x_{n+1} = a x_gamma - b x_n + s v_{n+1},   v_{n+1} = a v_gamma - b v_n + s M^-1 f_{n+1},

a = 1 / (gamma (2 - gamma)), b = (1 - gamma)^2 / (gamma (2 - gamma)), s = (1 - gamma) /
(2 - gamma) h. For this gamma both stages are backward Euler sub-steps of the same length
s = gamma h / 2 (the midpoint's half of gamma h; the BDF2 stage's s), each solved by Newton's
method from its origin (newton.py). On y' = lambda y, z = h lambda, a step multiplies y by

    R(z) = (a T(z) - b) / (1 - gamma z / 2),   T(z) = (1 + gamma z / 2) / (1 - gamma z / 2),

which tends to 0 as |z| grows (L-stable: tests/test_second_order_implicit.py checks a spring
chain's mode against it): a mode too stiff for the step dies out within it, as physical
damping would have it die; modes the step resolves keep their amplitude to O((w h)^3) per
step (docs/integrators.md).
"""

import math

import taichi as ti

from ..runtime.plan import ITEM, NOW, STATE, Loop, Once, Phase, Repeat, substep
from ..state import store_particle
from . import newton
from .conjugate_gradients import ROW, STAGE

GAMMA = 2.0 - math.sqrt(2.0)
A = 1.0 / (GAMMA * (2.0 - GAMMA))               # BDF2's weights on x_gamma and x_n
B = (1.0 - GAMMA) ** 2 / (GAMMA * (2.0 - GAMMA))
FRACTION = GAMMA / 2.0                           # s / h of both stages


@ti.func
def _first_stage(ws: ti.template(), now: ti.template()):
    """The step's first stage comes next (STAGE: the stage's index, on the worker's row)."""
    ws.iterations[now.row * ROW + STAGE] = 0


@ti.func
def _next_stage(ws: ti.template(), now: ti.template()):
    ws.iterations[now.row * ROW + STAGE] = ws.iterations[now.row * ROW + STAGE] + 1


@ti.func
def _origin(model: ti.template(), state: ti.template(), ws: ti.template(), i,
            now: ti.template()):
    """The stage's origin and predictor. The midpoint stage keeps (x_n, v_n) and starts
    from them; the BDF2 stage takes the midpoint stage's end x_gamma = 2 x_mid - x_n and
    starts from a x_gamma - b x_n = x_n + a (x_gamma - x_n) (a - b = 1; the second form
    leaves a particle that did not move exactly where it was), likewise for velocities."""
    if ws.iterations[now.row * ROW + STAGE] == 0:
        x, v = state.particle_position[i], state.particle_velocity[i]
        ws.step_position[i] = x
        ws.step_velocity[i] = v
        ws.origin_position[i] = x
        ws.origin_velocity[i] = v
    else:
        x_n, v_n = ws.step_position[i], ws.step_velocity[i]
        ws.origin_position[i] = x_n + A * 2.0 * (state.particle_position[i] - x_n)
        ws.origin_velocity[i] = v_n + A * 2.0 * (state.particle_velocity[i] - v_n)
    newton.predict(model, state, ws, i, now)


@ti.func
def _finish(state: ti.template(), i, now: ti.template()):
    """The step ends on the BDF2 stage's solution (the divergence guard sees it)."""
    store_particle(state, i, state.particle_position[i], state.particle_velocity[i], now.step)


class TRBDF2(newton.NewtonIntegrator):
    """TR-BDF2 (module doc), both stages solved by Newton's method.

    tolerance, most_newton, cg_tolerance, most_cg: each Newton solve's
        (newton.NewtonSettings). last_newton and last_cg report the latest solve's iterations.
    Order 2. L-stable: stable at any step, the stiffest modes damped out.
    """

    name = "tr_bdf2"
    order = 2
    solves = 2

    def phases(self, model, forces, ws):
        """The midpoint stage, then the BDF2 stage, each its origin and its Newton solve (one
        solve in the kernel, run twice: the stages' sub-steps are of one length), the
        guard."""
        n = model.particle_count
        stage = ((Phase(Loop(n, _origin, model, STATE, ws, ITEM, NOW)),)
                 + newton.solve(model, forces, ws) + (Once(_next_stage, ws, NOW),))
        return substep(FRACTION, (Once(_first_stage, ws, NOW), Repeat(2, *stage),
                                  Phase(Loop(n, _finish, STATE, ITEM, NOW))))
