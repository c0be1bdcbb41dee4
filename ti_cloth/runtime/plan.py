"""The plan runner: a step written once, as phases, run as a kernel per phase or by a team.

An integrator (or any owner of phases: forces.EVALUATION) writes its step once, as a tuple of
nodes returned by a method (`phases(model, forces, work)`):

    Phase(Loop(count, body, *args), ...)   loops over items that read only what earlier
                                           phases wrote; they end at a synchronisation point
                                           (count: an int, or Used: read at run time)
    Sweep(colouring, body, *args)          the items of a colouring, colour by colour, a
                                           synchronisation point after each colour
    Once(body, *args)                      a scalar computation (a sum of partial sums, a
                                           decision), done by every worker on its own row of
                                           a workspace
    Repeat(count, nodes...)                the nodes `count` times (an int, or a Setting:
                                           read at run time)
    Until(test, nodes..., args=())         the nodes while test(*args) holds

(a Repeat or an Until holds leaves (Phase, Sweep, Once) and Repeats and Untils: TR-BDF2's
stages around a Newton iteration around a conjugate-gradient loop).

Bodies are ti.funcs that take what they need: a node holds its body and the body's arguments,
`Loop(count, body, *args)`, and the runner calls body(*args) for each item, with these
placeholders among the args filled in (bind): ITEM, the item (a Loop's index, a Sweep's
position in its colour order); STATE, the State being stepped; DT, the step [s]; NOW, the step
as a struct of dt, step (its global index), k (its index in the launch: rows of tables
scheduled before the launch), start (1: the state has no history yet), row (the worker's
row of per-worker scalars; 0 in a launch per phase) and time (the step's start [s], float64,
step x dt as Simulation.time: what is given as a function of time, the wind's gusts, is
evaluated from it in the step); STAGES, the stages running inside the
step (stepping.TeamStages; STAGELESS in a launch per phase). The model, the force settings
and the workspace are given to the method that writes the nodes (`phases(model, forces,
work)`), which passes them as they are.

Two runners read the same nodes:

- `run` (GPUs, a single CPU step, and steps with a stage no team runs): a launch per phase,
  every maximal run of leaves one kernel whose loops are its top-level parallel loops
  (Taichi synchronises between them; a Sweep with a big body a kernel launched per
  colour), Repeat and Until looping on the host, the test a kernel; on the CPU, for a body of at most SERIAL_SPRING_LIMIT springs, one serial launch
  of the whole step instead (a parallel loop costs tens of microseconds to start, a pass of
  xpbd is a loop per colour: docs/performance.md);
- `run_team` (many steps per launch, CPU: stepping.py): each worker runs its slice of every
  loop (Team.share) and meets the team at every synchronisation point.

So a step's arithmetic is written once; the plans differ only in how items are grouped into
tasks, and with exact IEEE arithmetic (backend.py) they give the same bits
(tests/test_stepping.py).
"""


import taichi as ti

from ..inputs import limits
from . import backend
from .team import CHUNK, SOLO

SERIAL_SPRING_LIMIT = 50_000   # serial launches faster at 24k springs, parallel ones at 97k


class Placeholder:
    """An argument of a body that the runner fills in (module doc)."""

    def __init__(self, name: str):
        self.name = name

    def __repr__(self) -> str:
        return self.name


ITEM, STATE, DT, NOW, STAGES = (Placeholder(name)
                                for name in ("ITEM", "STATE", "DT", "NOW", "STAGES"))


class Substep(Placeholder):
    """DT or NOW of a sub-step: the step's dt times `fraction` (the rest of NOW as it is)."""

    def __init__(self, of: Placeholder, fraction: float):
        super().__init__(f"{of.name} x {fraction:g}")
        self.of, self.fraction = of, float(fraction)


