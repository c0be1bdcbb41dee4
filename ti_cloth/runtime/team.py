"""A team of CPU workers sharing one launch: the persistent-threads plan of every many-steps
CPU launch (stepping.py), as inside an OpenMP parallel region.

Each worker is one task of a Taichi parallel loop (`Team.size * TASK_SPACING` indices, the
worker being index / TASK_SPACING): Taichi 1.7's CPU runtime makes each block of 512 indices a
task, so every worker runs on a pool thread of its own. Workers own fixed slices of each loop
(`share`) and meet at barriers (`meet`) between phases that read what other workers wrote.

Thread counts never change a bit, by construction rather than by two kernels compiling alike:

- how many workers share a launch is a field (`size`), read at run time, so one worker and a
  team of any size run the same compiled kernel (one worker is a pool task too; small
  launches run serially on the launching thread instead, chosen by their work alone:
  stepping.ManySteps.serial);
- every slice of a loop starts at a multiple of CHUNK items from the start of its loop, so
  LLVM's vectorised loop body and its scalar remainder see each item at the same place
  whatever the slices: an item is computed by the same instructions for every team size. A
  colour of a sweep (`share_range`) is cut anywhere: its items write their particles through
  indices read from the mesh, which LLVM's loop vectoriser does not vectorise (a store may
  alias a later item's loads), and a colour of a few hundred items cut at multiples of 64
  left one worker nearly twice the other's share (docs/performance.md, "A sweep's colours
  shared item by item");
- sums over items are taken in fixed blocks and totalled in block order by the callers
  (implicit_euler.py), never per worker.

A barrier spins: on a 2-core machine a wake-up through the OS costs tens of microseconds, far
more than the phases between barriers. After BARRIER_SPINS polls a barrier gives up
(`stalled` reports it), so a team without a thread for every worker cannot hang.
"""


import taichi as ti

from . import backend

TASK_SPACING = 512   # indices per Taichi CPU task: worker w is index w * TASK_SPACING
CHUNK = 64           # slices start at multiples of this (a multiple of any vector width x unroll)
BARRIER_SPINS = 1 << 28   # polls before a barrier gives up on a missing worker
STALLED = 1 << 29         # added to the arrival count by a worker that gave up
PAD = 16                  # i32 slots between two workers' counters (one cache line)
MAX_WORKERS = 64


@backend.kernel_argument
class Team:
    """Up to MAX_WORKERS CPU workers that share the work of one launch: `size` of them in the
    next launch (set_size; they must not outnumber Taichi's CPU threads, since a barrier
    waits for every worker). Fields: `size`, `arrived` (meetings attended in this launch,
    + STALLED once a barrier gave up) and each worker's count of barriers passed."""

    def __init__(self):
        fields = backend.FieldGroup()
        self.size = fields.scalar(ti.i32, ())
        self.arrived = fields.scalar(ti.i32, ())
        self.passed = fields.scalar(ti.i32, PAD * MAX_WORKERS)
        fields.finalize(self)
        self._size = 0
        self.set_size(1)

    def set_size(self, workers: int) -> None:
        """How many workers run the next launches (1 to MAX_WORKERS)."""
        if not 1 <= workers <= MAX_WORKERS:
            raise ValueError(f"Team workers must be in [1, {MAX_WORKERS}], got {workers}")
        if workers != self._size:
            self.size[None] = workers
            self._size = workers

    @property
    def workers(self) -> int:
        """How many workers run the next launch."""
        return self._size

    @ti.func
    def start(self, worker):
        """Called by each worker first in its task: no barrier passed yet."""
        self.passed[PAD * worker] = 0

    @ti.func
    def meet(self, worker):
        """Barrier: wait until every worker has called meet as often as `worker` has."""
        workers = self.size[None]
        if workers > 1:
            passed = self.passed[PAD * worker] + 1
            self.passed[PAD * worker] = passed
            ti.atomic_add(self.arrived[None], 1)
            spins = 0
            while ti.atomic_add(self.arrived[None], 0) < passed * workers:
                spins += 1
                if spins == BARRIER_SPINS:
                    ti.atomic_add(self.arrived[None], STALLED)

    @ti.func
    def share(self, count, worker, chunk: ti.template() = CHUNK):
        """Worker `worker`'s slice [begin, end) of `count` items, starting at a multiple of
        `chunk` (CHUNK: module doc)."""
        return chunked_share(count, worker, self.size[None], chunk)

    @ti.func
    def share_range(self, begin, end, worker):
        """Worker `worker`'s slice of the items begin .. end - 1 of a sweep's colour, cut
        anywhere (module doc)."""
        first, last = self.share(end - begin, worker, 1)
        return begin + first, begin + last

    def stalled(self) -> bool:
        """Whether a barrier of the last launch gave up on a worker."""
        return self.workers > 1 and self.arrived[None] >= STALLED


@ti.func
def chunked_share(count, part, parts, chunk: ti.template()):
    """Part `part`'s slice [begin, end) of `count` items cut into `parts` near-equal parts,
    every cut at a multiple of `chunk` (the last part ends at `count`)."""
    begin = ti.i32(ti.i64(part) * count // parts) // chunk * chunk
    end = count
    if part + 1 < parts:
        end = ti.i32(ti.i64(part + 1) * count // parts) // chunk * chunk
    return begin, end


@backend.kernel_argument
class _Solo:
    """One worker known at compile time: every loop serial, no barriers, no fields (a serial
    launch of a step's phases: plan.py; strain limiting's serial sweeps: energies/springs.py)."""

    workers = 1

    @ti.func
    def meet(self, worker):
        pass

    @ti.func
    def share(self, count, worker, chunk: ti.template() = CHUNK):
        return 0, count

    @ti.func
    def share_range(self, begin, end, worker):
        return begin, end


SOLO = _Solo()
