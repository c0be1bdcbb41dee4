"""Many steps per launch on the CPU: the plan Simulation.step takes there, with the stages
inside the launch (those with a `launched` object: stages.py).

A launch and every parallel loop in it cost tens of microseconds on a CPU (the thread pool
waking), about a small cloth's whole step of arithmetic, and a step of xpbd is 2 + 17 x
iterations loops, one per colour (docs/performance.md has the figures). So a run of steps is
one launch, shared by
a Team (team.py): a small body's launches run serially on the launching thread (no pool
wake-up), a bigger body's as pool tasks, on one worker for launches of little work and on a
worker per core otherwise, each owning fixed slices and meeting the others at barriers (the
serial or pool choice is compiled, so it is the body's: ManySteps.serial). A step is, per
worker:

    stage starts (the colliders keep the positions at the step start)
    ->  the integrator's phases (Integrator.phases, run by plan.run_team: their barriers)
    ->  handles (their particles put on targets tabled before the launch)
    ->  sewing (seam particles pulled towards their partners)
    ->  strain limiting (relaxation passes, colour by colour)
    ->  colliders (scripted ones placed from a table written before the launch)
    ->  tearing

each stage after the integrator running its own phases (TeamStages.after), the ones its
after_step launches in a launch per stage:

the order of stages.STEP_ORDER. What is a function of time is evaluated in the step from its
start time (plan.py's NOW.time: the wind's gusts, sampled animations), except what only Python
can compute, a user's callable (a handle's or a collider's path, a callable animation): that
is tabled for the launch's steps; a launch ends at the step after which a
handle lets go (its particles are free from that step's handle stage on: that step runs stage
by stage). With self-collision (its passes are phases, but its candidate list is made on
the host between steps) each step is a launch of the integrator and the stages before
self-collision, then self-collision and tearing a launch each (Simulation._step_teamed); GPUs
launch per stage.

Every worker evaluates each spring and particle with the same formula and in the same order
as a launch per phase (the same phases: runtime/plan.py), and sums in fixed blocks,
with exact IEEE arithmetic (runtime/backend.py): every plan gives the same bits
(tests/test_stepping.py). One worker and a team also run the same compiled kernel on
chunk-aligned slices (team.py). Which plan a step takes is decided by the arch and the call
alone (Simulation.step).
"""


import time
from collections import deque

import taichi as ti

from .contact.colliders.collision import resolve_particle
from .errors import TeamStalled
from .inputs import limits
from .runtime import backend, plan
from .runtime.team import BARRIER_SPINS, MAX_WORKERS, TASK_SPACING, Team
from .stages import STEP_ORDER
from .state import NO_BAD_STEP

MAX_STEPS_PER_LAUNCH = 4096    # bounds one launch (Ctrl-C and the divergence check wait for it)
SPRING_STEPS_PER_LAUNCH = 25_000_000   # about 0.1 s of one core's work: fewer steps for big cloths
TEAM_MIN_SPRING_STEPS = 1_000_000   # less work per launch runs on one worker (launch_plans.py)
TEAM_MIN_SPRINGS = 1_000   # a smaller body runs every launch on one worker (launch_plans.py)
PROBE_EVERY = 64    # of big launches, one in this many takes the plan not in favour (~1 % cost)
RECENT_LAUNCHES = 4    # big launches a plan's cost is judged on (the least of them)
TEAM_MARGIN = 1.25     # one worker takes over when the team costs more than this times its cost