def bind(args: tuple, item, state, now, stages) -> tuple:
    """`args` with the placeholders filled in (called at compile time: ti.static(bind(...)))."""
    values = {ITEM: item, STATE: state, DT: now.dt, NOW: now, STAGES: stages}
    bound = []
    for a in args:
        if isinstance(a, Substep):
            dt = now.dt * a.fraction
            a = dt if a.of is DT else ti.Struct(dt=dt, step=now.step, k=now.k, start=now.start,
                                                row=now.row, time=now.time)
        elif isinstance(a, Placeholder):
            a = values[a]
        bound.append(a)
    return tuple(bound)


def substep(fraction: float, nodes: tuple) -> tuple:
    """`nodes` (any of this module's) with DT and NOW among their bodies' arguments standing
    for a sub-step of `fraction` x dt: phases written for a step, run as a part of one
    (an implicit stage of a Runge-Kutta or TR-BDF2 step, the half step of implicit
    midpoint)."""
    def scaled(args):
        return tuple(Substep(a, fraction) if a is DT or a is NOW else a for a in args)

    out = []
    for node in nodes:
        if isinstance(node, Phase):
            node = Phase(*(Loop(loop.count, loop.body, *scaled(loop.args), chunk=loop.chunk)
                            for loop in node.loops))
        elif isinstance(node, Sweep):
            copy = Sweep(node.colouring, node.body, *scaled(node.args))
            copy.per_colour = node.per_colour
            node = copy
        elif isinstance(node, Once):
            node = Once(node.body, *scaled(node.args))
        elif isinstance(node, Repeat):
            node = Repeat(node.count, *substep(fraction, node.leaves))
        else:
            node = Until(node.test, *substep(fraction, node.leaves), args=scaled(node.args))
        out.append(node)
    return tuple(out)


class Used:
    """A loop's count read at run time: the items in use, field[index], of at most
    `capacity` (a candidate list's pairs in the room it was given). A list grown once for a
    dense moment kept the cape's contact passes walking 121,440 slots for its 1,300 pairs
    ever after."""

    def __init__(self, field, index: int, capacity: int):
        self.field, self.index, self.capacity = field, int(index), int(capacity)


class Loop:
    """body(*args) for every item i in 0 .. count - 1 (count: a Python int, a compile-time
    constant, or a Used, read when the loop starts; ITEM among the args is i). chunk: a team
    worker's slice starts at a multiple of this many items (team.py: CHUNK, where LLVM may
    vectorise the loop over items); 1 for a loop over blocks of particles, each block a
    serial loop of its own, so that a body of a few blocks is still shared
    (conjugate_gradients.BLOCK)."""

    def __init__(self, count: int | Used, body, *args, chunk: int = CHUNK):
        self.count = count if isinstance(count, Used) else int(count)
        self.body, self.args, self.chunk = body, args, int(chunk)


@ti.func
def items(count: ti.template()):
    """How many items a Loop of `count` (Loop.count) runs over now (an int stays the
    compile-time constant it is)."""
    if ti.static(isinstance(count, Used)):
        return ti.min(count.field[count.index], count.capacity)
    else:
        return count


class Phase:
    """Loops whose items are independent of each other's, then a synchronisation point."""

    def __init__(self, *loops: Loop):
        self.loops = loops


class Sweep:
    """body(*args) for every position t of a colouring's order (ITEM), colour by colour
    (the items of one colour are independent), synchronising after each colour. colouring:
    an object with count, start (field, count + 1) and offsets (the same, a list).

    A launch per phase unrolls the colours into one kernel, a copy of the body per colour;
    a Sweep made with_big_body() is instead compiled once and launched per colour (a
    Fabric's bending constraint unrolled over 14 colours took 247 s to compile)."""

    def __init__(self, colouring, body, *args):
        self.colouring, self.body, self.args = colouring, body, args
        self.per_colour = False

    def with_big_body(self):
        """This Sweep, launched per colour by a launch per phase (returns self)."""
        self.per_colour = True
        return self


