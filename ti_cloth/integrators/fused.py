"""The fused integrators' step (those that define `Integrator.move`): every spring's force,
evaluated once (forces.py); then every particle's gathered force, and its move.

One step per launch (`advance_one`): the two loops run in parallel. GPUs take this plan, and so
does a CPU run of step(1). Many steps per launch (stepping.py, CPU) run `team_step`: a
worker's slice of the springs, a barrier, its slice of the particles, a barrier. There a
particle also meets the colliders as soon as it has moved, when the launch's stages allow
(stepping.TeamStages.collides_on_move): the collision stage touches nothing but the particle,
so it gives the same bits as a pass of its own, without one.

Every plan evaluates each spring and moves each particle with the same formula and gathers in
the same order, so explicit and symplectic Euler give the same bits in every plan. Verlet's
results, and those of bodies with altitude springs, agree to rounding between a launch per step
and many: fast math lets LLVM contract Verlet's three-term update and an altitude spring's
cross and dot products differently in different kernels, and exact IEEE math would cost 40 %
at 32 x 32. A team and one worker run the same kernel, so thread counts never change a bit.
"""


import taichi as ti

from ..physics.forces import blow, evaluate_altitudes, evaluate_springs, gather_force
from ..runtime import backend, limits


@ti.func
def move_particles(integrator: ti.template(), model: ti.template(), state: ti.template(),
                   forces: ti.template(), stages: ti.template(), dt, step, start, begin, end):
    """Gather the total force of particles begin .. end - 1 (springs already evaluated), keep
    it in particle_force, and move them; then, when stages.collides_on_move, their collision
    stage (stages.collide: the particle and where it was at the step's start)."""
    for i in range(begin, end):
        f = gather_force(model, state, forces, i, True)
        state.particle_force[i] = f
        if ti.static(stages.collides_on_move):
            x0 = state.particle_position[i]
            integrator.move(model, state, i, f, dt, step, start)
            stages.collide(model, state, i, x0, dt)
        else:
            integrator.move(model, state, i, f, dt, step, start)


@backend.kernel_argument
class _Stageless:
    """No stage in the particle loop (a launch per stage)."""

    collides_on_move = False


STAGELESS = _Stageless()


@backend.kernel
def advance_one(integrator: ti.template(), model: ti.template(), state: ti.template(),
                forces: ti.template(), dt: float, step: ti.i32, start: ti.i32):
    """One step, its loops in parallel. start: 1 if the state has no history yet."""
    evaluate_springs(model, state, forces.tearable, 0, model.spring_count)
    evaluate_altitudes(model, state, 0, model.altitude_count)
    move_particles(integrator, model, state, forces, STAGELESS, dt, step, start, 0,
                   model.particle_count)


@ti.func
def team_step(integrator: ti.template(), model: ti.template(), state: ti.template(),
              forces: ti.template(), stages: ti.template(), team: ti.template(), worker, dt,
              step, start):
    """Worker `worker`'s share of one step (stepping.py): its slice of the springs, a
    barrier (every spring force is written), its slice of the particles (moved, and with
    `stages` collided: move_particles), a barrier."""
    s_begin, s_end = team.share(model.spring_count, worker)
    a_begin, a_end = team.share(model.altitude_count, worker)
    p_begin, p_end = team.share(model.particle_count, worker)
    evaluate_springs(model, state, forces.tearable, s_begin, s_end)
    evaluate_altitudes(model, state, a_begin, a_end)
    team.meet(worker)
    move_particles(integrator, model, state, forces, stages, dt, step, start, p_begin, p_end)
    team.meet(worker)


def step_once(integrator, model, state, forces, dt: float, step_index: int) -> None:
    """One step of a fused integrator: the wind (forces.blow), then one parallel launch."""
    blow(model, state, forces)
    advance_one(integrator, model, state, forces, dt, step_index, not state.prev_valid)
    state.prev_valid = integrator.records_history


def spring_work(model) -> int:
    """A step's work in springs (limits.ALTITUDE_SPRINGS per altitude spring)."""
    return model.spring_count + limits.ALTITUDE_SPRINGS * model.altitude_count
