"""The fused integrators' step (those that define `Integrator.move`): the wind, every spring's
force, evaluated once (forces.py); then every particle's gathered force, and its move.

Written once as phases (runtime/plan.py): a launch per phase runs the spring loop and the
particle loop as two parallel loops of one kernel (GPUs take this plan, and so does a CPU run
of step(1)); many steps per launch (stepping.py, CPU) give each worker its slice of the springs,
a barrier, its slice of the particles, a barrier. There a particle also meets the colliders as
soon as it has moved, when the launch's stages allow (stepping.TeamStages.collides_on_move):
the collision stage touches nothing but the particle, so it gives the same bits as a pass of
its own, without one.

Every plan evaluates each spring and moves each particle with the same formula and gathers in
the same order, with exact IEEE arithmetic (runtime/backend.py), so every plan gives the same
bits.
"""


import taichi as ti

from ..inputs import limits
from ..physics import wind
from ..physics.forces import gather_force, spring_phases
from ..runtime.plan import ITEM, NOW, STAGES, STATE, Loop, Phase


@ti.func
def move_particle(model: ti.template(), state: ti.template(), forces: ti.template(),
                  stages: ti.template(), i, now: ti.template(), integrator: ti.template()):
    """Gather particle i's total force (springs already evaluated), keep it in
    particle_force, and move it (integrator.move); then, when stages.collides_on_move, its
    collision stage (stages.collide: the particle and where it was at the step's start)."""
    f = gather_force(model, state, forces, i, True)
    state.particle_force[i] = f
    if ti.static(stages.collides_on_move):
        x0 = state.particle_position[i]
        integrator.move(model, state, i, f, now.dt, now.step, now.start)
        stages.collide(model, state, i, x0, now.dt)
    else:
        integrator.move(model, state, i, f, now.dt, now.step, now.start)


def phases(integrator, model, forces) -> tuple:
    """A fused integrator's step: the wind, the springs, every particle's move."""
    return (wind.phases(model, forces) + spring_phases(model, forces)
            + (Phase(Loop(model.particle_count, move_particle, model, STATE, forces, STAGES, ITEM,
                          NOW, integrator)),))


def spring_work(model) -> int:
    """A step's work in springs (limits.spring_equivalents)."""
    return limits.spring_equivalents(model)