@backend.kernel_argument
class TeamStages:
    """The stages after the integrator that run inside a many-steps launch: {STEP_ORDER name:
    the stage's `launched` object} (stages.py; an absent stage is compiled out): handles
    (their HandleTable), sewing (the Seams), strain limiting (the StrainLimiter), colliders
    (the ColliderSet), tearing (the Tearing); the wind is the integrator's (its phases). Each
    runs its phases (runtime/plan.py), as in a launch per stage.

    fused: whether the integrator is fused (its particles move independently of each other
    at the end of its step). Then, unless sewing or strain limiting moves them in between
    or an animated mesh must be placed first (its phases), each particle meets the colliders as
    soon as it has moved (`collides_on_move`, called by
    fused.move_particle): the collision stage reads and writes nothing but the particle,
    and held particles (handles, the stage in between) never collide, so this is the order
    of STEP_ORDER with the same bits, without a pass over the particles of its own nor the
    copy of the step's start positions."""

    def __init__(self, stages: dict | None = None, fused: bool = False):
        self.stages = dict(stages or {})
        self.colliders = self.stages.get("colliders")
        self.holds = "handles" in self.stages          # read at compile time
        self.limits_strain = "strain_limit" in self.stages
        self.collides = self.colliders is not None
        self.collides_on_move = (self.collides and fused and not self.limits_strain
                                 and "sewing" not in self.stages
                                 and not self.colliders.animated)

    def running(self, name: str) -> tuple:
        """(stage `name`'s object,) when it runs its phases after the integrator's, else ()
        (compile time; the object owns the phases and is their workspace)."""
        stage = self.stages.get(name)
        if stage is None or (name == "colliders" and self.collides_on_move):
            return ()
        return (stage,)

    @ti.func
    def collide(self, model: ti.template(), state: ti.template(), i, x0, dt):
        """The collision stage of particle i, which was at x0 at the step's start."""
        resolve_particle(model, state, self.colliders, i, x0, dt)

    @ti.func
    def begin(self, state: ti.template(), worker, p_begin, p_end, k, moving):
        """At the start of the launch's k-th step, before the integrator: the colliders keep
        the worker's particles' positions (or, when they collide on the move, worker 0 puts
        moving ones where this step leaves them: the integrator's barrier before its particle
        loop publishes that)."""
        if ti.static(self.collides_on_move):
            if moving != 0 and worker == 0:
                self.colliders.place_scheduled(k)
        elif ti.static(self.collides):
            for i in range(p_begin, p_end):
                self.colliders.step_start[i] = state.particle_position[i]

    @ti.func
    def after(self, model: ti.template(), state: ti.template(), forces: ti.template(),
              team: ti.template(), worker, now: ti.template(), moving):
        """The stages of the launch's step now.k after the integrator's last barrier, in
        STEP_ORDER (those with a `launched` object; self-collision never is): each
        stage's phases, the colliders placed first when they move (by worker 0, then a
        barrier)."""
        for name in ti.static(STEP_ORDER[1:]):
            for stage in ti.static(self.running(name)):
                if ti.static(name == "colliders"):
                    if moving != 0:
                        if worker == 0:
                            stage.place_scheduled(now.k)
                        team.meet(worker)
                plan.run_team(ti.static(plan.nodes_of(stage, "phases", model, forces, stage)),
                              model, state, forces, stage, self, team, worker, now)


@ti.func
def _run(integrator: ti.template(), model: ti.template(), state: ti.template(),
         forces: ti.template(), work: ti.template(), stages: ti.template(), team: ti.template(),
         worker, dt, first, count, start, moving):
    """Worker `worker`'s share of steps first .. first + count - 1."""
    team.start(worker)
    p_begin, p_end = team.share(model.particle_count, worker)
    for k in range(count):
        stages.begin(state, worker, p_begin, p_end, k, moving)
        now = ti.Struct(dt=ti.cast(dt, float), step=first + k, k=k,
                        start=ti.i32(start != 0 and k == 0), row=worker,
                        time=ti.cast(first + k, ti.f64) * dt)
        plan.run_team(ti.static(plan.nodes_of(integrator, "phases", model, forces, work)),
                      model, state, forces, work, stages, team, worker, now)
        stages.after(model, state, forces, team, worker, now, moving)


