"""A team of CPU workers sharing one launch: the persistent-threads plan of every many-steps
CPU launch (stepping.py), as inside an OpenMP parallel region.

Each worker is one task of a Taichi parallel loop (`Team.workers * TASK_SPACING` indices, the
worker being index / TASK_SPACING): Taichi 1.7's CPU runtime makes each block of 512 indices a
task, so every worker runs on a pool thread of its own. Workers own fixed slices of each loop
(`share`) and meet at barriers (`meet`) between phases that read what other workers wrote.
One worker runs everything serially on the launching thread; its barriers compile to nothing,
so a team of any size computes the same bits as one worker.

A barrier spins: on a 2-core machine a wake-up through the OS costs tens of microseconds, far
more than the phases between barriers. After BARRIER_SPINS polls a barrier gives up
(`stalled` reports it), so a team without a thread for every worker cannot hang.
"""


import taichi as ti

from . import backend

TASK_SPACING = 512   # indices per Taichi CPU task: worker w is index w * TASK_SPACING
BARRIER_SPINS = 1 << 28   # polls before a barrier gives up on a missing worker
STALLED = 1 << 29         # added to the arrival count by a worker that gave up
PAD = 16                  # i32 slots between two workers' counters (one cache line)
MAX_WORKERS = 64


@backend.kernel_argument
class Barrier:
    """The counters of a team's barriers: `arrived`, how many meetings have been attended in
    this launch (+ STALLED once a barrier gave up), and each worker's count of barriers
    passed. Teams that never run at the same time may share one."""

    def __init__(self):
        fields = backend.FieldGroup()
        self.arrived = fields.scalar(ti.i32, ())
        self.passed = fields.scalar(ti.i32, PAD * MAX_WORKERS)
        fields.finalize(self)


@backend.kernel_argument
class Team:
    """`workers` CPU workers (1 to MAX_WORKERS) that share the work of one launch. workers
    must not exceed Taichi's CPU threads, since a barrier waits for every worker."""

    def __init__(self, workers: int, barrier: Barrier | None = None):
        if not 1 <= workers <= MAX_WORKERS:
            raise ValueError(f"Team.workers must be in [1, {MAX_WORKERS}], got {workers}")
        if workers > 1 and barrier is None:
            raise ValueError("a Team of several workers needs a Barrier")
        self.workers = workers
        self.barrier = barrier

    @ti.func
    def start(self, worker):
        """Called by each worker first in its task: no barrier passed yet."""
        if ti.static(self.workers > 1):
            self.barrier.passed[PAD * worker] = 0

    @ti.func
    def meet(self, worker):
        """Barrier: wait until every worker has called meet as often as `worker` has."""
        if ti.static(self.workers > 1):
            passed = self.barrier.passed[PAD * worker] + 1
            self.barrier.passed[PAD * worker] = passed
            ti.atomic_add(self.barrier.arrived[None], 1)
            spins = 0
            while ti.atomic_add(self.barrier.arrived[None], 0) < passed * self.workers:
                spins += 1
                if spins == BARRIER_SPINS:
                    ti.atomic_add(self.barrier.arrived[None], STALLED)

    @ti.func
    def share(self, count, worker):
        """Worker `worker`'s slice [begin, end) of `count` items."""
        return share(count, worker, self.workers)

    @ti.func
    def share_range(self, begin, end, worker):
        """Worker `worker`'s slice of the items begin .. end - 1."""
        first, last = self.share(end - begin, worker)
        return begin + first, begin + last

    def stalled(self) -> bool:
        """Whether a barrier of the last launch gave up on a worker."""
        return self.workers > 1 and self.barrier.arrived[None] >= STALLED


@ti.func
def share(count, part, parts):
    """Part `part`'s slice [begin, end) of `count` items cut into `parts` near-equal parts."""
    return ti.i32(ti.i64(part) * count // parts), ti.i32(ti.i64(part + 1) * count // parts)


SOLO = Team(1)   # one worker: every loop serial, no barriers (holds no fields)