class Once:
    """body(*args) once per row (every worker of a team
    computes it for itself: it reads what the team wrote before the last synchronisation
    point and writes only row now.row of its workspace)."""

    def __init__(self, body, *args):
        self.body, self.args = body, args


class Setting:
    """A value of `work`'s run-time settings (work.settings[slot], its host copy
    work.loaded[slot]): an integrator's option that a kernel reads at run time, so that
    changing it compiles nothing (Integrator.runtime_options)."""

    def __init__(self, work, slot: int):
        self.work, self.slot = work, slot

    def host(self) -> int:
        """The value as a count, on the host (the last values loaded: Integrator.load_settings)."""
        return int(self.work.loaded[self.slot])


@ti.func
def repeats(count: ti.template()):
    """A Repeat's count in a kernel: a Python int, or a Setting read at run time."""
    n = 0
    if ti.static(isinstance(count, Setting)):
        n = ti.i32(count.work.settings[count.slot])
    else:
        n = count
    return n


class Repeat:
    """The nodes `count` times (count: a Python int, or a Setting read at run time)."""

    def __init__(self, count, *leaves):
        self.count = count if isinstance(count, Setting) else int(count)
        self.leaves = leaves

    def host_count(self) -> int:
        """The count on the host (a launch per phase loops there)."""
        return self.count.host() if isinstance(self.count, Setting) else self.count


class Until:
    """The nodes while test(*args) is true (test reads only the worker's row, so every worker
    decides alike)."""

    def __init__(self, test, *leaves, args: tuple = ()):
        self.test, self.leaves, self.args = test, leaves, args


LEAVES = (Phase, Sweep, Once)
LOOPS = (Repeat, Until)


def _check(nodes) -> tuple:
    for node in nodes:
        if isinstance(node, LOOPS):
            _check(node.leaves)
        elif not isinstance(node, LEAVES):
            raise TypeError(f"phases may hold Phase, Sweep, Once, Repeat and Until, got {node!r}")
    return tuple(nodes)


def nodes_of(owner, part: str, model, forces, work) -> tuple:
    """The nodes `owner`'s method `part` returns for this model, forces and workspace."""
    return _check(getattr(owner, part)(model, forces, work))


def _leaves(nodes, container: tuple) -> tuple:
    """The top-level nodes (container ()) or the nodes in the Repeat or Until at path
    `container` ((i,): top-level node i; (i, j): node j inside it)."""
    for index in container:
        nodes = nodes[index].leaves
    return nodes


def _node(nodes, path: tuple):
    """The node at `path` (_leaves)."""
    return _leaves(nodes, path[:-1])[path[-1]]


def _bodies(nodes):
    """Every body in `nodes`, depth first: loop bodies, leaf bodies and Until tests."""
    for node in nodes:
        if isinstance(node, LOOPS):
            yield from _bodies(node.leaves)
            if isinstance(node, Until):
                yield node.test
        elif isinstance(node, Phase):
            yield from (loop.body for loop in node.loops)
        else:
            yield node.body


def _alone(leaf) -> bool:
    """Whether a launch per phase runs `leaf` colour by colour in launches of its own."""
    return isinstance(leaf, Sweep) and leaf.per_colour


def _segment(nodes, path):
    """The leaves a launch per phase runs in one kernel: path (container, begin, end) the
    leaves begin .. end - 1 of _leaves(nodes, container)."""
    container, begin, end = path
    return _leaves(nodes, container)[begin:end]


def note_launch(nodes, key) -> None:
    """Count a launch of every body in `nodes` under `key` (backend.note_launch): tests
    tell what a step compiled by its bodies, as by kernels (backend.compilations)."""
    if not backend.counting():
        return
    for body in _bodies(nodes):
        backend.note_launch(getattr(body, "__func__", body), key)


@backend.kernel_argument
class _Stageless:
    """No stage runs inside the step (a launch per phase)."""

    collides_on_move = False


