"""Classical fourth-order Runge-Kutta on the first-order system x' = v, v' = M^-1 f(x, v)."""


import math

import taichi as ti

from ..physics.forces import compute_forces, evaluate_altitudes, evaluate_springs, gather_force
from ..runtime import backend
from ..state import store_particle
from . import fused
from .base import Integrator

# Stage weights of the classical tableau: the sum is k1 + 2 k2 + 2 k3 + k4, and stage s+1 is
# evaluated at y0 + NEXT[s] h k_s.
WEIGHTS = (1.0, 2.0, 2.0, 1.0)
NEXT = (0.5, 0.5, 1.0)
RK4_IMAGINARY = 2.0 * math.sqrt(2.0)   # |1 + z + z^2/2 + z^3/6 + z^4/24| <= 1 on z = iy, |y| <= this
RK4_RADIUS = 2.61                      # a left half-disc of this radius lies in RK4's region (min 2.6156)


@backend.kernel_argument
class _Stages:
    """Start-of-step state and the running weighted sum of the stage derivatives."""

    def __init__(self, particle_count: int):
        real = backend.real()
        fields = backend.FieldGroup()
        self.x0 = fields.vector(3, real, particle_count)
        self.v0 = fields.vector(3, real, particle_count)
        self.sum_x = fields.vector(3, real, particle_count)
        self.sum_v = fields.vector(3, real, particle_count)
        fields.finalize(self)


@backend.kernel
def rk4_stage(model: ti.template(), state: ti.template(), stages: ti.template(), dt: float,
           stage: ti.template(), step: ti.i32):
    for i in range(model.particle_count):
        _stage_particle(model, state, stages, i, dt, stage, step)


@ti.func
def _stage_particle(model: ti.template(), state: ti.template(), stages: ti.template(), i, dt,
                    stage: ti.template(), step):
    """Stage k = (v, M^-1 f) of particle i at the current state: add it, weighted, to the
    sums; move the particle to where the next stage is evaluated, or (last stage) to the
    step's result."""
    kx = state.particle_velocity[i]
    kv = model.particle_inv_mass[i] * state.particle_force[i]
    if ti.static(stage == 0):
        stages.x0[i] = state.particle_position[i]
        stages.v0[i] = kx
        stages.sum_x[i] = kx
        stages.sum_v[i] = kv
    else:
        stages.sum_x[i] = stages.sum_x[i] + ti.static(WEIGHTS[stage]) * kx
        stages.sum_v[i] = stages.sum_v[i] + ti.static(WEIGHTS[stage]) * kv
    if ti.static(stage < 3):
        state.particle_position[i] = stages.x0[i] + ti.static(NEXT[stage]) * dt * kx
        state.particle_velocity[i] = stages.v0[i] + ti.static(NEXT[stage]) * dt * kv
    else:
        store_particle(state, i, stages.x0[i] + dt / 6.0 * stages.sum_x[i],
                       stages.v0[i] + dt / 6.0 * stages.sum_v[i], step)


class RK4(Integrator):
    """Classical Runge-Kutta: four force evaluations per step, weights 1, 2, 2, 1 / 6.

    Order 4 for smooth forces (it is the reference integrator of accuracy studies). Not
    symplectic: undamped energy drifts slowly (down, at stable steps). Stability: an undamped
    mode of angular frequency w needs h < 2.83 / w (the imaginary-axis reach of its stability
    region, 2 sqrt(2)), about 1.4 x the symplectic Euler limit, at 4 x the cost per step.
    """

    name = "rk4"
    order = 4
    teamed = True
    wind_once = False

    def workspace(self, model, state):
        return self.buffers(state, lambda: _Stages(model.particle_count))

    def step_work(self, model):
        return 4 * fused.spring_work(model)

    @ti.func
    def team_step(self, model: ti.template(), state: ti.template(), forces: ti.template(),
                  work: ti.template(), stages: ti.template(), team: ti.template(), worker, dt,
                  step, start):
        """step()'s four force evaluations and stage updates as phases of one worker's
        share, meeting the team after each."""
        s_begin, s_end = team.share(model.spring_count, worker)
        a_begin, a_end = team.share(model.altitude_count, worker)
        p_begin, p_end = team.share(model.particle_count, worker)
        for stage in ti.static(range(4)):
            evaluate_springs(model, state, forces.tearable, s_begin, s_end)
            evaluate_altitudes(model, state, a_begin, a_end)
            team.meet(worker)
            for i in range(p_begin, p_end):
                state.particle_force[i] = gather_force(model, state, forces, i, True)
                _stage_particle(model, state, work, i, dt, stage, step)
            team.meet(worker)

    def step(self, model, state, dt, forces, step_index):
        stages = self.workspace(model, state)
        for s in range(4):
            compute_forces(model, state, forces)    # f at stage s (x0 and v0 for s = 0)
            rk4_stage(model, state, stages, dt, s, step_index)
        state.prev_valid = False

    def mode_stable_step(self, w2, g):
        """h |lambda| within the stability region: 2 sqrt(2) / w undamped (the region's reach up
        the imaginary axis), else RK4_RADIUS / |lambda|, |lambda| the mode's largest eigenvalue
        modulus."""
        largest = max(math.sqrt(w2), 0.5 * g + math.sqrt(max(0.25 * g * g - w2, 0.0)))
        return (RK4_RADIUS if g > 0 else RK4_IMAGINARY) / largest
