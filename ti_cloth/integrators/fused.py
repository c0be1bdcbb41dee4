"""Launch plans for the fused integrators (those that define `Integrator.move`). A step is: every
spring's force, evaluated once (forces.py); then every particle's gathered force, and its move.
Of the stages Simulation runs after the integrator (simulation.STEP_ORDER), the many-steps plan
fuses only tearing (FUSED_STAGES): a simulation with any other stage steps one launch at a time.

One step per launch (`advance_one`): the two loops run in parallel. GPUs take this plan, and so
does a CPU run when something acts between steps (wind, colliders, handles, strain limiting).

Many steps per launch (`ManySteps`, CPU only). On the 2-core CPU these figures were measured on,
a launch costs 10 to 25 us and every parallel loop another 15 to 50 us (the thread pool waking,
up to milliseconds after the machine idled), while the arithmetic of a 32 x 32 cloth's step is
about 30 us. So a run of steps is one launch, shared by a `Team`:
- one worker runs every loop serially on the launching thread, for short runs of small
  cloths, where waking the pool would cost more than sharing the work saves;
- otherwise one worker per Taichi CPU thread. Each owns a fixed slice of the springs and of the
  particles, and all of them meet at a barrier after the spring phase and after the particle
  phase (persistent threads, as inside an OpenMP parallel region), so the pool wakes once per
  launch instead of twice per step.

Every plan evaluates each spring and moves each particle with the same formula and gathers in
the same order, so explicit and symplectic Euler give the same bits in every plan. Verlet's
results, and those of bodies with altitude springs, agree to rounding between a launch per step
and many: fast math lets LLVM contract Verlet's three-term update and an altitude spring's
cross and dot products differently in different kernels, and exact IEEE math would cost 40 %
at 32 x 32. A team and one worker run the same kernel, so thread counts never change a bit.
"""


import taichi as ti

from .. import backend, limits
from ..errors import TeamStalled
from ..forces import evaluate_altitudes, evaluate_springs, gather_force
from ..state import NO_BAD_STEP
from ..tearing import tear_overstretched
from ..wind import accumulate_wind

FUSED_STAGES = ("integrator", "tearing")   # what one step of advance_many runs, in this order
MAX_STEPS_PER_LAUNCH = 4096    # bounds one launch (Ctrl-C and the divergence check wait for it)
SPRING_STEPS_PER_LAUNCH = 25_000_000   # about 0.1 s of one core's work: fewer steps for big cloths
TEAM_MIN_SPRING_STEPS = 1_000_000   # less work per launch runs on one worker (launch_plans.py)
TASK_SPACING = 512   # Taichi 1.7's CPU runtime makes each block of 512 indices of a parallel loop
                     # one task: worker w is index w * 512, so each worker is a task of its own
BARRIER_SPINS = 1 << 28   # polls (seconds) before a barrier gives up on a missing worker
STALLED = 1 << 29         # added to the barrier count by a worker that gave up


