"""Launch plans for integrators that write a whole step as one ti.func (`Integrator.advance`).

One step per launch: the step's loops (springs, then particles) run in parallel. Many steps per
launch (`advance_many`): the same loops run serially inside one loop over the steps, so a run of
steps pays one kernel launch instead of one per step. Both give the same bits for explicit and
symplectic Euler; Verlet's agree to rounding (Taichi's fast math lets LLVM contract its
three-term update differently in the two kernels; exact IEEE math would cost 40 % at 32 x 32).

On a 2-core CPU a parallel loop costs ~50 us to start and a launch with template arguments
~25 us, while a serial step of a 32 x 32 cloth (5.8k springs) takes ~30 us: small cloths are
launch-bound and run serially; large ones (more than SERIAL_SPRING_LIMIT springs) run a
parallel launch per step. GPUs always take a launch per step.
"""


import taichi as ti

from . import backend
from .state import NO_BAD_STEP
from .tearing import tear_overstretched
from .wind import accumulate_wind

SERIAL_SPRING_LIMIT = 50_000   # serial faster at 24k springs, parallel at 97k (measured)
MAX_STEPS_PER_LAUNCH = 256     # bounds one launch (Ctrl-C and the divergence check wait for it)


def serial_is_faster(model) -> bool:
    """Whether this model's loops run faster serially in one launch (CPU and few springs)."""
    return backend.config().arch == "cpu" and model.spring_count <= SERIAL_SPRING_LIMIT


@ti.kernel
def advance_one(integrator: ti.template(), model: ti.template(), state: ti.template(),
                forces: ti.template(), dt: float, step: ti.i32, start: ti.i32):
    """One step, its loops in parallel. start: 1 if the state has no history yet."""
    integrator.advance(model, state, forces, dt, step, start)


@ti.kernel
def advance_many(integrator: ti.template(), model: ti.template(), state: ti.template(),
                 forces: ti.template(), dt: float, first: ti.i32, count: ti.i32, start: ti.i32,
                 tear_stretch: float):
    """Steps first .. first + count - 1 serially, each followed by tearing when it is on
    (Simulation.step's order when no other feature acts between steps)."""
    ti.loop_config(serialize=True)
    for k in range(count):
        integrator.advance(model, state, forces, dt, first + k, ti.i32(start != 0 and k == 0))
        if ti.static(forces.tearing):
            tear_overstretched(model, state, tear_stretch, first + k)


def step_once(integrator, model, state, forces, dt: float, step: int) -> None:
    """One step of a fused integrator: the wind's kernel if any, then one parallel launch."""
    if forces.wind is not None:
        accumulate_wind(model, state, forces.wind, forces.tearing)
    advance_one(integrator, model, state, forces, dt, step, not state.prev_valid)
    state.prev_valid = integrator.records_history


def step_many(integrator, model, state, forces, dt: float, first: int, count: int,
              tear_stretch: float) -> int:
    """Up to `count` steps of a fused integrator, each followed by tearing when forces.tearing,
    MAX_STEPS_PER_LAUNCH per serial launch; stops after the launch in which a step diverged.
    Returns how many steps ran. Needs forces.wind None (the wind is set between steps)."""
    done = 0
    while done < count and state.first_bad_step[None] == NO_BAD_STEP:
        chunk = min(MAX_STEPS_PER_LAUNCH, count - done)
        advance_many(integrator, model, state, forces, dt, first + done, chunk,
                     not state.prev_valid, tear_stretch)
        state.prev_valid = integrator.records_history
        done += chunk
    return done