@backend.kernel
def advance_many(integrator: ti.template(), model: ti.template(), state: ti.template(),
                 forces: ti.template(), work: ti.template(), stages: ti.template(),
                 team: ti.template(), dt: ti.f64, first: ti.i32, count: ti.i32, start: ti.i32,
                 moving: ti.i32, serial: ti.template()):
    """Steps first .. first + count - 1 of dt [s] in one launch (the steps' dt in the
    working precision, their start times (first + k) dt in float64, as Simulation.time
    computes them), shared by `team` (start: 1 when the
    state has no history yet; moving: 1 when a collider moves, placed from its schedule;
    held particles' targets come from the handles' table)."""
    team.arrived[None] = 0
    if ti.static(serial):        # a small launch, on the launching thread (ManySteps.serial)
        ti.loop_config(serialize=True)
        for worker in range(1):
            _run(integrator, model, state, forces, work, stages, team, worker, dt, first, count,
                 start, moving)
    else:
        for index in range(team.size[None] * TASK_SPACING):   # one task per worker (team.py)
            if index % TASK_SPACING == 0:
                _run(integrator, model, state, forces, work, stages, team, index // TASK_SPACING,
                     dt, first, count, start, moving)


class ManySteps:
    """Runs many steps of an integrator on the CPU in few launches.

    stages: the TeamStages of the simulation (its Model's lent set). A launch holds at most
    MAX_STEPS_PER_LAUNCH steps, fewer for big cloths (SPRING_STEPS_PER_LAUNCH of the
    integrator's step_work), limits.SCHEDULED_STEPS when a collider moves or a handle holds
    (the values of their paths, Python callables, are tabled before the launch). A body under
    TEAM_MIN_SPRINGS runs every launch serially; a bigger body's launch with less work than
    TEAM_MIN_SPRING_STEPS runs on one pool worker, a bigger one on a team of a worker per
    Taichi CPU thread (at most one per core).
    """

    def __init__(self, stages: TeamStages):
        self.stages = stages
        self.team = Team()
        # A worker per pool thread, but no more than the cores: a worker waiting at a barrier
        # for one that has no core to run on spins away its time slice.
        self.workers = min(backend.cpu_threads(), backend.cpu_cores(), MAX_WORKERS)
        self.adaptive = True       # False: big launches always on the team (tests, benchmarks)
        self._cost = {}            # workers -> seconds per spring-step of recent big launches
        self._big_launches = 0
        self._launched = set()     # team sizes that have run a big launch

    def steps_per_launch(self, integrator, model) -> int:
        """How many steps one launch of `integrator` on `model` holds at most."""
        most = MAX_STEPS_PER_LAUNCH
        colliders = self.stages.colliders
        if (colliders is not None and colliders.moving) or self.stages.holds:
            most = limits.SCHEDULED_STEPS
        return max(1, min(most, SPRING_STEPS_PER_LAUNCH // max(integrator.step_work(model), 1)))

    def workers_for(self, integrator, model, steps: int) -> int:
        """How many workers run a launch of `steps` steps: one below TEAM_MIN_SPRING_STEPS of
        work; above it every worker, unless timed launches show the team costing more than
        TEAM_MARGIN x one worker in this process (its spinning workers sharing the cores with
        other processes): every PROBE_EVERY-th big launch takes the size not in favour, so the
        choice follows the machine. Every size runs the same compiled kernel on chunk-aligned
        slices (team.py), so the choice never changes a bit."""
        work = steps * integrator.step_work(model)
        if work < TEAM_MIN_SPRING_STEPS or self.workers == 1:
            return 1
        if not self.adaptive:
            return self.workers
        self._big_launches += 1
        measured = [size for size in (self.workers, 1) if self._cost.get(size)]
        if len(measured) < 2:
            return 1 if measured == [self.workers] else self.workers
        slower = self.cost(self.workers) > TEAM_MARGIN * self.cost(1)
        best, other = (1, self.workers) if slower else (self.workers, 1)
        return other if self._big_launches % PROBE_EVERY == 0 else best

    def serial(self, model) -> bool:
        """Whether this body's launches run serially on the launching thread (no pool
        wake-up): those of a body under TEAM_MIN_SPRINGS spring equivalents, whose loops are
        too short for a team to pay for its barriers (at 8² a team step took 58 µs against
        1.6 on one worker, at 16² 4.2 against 5.8: docs/performance.md). A bigger body's
        launches run as pool tasks, on one worker or a team (workers_for). The choice is the
        body's, not the launch's, because it is compiled (advance_many's `serial`): a
        simulation builds one variant of its step, and no later step count compiles another.
        Every plan gives the same bits (IEEE arithmetic: runtime/backend.py)."""
        return limits.spring_equivalents(model) < TEAM_MIN_SPRINGS

    def cost(self, workers: int) -> float:
        """Seconds per spring-step of recent big launches on `workers` workers: the least of
        the last few (one slow wake-up does not condemn a size; a lasting slowdown shows in
        all)."""
        return min(self._cost[workers])

    def timed(self, workers: int, work: int, seconds: float) -> None:
        """Keep a big launch's seconds per spring-step (not the first launch on a size: it
        may have compiled the kernel)."""
        if workers not in self._launched:
            self._launched.add(workers)
            return
        self._cost.setdefault(workers, deque(maxlen=RECENT_LAUNCHES)).append(seconds / work)

    def run(self, integrator, model, state, forces, dt: float, first: int, count: int,
            handles=None, run_length: int | None = None) -> int:
        """Up to `count` steps; stops after the launch in which a step diverged, and before
        a step in which a handle lets go (the caller runs that one stage by stage). Returns
        how many steps ran. handles: the HandleSet (whose table is this plan's stages').
        run_length: the steps the caller runs back to back, a launch each (a simulation with
        self-collision, whose list is made on the host between steps), `count` unless given:
        the team is chosen for that run's work (workers_for), as it would be for one launch
        of it (a barrier's cost is per step, the pool's wake-up a small part of a big
        step). Raises TeamStalled if a barrier gave up on a worker (the state is then
        unusable)."""
        work = integrator.loaded_workspace(model, state)
        plan.note_launch(plan.nodes_of(integrator, "phases", model, forces, work), "team")
        for name in STEP_ORDER[1:]:
            for stage in self.stages.running(name):
                plan.note_launch(plan.nodes_of(stage, "phases", model, forces, stage), "team")
        colliders = self.stages.colliders
        moving = colliders is not None and colliders.moving
        done = 0
        while done < count and (done == 0 or state.first_bad_step[None] == NO_BAD_STEP):
            step = first + done
            chunk = min(self.steps_per_launch(integrator, model), count - done)
            if handles is not None:
                chunk = min(chunk, handles.steps_before_release(step, dt))
                if chunk == 0:
                    break
                handles.schedule(step, chunk, dt)
            if moving:
                colliders.schedule(step, chunk, dt)
            serial = self.serial(model)
            judged = max(chunk, run_length or 0)       # the steps the team is chosen for
            workers = 1 if serial else self.workers_for(integrator, model, judged)
            team = self.team
            team.set_size(workers)
            began = time.perf_counter()
            advance_many(integrator, model, state, forces, work, self.stages, team, dt, step,
                         chunk, not state.prev_valid, int(moving), serial)
            spring_steps = chunk * integrator.step_work(model)
            if not serial and judged * integrator.step_work(model) >= TEAM_MIN_SPRING_STEPS:
                self.timed(workers, spring_steps, time.perf_counter() - began)
            if team.stalled():
                raise TeamStalled(
                    f"a barrier of steps {step}..{step + chunk - 1} waited "
                    f"{BARRIER_SPINS} polls for one of {team.workers} workers; Taichi must give "
                    f"each worker its own CPU thread (ti_cloth.init(threads=1) avoids teams)")
            state.prev_valid = integrator.records_history
            integrator.after_launch(work)
            done += chunk
        return done