@backend.kernel_argument
class Team:
    """`workers` CPU workers that share the steps of one launch: each owns a fixed slice of
    every loop, and they meet at barriers. workers must not exceed Taichi's CPU threads, since
    a barrier waits for every worker and so each needs a thread of its own; one worker runs
    everything serially and its barriers compile to nothing.

    arrived: a scalar i32 field, the barrier arrivals in the current launch (+ STALLED once a
        barrier gave up); teams that never run at the same time may share one.
    """

    def __init__(self, workers: int, arrived):
        self.workers = workers
        self.arrived = arrived

    @ti.func
    def meet(self, count):
        """Barrier: wait until every worker has called meet `count` times in this launch. A
        worker that waits BARRIER_SPINS polls releases every barrier of the launch (the
        launch then finishes without synchronising, and `stalled` reports it)."""
        if ti.static(self.workers > 1):
            ti.atomic_add(self.arrived[None], 1)
            spins = 0
            while ti.atomic_add(self.arrived[None], 0) < count * self.workers:
                spins += 1
                if spins == BARRIER_SPINS:
                    ti.atomic_add(self.arrived[None], STALLED)

    @ti.func
    def share(self, count, worker):
        """Worker `worker`'s slice [begin, end) of `count` items."""
        return (ti.i32(ti.i64(worker) * count // self.workers),
                ti.i32(ti.i64(worker + 1) * count // self.workers))

    def stalled(self) -> bool:
        return self.workers > 1 and self.arrived[None] >= STALLED


@ti.func
def move_particles(integrator: ti.template(), model: ti.template(), state: ti.template(),
                   forces: ti.template(), dt, step, start, begin, end):
    """Gather the total force of particles begin .. end - 1 (springs already evaluated), keep
    it in particle_force, and move them."""
    for i in range(begin, end):
        f = gather_force(model, state, forces, i, True)
        state.particle_force[i] = f
        integrator.move(model, state, i, f, dt, step, start)


@ti.kernel
def advance_one(integrator: ti.template(), model: ti.template(), state: ti.template(),
                forces: ti.template(), dt: float, step: ti.i32, start: ti.i32):
    """One step, its loops in parallel. start: 1 if the state has no history yet."""
    evaluate_springs(model, state, forces.tearable, 0, model.spring_count)
    evaluate_altitudes(model, state, 0, model.altitude_count)
    move_particles(integrator, model, state, forces, dt, step, start, 0, model.particle_count)


@ti.func
def run_steps(integrator: ti.template(), model: ti.template(), state: ti.template(),
              forces: ti.template(), team: ti.template(), worker, dt, first, count, start,
              tear_stretch):
    """Worker `worker`'s share of steps first .. first + count - 1: each step is the
    FUSED_STAGES of simulation.STEP_ORDER, the integrator and then tearing when it is on."""
    s_begin, s_end = team.share(model.spring_count, worker)
    a_begin, a_end = team.share(model.altitude_count, worker)
    p_begin, p_end = team.share(model.particle_count, worker)
    for k in range(count):
        evaluate_springs(model, state, forces.tearable, s_begin, s_end)
        evaluate_altitudes(model, state, a_begin, a_end)
        team.meet(2 * k + 1)                  # every spring force of this step is written
        move_particles(integrator, model, state, forces, dt, first + k,
                       ti.i32(start != 0 and k == 0), p_begin, p_end)
        team.meet(2 * k + 2)                  # every particle has moved
        if ti.static(forces.tearable):
            tear_overstretched(model, state, tear_stretch, first + k, s_begin, s_end)


@ti.kernel
def advance_many(integrator: ti.template(), model: ti.template(), state: ti.template(),
                 forces: ti.template(), team: ti.template(), dt: float, first: ti.i32,
                 count: ti.i32, start: ti.i32, tear_stretch: float):
    """Steps first .. first + count - 1 in one launch, shared by `team`."""
    team.arrived[None] = 0
    if ti.static(team.workers == 1):
        ti.loop_config(serialize=True)
        for worker in range(1):
            run_steps(integrator, model, state, forces, team, worker, dt, first, count, start,
                      tear_stretch)
    else:
        for index in range(team.workers * TASK_SPACING):   # one task per worker
            if index % TASK_SPACING == 0:
                run_steps(integrator, model, state, forces, team, index // TASK_SPACING, dt,
                          first, count, start, tear_stretch)


def step_once(integrator, model, state, forces, dt: float, step_index: int) -> None:
    """One step of a fused integrator: the wind's kernel if any, then one parallel launch."""
    if forces.wind is not None:
        accumulate_wind(model, state, forces.wind, forces.tearable)
    advance_one(integrator, model, state, forces, dt, step_index, not state.prev_valid)
    state.prev_valid = integrator.records_history


def spring_work(model) -> int:
    """A step's work in springs (limits.ALTITUDE_SPRINGS per altitude spring)."""
    return model.spring_count + limits.ALTITUDE_SPRINGS * model.altitude_count


class ManySteps:
    """Runs many steps of a fused integrator on the CPU in few launches (nothing but tearing
    may act between them: the wind, for one, is set between steps).

    steps_per_launch: MAX_STEPS_PER_LAUNCH, or fewer for big cloths (SPRING_STEPS_PER_LAUNCH).
    A launch with less work than TEAM_MIN_SPRING_STEPS runs on one worker, a bigger one on a
    team of a worker per Taichi CPU thread (at most one per core).
    """

    def __init__(self, model):
        self.steps_per_launch = max(1, min(MAX_STEPS_PER_LAUNCH,
                                           SPRING_STEPS_PER_LAUNCH // max(spring_work(model), 1)))
        fields = backend.FieldGroup()
        arrived = fields.scalar(ti.i32, ())
        fields.finalize(self)
        # A worker per pool thread, but no more than the cores: a worker waiting at a barrier
        # for one that has no core to run on spins away its time slice.
        workers = min(backend.cpu_threads(), backend.cpu_cores())
        self.solo = Team(1, arrived)
        self.team = Team(workers, arrived) if workers > 1 else self.solo

    def team_for(self, model, steps: int) -> Team:
        """The team that runs a launch of `steps` steps."""
        return self.team if steps * spring_work(model) >= TEAM_MIN_SPRING_STEPS else self.solo

    def run(self, integrator, model, state, forces, dt: float, first: int, count: int,
            tear_stretch: float) -> int:
        """Up to `count` steps, each followed by tearing when forces.tearable; stops after the
        launch in which a step diverged. Returns how many steps ran. Raises TeamStalled if a
        barrier gave up on a worker (the state is then unusable)."""
        done = 0
        while done < count and state.first_bad_step[None] == NO_BAD_STEP:
            chunk = min(self.steps_per_launch, count - done)
            team = self.team_for(model, chunk)
            advance_many(integrator, model, state, forces, team, dt, first + done, chunk,
                         not state.prev_valid, tear_stretch)
            if team.stalled():
                raise TeamStalled(
                    f"a barrier of steps {first + done}..{first + done + chunk - 1} waited "
                    f"{BARRIER_SPINS} polls for one of {team.workers} workers; Taichi must give "
                    f"each worker its own CPU thread (ti_cloth.init(threads=1) avoids teams)")
            state.prev_valid = integrator.records_history
            done += chunk
        return done