STAGELESS = _Stageless()


@backend.kernel
def launch_phases(owner: ti.template(), part: ti.template(), model: ti.template(),
                 state: ti.template(), forces: ti.template(), work: ti.template(), dt: float,
                 step: ti.i32, start: ti.i32, time: ti.f64, path: ti.template()):
    """The leaves at `path` of owner's nodes, each loop a parallel loop of its own."""
    for leaf in ti.static(_segment(nodes_of(owner, part, model, forces, work), path)):
        if ti.static(isinstance(leaf, Phase)):
            for loop in ti.static(leaf.loops):
                for i in range(items(loop.count)):
                    now = ti.Struct(dt=dt, step=step, k=0, start=start, row=0, time=time)
                    loop.body(*ti.static(bind(loop.args, i, state, now, STAGELESS)))
        elif ti.static(isinstance(leaf, Sweep)):
            colours = leaf.colouring
            for c in ti.static(range(colours.count)):
                for t in range(colours.offsets[c], colours.offsets[c + 1]):
                    now = ti.Struct(dt=dt, step=step, k=0, start=start, row=0, time=time)
                    leaf.body(*ti.static(bind(leaf.args, t, state, now, STAGELESS)))
        else:
            for _ in range(1):
                now = ti.Struct(dt=dt, step=step, k=0, start=start, row=0, time=time)
                leaf.body(*ti.static(bind(leaf.args, None, state, now, STAGELESS)))


@backend.kernel
def launch_colour(owner: ti.template(), part: ti.template(), model: ti.template(),
                  state: ti.template(), forces: ti.template(), work: ti.template(), dt: float,
                  step: ti.i32, start: ti.i32, time: ti.f64, path: ti.template(), begin: ti.i32,
                  end: ti.i32):
    """Positions begin .. end - 1 (a colour) of the Sweep at `path` (container, index)."""
    for leaf in ti.static(_leaves(nodes_of(owner, part, model, forces, work), path[0])[path[1]:path[1] + 1]):
        for t in range(begin, end):
            now = ti.Struct(dt=dt, step=step, k=0, start=start, row=0, time=time)
            leaf.body(*ti.static(bind(leaf.args, t, state, now, STAGELESS)))


def _launch_leaves(args, nodes, container: tuple, begin: int, end: int) -> None:
    """Leaves begin .. end - 1 of _leaves(nodes, container): runs of them in one kernel,
    split at the Sweeps that run alone, each of those a launch per colour."""
    leaves = _leaves(nodes, container)
    j = begin
    while j < end:
        if _alone(leaves[j]):
            offsets = leaves[j].colouring.offsets
            for c in range(leaves[j].colouring.count):
                launch_colour(*args, (container, j), offsets[c], offsets[c + 1])
            j += 1
            continue
        k = j
        while k < end and not _alone(leaves[k]):
            k += 1
        launch_phases(*args, (container, j, k))
        j = k


@backend.kernel
def _holds(owner: ti.template(), part: ti.template(), model: ti.template(), state: ti.template(),
           forces: ti.template(), work: ti.template(), dt: float, step: ti.i32, start: ti.i32,
           time: ti.f64, path: ti.template()) -> ti.i32:
    """Whether the test of the Until at `path` (_leaves) holds (row 0)."""
    now = ti.Struct(dt=dt, step=step, k=0, start=start, row=0, time=time)
    holds = 0
    for node in ti.static((_node(nodes_of(owner, part, model, forces, work), path),)):
        holds = ti.i32(node.test(*ti.static(bind(node.args, None, state, now, STAGELESS))))
    return holds


def serial_is_faster(model) -> bool:
    """Whether a step of this model runs faster as one serial launch (CPU, few springs)."""
    return (backend.config().arch == "cpu"
            and limits.spring_equivalents(model) <= SERIAL_SPRING_LIMIT)


