"""Classical fourth-order Runge-Kutta on the first-order system x' = v, v' = M^-1 f(x, v)."""


import math

import taichi as ti

from ..physics import wind
from ..physics.forces import gather_force, spring_phases
from ..runtime import backend
from ..runtime.plan import ITEM, NOW, STATE, Loop, Once, Phase, Repeat
from ..runtime.team import MAX_WORKERS
from ..state import store_particle
from . import fused
from .base import Integrator

# The classical tableau: the step adds (k1 + 2 k2 + 2 k3 + k4) h / 6, and stage s+1 is
# evaluated at y0 + (0.5, 0.5, 1.0)[s] h k_s (rk4_stage's branches).
RK4_IMAGINARY = 2.0 * math.sqrt(2.0)   # |1 + z + z^2/2 + z^3/6 + z^4/24| <= 1 on z = iy, |y| <= this
RK4_RADIUS = 2.61                      # a left half-disc of this radius lies in RK4's region (min 2.6156)
ROW = 16                               # slots per worker in the stage counter (a cache line each)


@backend.kernel_argument
class _Stages:
    """Start-of-step state, the running weighted sum of the stage derivatives, and each
    worker's count of the stages done in this step."""

    def __init__(self, particle_count: int):
        real = backend.real()
        fields = backend.FieldGroup()
        self.x0 = fields.vector(3, real, particle_count)
        self.v0 = fields.vector(3, real, particle_count)
        self.sum_x = fields.vector(3, real, particle_count)
        self.sum_v = fields.vector(3, real, particle_count)
        self.stage = fields.scalar(ti.i32, MAX_WORKERS * ROW)
        fields.finalize(self)


@ti.func
def rk4_stage(model: ti.template(), state: ti.template(), forces: ti.template(),
              work: ti.template(), i, now: ti.template()):
    """Stage k = (v, M^-1 f) of particle i at the current state (its total force gathered
    and kept in particle_force): add it, weighted, to the sums; move the particle to where
    the next stage is evaluated, or (last stage) to the step's result. The stage (0 to 3) is
    the worker's count."""
    stage = work.stage[now.row * ROW]
    state.particle_force[i] = gather_force(model, state, forces, i, True)
    dt = now.dt
    kx = state.particle_velocity[i]
    kv = model.particle_inv_mass[i] * state.particle_force[i]
    if stage == 0:
        work.x0[i] = state.particle_position[i]
        work.v0[i] = kx
        work.sum_x[i] = kx
        work.sum_v[i] = kv
    else:
        weight = 1.0 if stage == 3 else 2.0
        work.sum_x[i] = work.sum_x[i] + weight * kx
        work.sum_v[i] = work.sum_v[i] + weight * kv
    if stage < 3:
        ahead = 1.0 if stage == 2 else 0.5
        state.particle_position[i] = work.x0[i] + ahead * dt * kx
        state.particle_velocity[i] = work.v0[i] + ahead * dt * kv
    else:
        store_particle(state, i, work.x0[i] + dt / 6.0 * work.sum_x[i],
                       work.v0[i] + dt / 6.0 * work.sum_v[i], now.step)


@ti.func
def first_stage(work: ti.template(), now: ti.template()):
    work.stage[now.row * ROW] = 0


@ti.func
def next_stage(work: ti.template(), now: ti.template()):
    work.stage[now.row * ROW] = work.stage[now.row * ROW] + 1


class RK4(Integrator):
    """Classical Runge-Kutta: four force evaluations per step, weights 1, 2, 2, 1 / 6.

    Order 4 for smooth forces (it is the reference integrator of accuracy studies). Not
    symplectic: undamped energy drifts slowly (down, at stable steps). Stability: an undamped
    mode of angular frequency w needs h < 2.83 / w (the imaginary-axis reach of its stability
    region, 2 sqrt(2)), about 1.4 x the symplectic Euler limit, at 4 x the cost per step.
    """

    name = "rk4"
    order = 4

    def workspace(self, model, state):
        return self.buffers(state, lambda: _Stages(model.particle_count))

    def step_work(self, model):
        return 4 * fused.spring_work(model)

    def phases(self, model, forces, work):
        """Four times: the wind and the springs at the stage's state, then every particle's
        stage (work: the _Stages), counted per worker: the stage is compiled once, not four
        times (a Fabric's rk4 step compiled in 26 s unrolled)."""
        stage = (wind.phases(model, forces) + spring_phases(model, forces)
                 + (Phase(Loop(model.particle_count, rk4_stage, model, STATE, forces, work, ITEM,
                               NOW)),
                    Once(next_stage, work, NOW)))
        return (Once(first_stage, work, NOW), Repeat(4, *stage))

    def mode_stable_step(self, w2, g):
        """h |lambda| within the stability region: 2 sqrt(2) / w undamped (the region's reach up
        the imaginary axis), else RK4_RADIUS / |lambda|, |lambda| the mode's largest eigenvalue
        modulus."""
        largest = max(math.sqrt(w2), 0.5 * g + math.sqrt(max(0.25 * g * g - w2, 0.0)))
        return (RK4_RADIUS if g > 0 else RK4_IMAGINARY) / largest