@backend.kernel
def launch_serial(owner: ti.template(), part: ti.template(), model: ti.template(),
                  state: ti.template(), forces: ti.template(), work: ti.template(), dt: float,
                  step: ti.i32, start: ti.i32, time: ti.f64):
    """Every node of owner's `part`, in one serial task (run_team with one worker)."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        now = ti.Struct(dt=dt, step=step, k=0, start=start, row=0, time=time)
        run_team(ti.static(nodes_of(owner, part, model, forces, work)), model, state, forces,
                 work, STAGELESS, SOLO, 0, now)


def run(owner, model, state, forces, work, dt: float, step: int, start: bool,
        part: str = "phases", time: float | None = None, serial: bool | None = None) -> None:
    """owner's nodes (its method `part`) for step `step` of dt [s], which starts at `time`
    [s] (step x dt unless given): one serial launch when `serial` (None: when
    serial_is_faster), else a launch per run of leaves (module doc)."""
    nodes = nodes_of(owner, part, model, forces, work)
    note_launch(nodes, ("run", part))
    args = (owner, part, model, state, forces, work, dt, step, int(start),
            step * dt if time is None else time)
    if serial_is_faster(model) if serial is None else serial:
        launch_serial(*args)
        return
    _run_nodes(args, nodes, ())


def _run_nodes(args, nodes, container: tuple) -> None:
    """The nodes at `container` (_leaves), a launch per run of leaves, loops on the host."""
    inner = _leaves(nodes, container)
    i = 0
    while i < len(inner):
        node = inner[i]
        if isinstance(node, Repeat):
            for _ in range(node.host_count()):
                _run_nodes(args, nodes, container + (i,))
        elif isinstance(node, Until):
            while _holds(*args, container + (i,)):
                _run_nodes(args, nodes, container + (i,))
        else:
            end = i
            while end < len(inner) and isinstance(inner[end], LEAVES):
                end += 1
            _launch_leaves(args, nodes, container, i, end)
            i = end - 1
        i += 1


@ti.func
def _run_leaf(leaf: ti.template(), model: ti.template(), state: ti.template(),
              forces: ti.template(), work: ti.template(), stages: ti.template(),
              team: ti.template(), worker, now: ti.template()):
    if ti.static(isinstance(leaf, Phase)):
        for loop in ti.static(leaf.loops):
            begin, end = team.share(items(loop.count), worker, loop.chunk)
            for i in range(begin, end):
                loop.body(*ti.static(bind(loop.args, i, state, now, stages)))
        team.meet(worker)
    elif ti.static(isinstance(leaf, Sweep)):
        colours = leaf.colouring
        for c in range(colours.count):
            begin, end = team.share_range(colours.start[c], colours.start[c + 1], worker)
            for t in range(begin, end):
                leaf.body(*ti.static(bind(leaf.args, t, state, now, stages)))
            team.meet(worker)
    else:
        leaf.body(*ti.static(bind(leaf.args, None, state, now, stages)))


@ti.func
def run_team(nodes: ti.template(), model: ti.template(), state: ti.template(),
             forces: ti.template(), work: ti.template(), stages: ti.template(),
             team: ti.template(), worker, now: ti.template()):
    """Worker `worker`'s share of `nodes` (nodes_of) in a team launch (stepping.py), meeting
    the team at every synchronisation point; now.row is the worker. A loop's nodes run as
    these do (this function inlined into itself at compile time, down to the leaves)."""
    for node in ti.static(nodes):
        if ti.static(isinstance(node, Repeat)):
            for _ in range(repeats(node.count)):
                run_team(node.leaves, model, state, forces, work, stages, team, worker, now)
        elif ti.static(isinstance(node, Until)):
            while node.test(*ti.static(bind(node.args, None, state, now, stages))):
                run_team(node.leaves, model, state, forces, work, stages, team, worker, now)
        else:
            _run_leaf(node, model, state, forces, work, stages, team, worker, now)
