"""Matrix-free preconditioned conjugate gradients on the system of an implicit step,

    A dv = b,   A = M (1 + h drag) - h D - h^2 K,

with K = df/dx and D = df/dv linearised by the terms of energies.ROWS (each term's
implicit_start fills its blocks and its share of the 3x3 diagonal, implicit_product applies
them), h the step of the solve (implicit Euler's step, or the sub-step of implicit midpoint
and TR-BDF2: newton.py). The system is never assembled: each iteration gathers A p per
particle in the Model's fixed adjacency order, and every dot product is summed in fixed blocks
of BLOCK particles, so a run is bit-for-bit repeatable. Preconditioner (Preconditioner): the
3x3 diagonal (Jacobi), and by default a coarse level (coarse.py: z = D^-1 r + P A_c^-1 P^T r,
its solve in the scalar steps, its matrix assembled at a solve's first linearisation).
Pins: dv is filtered to zero on particles of inverse mass 0 (Baraff & Witkin's modified CG
with S = 0 there). Three synchronisation points per iteration: after A p, the update, the new
direction; every worker sums the same partial sums in block order, so all take the same
decisions (runtime/plan.py's Until).

Seams (a garment's particles sewn together, Model.weld_*): each group is one particle of the
solve, dv = P y with P copying a group's y to its members, so CG runs on P^T A P y = P^T b
(symmetric positive definite as A is): b, A p and the diagonal are summed over the group on
its representative (the members' rows 0), z and p read the representative's. A step then
keeps sewn particles moving together (the sewing stage closes their gap), where separate
solves for the two sides of a seam, the seam's bending coupling them, would be joined only
after the step and a large step could tear the seam's fold apart or fling it. A group with
a pinned particle is pinned.
"""

import math

import taichi as ti

from ..energies import ROWS
from ..energies.altitude import linearise_altitude, project_altitude
from ..energies.bending import bending_phases
from ..energies.springs import linearise_spring
from ..inputs import limits
from ..inputs.validation import count, require
from ..physics import wind
from ..physics.forces import force_loops, gather_force
from ..runtime import backend
from ..runtime.plan import ITEM, NOW, STATE, Loop, Once, Phase, Until
from ..runtime.team import MAX_WORKERS
from . import coarse, implicit_elements
from .base import add_settings

BLOCK = 64                      # particles per partial sum of a dot product
TYPICAL_ITERATIONS = 20         # CG iterations a step is assumed to take (sizing launches)
ALPHA, RZ, RR, BB, BETA, CHANGE = range(6)  # slots of a row of the workspace's scalar field
CG, NEWTON, CG_TOTAL, RAN_OUT, STAGE = range(5)   # slots of a row of its counts (STAGE: TR-BDF2)
ROW = 16                        # slots per row (a worker's row fills its own cache line)
# slots of the workspace's run-time settings (Integrator.runtime_options): CG's tolerance
# squared and its cap; a Newton solve's tolerance [m] and cap (newton.py)
CG_TOLERANCE_SQUARED, MOST_CG, NEWTON_TOLERANCE, MOST_NEWTON = range(4)


PRECONDITIONERS = ("two-level", "jacobi")


class Preconditioner:
    """A solve's preconditioner, checked.

    kind: "two-level" (the 3x3 diagonal and a coarse level of aggregates: coarse.py) or
        "jacobi" (the 3x3 diagonal alone).
    aggregate_size: particles per aggregate of the coarse level, >= 1; None: one (the coarse
        level is then the whole system, solved exactly) where the body's particles lie in a
        band of coarse.EXACT_BAND (hair, strings, narrow sheets), else about
        1 / coarse.AGGREGATES of the body, at least coarse.SMALLEST.
    """

    def __init__(self, owner: str, kind: str, aggregate_size: int | None):
        require(kind in PRECONDITIONERS, f"{owner}.preconditioner", kind,
                f"one of {', '.join(map(repr, PRECONDITIONERS))}")
        self.kind = kind
        self.aggregate_size = (None if aggregate_size is None else
                               count(f"{owner}.aggregate_size", aggregate_size,
                                     limits.AGGREGATE))

    def options(self) -> dict:
        return {"preconditioner": self.kind, "aggregate_size": self.aggregate_size}

    def key(self) -> tuple:
        """What the workspace's fields depend on (Integrator.buffer_key)."""
        return (self.kind, self.aggregate_size)

    def workspace(self, integrator, model, state, newton: bool = False) -> "Workspace":
        """`state`'s workspace for `integrator`'s solve with this preconditioner (made on
        first use: Integrator.buffers; the coarse level's fields are part of it)."""
        return integrator.buffers(state, lambda: Workspace(
            model.particle_count, model.spring_count, model.altitude_count, model.face_count,
            model.hinge_count, newton,
            coarse.Layout(model.cloth, self.aggregate_size) if self.kind == "two-level"
            else None))


@backend.kernel_argument
class Workspace:
    """CG vectors, per-spring linearisation and the partial sums of one State's solve."""

    def __init__(self, particle_count: int, spring_count: int, altitude_count: int,
                 face_count: int, hinge_count: int, newton: bool = False,
                 layout: coarse.Layout | None = None):
        real = backend.real()
        n = particle_count
        self.block_count = math.ceil(n / BLOCK)
        fields = backend.FieldGroup()
        self.dv = fields.vector(3, real, n)
        self.r = fields.vector(3, real, n)
        self.z = fields.vector(3, real, n)
        self.p = fields.vector(3, real, n)
        self.ap = fields.vector(3, real, n)
        self.diagonal = fields.vector(3, real, n)
        self.spring_normal = fields.vector(3, real, max(spring_count, 1))
        self.spring_lateral = fields.scalar(real, max(spring_count, 1))
        # h^2 K + h D of each spring, once per end in the model's adjacency order (symmetric:
        # xx, yy, zz, xy, xz, yz), so A p reads them front to back
        self.adjacency_block = fields.vector(6, real, max(2 * spring_count, 1))
        self.altitude_normal = fields.vector(3, real, max(altitude_count, 1))
        self.altitude_weight = fields.scalar(real, max(4 * altitude_count, 1))   # g, per corner
        self.altitude_projection = fields.scalar(real, max(altitude_count, 1))   # G . (v or p)
        self.partial = fields.vector(2, real, self.block_count)
        self.partial_pap = fields.scalar(real, self.block_count)
        # each worker's copy of the solve's scalars and iteration count (plan.Once), a row
        # of ROW slots per worker
        self.scalar = fields.scalar(real, MAX_WORKERS * ROW)
        self.iterations = fields.scalar(ti.i32, MAX_WORKERS * ROW)
        implicit_elements.add_fields(self, fields, face_count, hinge_count)
        add_settings(self, fields)
        if newton:      # a Newton solve's start and the step's start (newton.py)
            self.origin_position = fields.vector(3, real, n)
            self.origin_velocity = fields.vector(3, real, n)
            self.step_position = fields.vector(3, real, n)
            self.step_velocity = fields.vector(3, real, n)
            self.partial_change = fields.scalar(real, self.block_count)
        self.two_level = layout is not None     # the coarse level's correction (coarse.py)
        if self.two_level:
            coarse.add_fields(self, fields, layout)
        fields.finalize(self)
        if self.two_level:
            coarse.upload_layout(self, layout)


@ti.func
def block_sum(ws: ti.template(), partial: ti.template(), zero):
    """Sum of the per-block partial sums `partial`, in block order (deterministic), from
    `zero` (0.0 or a zero vector, its type)."""
    total = zero
    for block in range(ws.block_count):
        total += partial[block]
    return total


@ti.func
def block_range(block, count):
    return block * BLOCK, ti.min((block + 1) * BLOCK, count)


def blocks(ws, body, *args) -> Loop:
    """body(*args) for every block of BLOCK particles (ITEM: the block), a team sharing them
    block by block (plan.Loop's chunk 1): a block's particles are a serial loop of their own,
    so a body of a few blocks (16 at 32 x 32) still runs on every worker, where slices of
    team.CHUNK blocks gave them all to one."""
    return Loop(ws.block_count, body, *args, chunk=1)


@ti.func
def system_row(model: ti.template(), state: ti.template(), forces: ti.template(),
               ws: ti.template(), i, h):
    """Particle i's row of the system at the linearisation: (K v's row, with v the State's
    velocities; the 3x3 diagonal of A = M (1 + h drag) - h D - h^2 K; 1.0 if the particle is
    free, 0.0 if pinned). Each term of energies.ROWS, in a fixed order, also keeps its
    blocks for the products."""
    free = ti.cast(model.particle_inv_mass[i] > 0, float)
    kv = ti.Vector([0.0, 0.0, 0.0])
    diagonal = model.particle_mass[i] * (1.0 + h * forces.drag) * ti.Vector([1.0, 1.0, 1.0])
    for term in ti.static(ROWS):
        kv, diagonal = term.implicit_start(model, state, forces, ws, i, h, kv, diagonal)
    return kv, diagonal, free


@ti.func
def start_row(ws: ti.template(), i, b, diagonal, free):
    """The CG start of particle i for right-hand side b (0 on a pin, whose row is the
    identity): dv = 0, r = b, p = z = r / diagonal; returns its (r . z, b . b)."""
    if free == 0:
        diagonal = ti.Vector([1.0, 1.0, 1.0])
    z = b / diagonal
    ws.dv[i] = ti.Vector([0.0, 0.0, 0.0])
    ws.r[i] = b
    ws.z[i] = z
    ws.p[i] = z
    ws.diagonal[i] = diagonal
    return b.dot(z), b.dot(b)


@ti.func
def apply_block(model: ti.template(), forces: ti.template(), ws: ti.template(), block,
                 now: ti.template()):
    """ap = A p on the particles of `block` (rows of pinned particles 0), and its partial
    sum of p . ap."""
    dt, drag = now.dt, forces.drag
    begin, end = block_range(block, model.particle_count)
    pap = 0.0
    for i in range(begin, end):
        free = ti.cast(model.particle_inv_mass[i] > 0, float)
        pi = ws.p[i]
        ap = model.particle_mass[i] * (1.0 + dt * drag) * pi
        for term in ti.static(ROWS):
            ap = term.implicit_product(model, ws, i, dt, ap)
        ap *= free
        ws.ap[i] = ap
        pap += pi.dot(ap)
    ws.partial_pap[block] = pap


@ti.func
def update_block(model: ti.template(), ws: ti.template(), block, now: ti.template()):
    """dv += alpha p, r -= alpha ap, z = r / diag on the particles of `block`; its partial
    sums of r . z and r . r."""
    alpha = ws.scalar[now.row * ROW + ALPHA]
    begin, end = block_range(block, model.particle_count)
    rz, rr = 0.0, 0.0
    for i in range(begin, end):
        ws.dv[i] = ws.dv[i] + alpha * ws.p[i]
        r = ws.r[i] - alpha * ws.ap[i]
        z = r / ws.diagonal[i]
        ws.r[i] = r
        ws.z[i] = z
        rz += r.dot(z)
        rr += r.dot(r)
    ws.partial[block] = ti.Vector([rz, rr])


@ti.func
def turn_block(model: ti.template(), ws: ti.template(), block, now: ti.template()):
    """p = z + beta p on the particles of `block` (z of the representative of a sewn
    particle: the module doc's P; with the coarse level's correction)."""
    beta = ws.scalar[now.row * ROW + BETA]
    begin, end = block_range(block, model.particle_count)
    for i in range(begin, end):
        z = ws.z[i]
        if ti.static(model.sewn):
            z = ws.z[model.particle_weld[i]]
        if ti.static(ws.two_level):
            z += coarse.correction(ws, i, now.row)
        ws.p[i] = z + beta * ws.p[i]


@ti.func
def coarse_level(model: ti.template(), forces: ti.template(), ws: ti.template(), item,
                 now: ti.template()):
    """The coarse level's A_c and its factor (coarse.assemble; a Loop of one item) at the
    first linearisation of a solve: a Newton solve's later iterations keep it (a fixed
    symmetric positive definite preconditioner for each of their CG solves, a little less
    close to their A: 109 CG iterations a step against 103 on issue 53's sheet at 1/120 s,
    for a quarter of the assemblies)."""
    if ws.iterations[now.row * ROW + NEWTON] == 0:
        coarse.assemble(model, forces, ws, now.dt)


@ti.func
def coarse_start(model: ti.template(), ws: ti.template(), block, now: ti.template()):
    """p = z + the coarse level's correction on the particles of `block` (the CG start)."""
    begin, end = block_range(block, model.particle_count)
    for i in range(begin, end):
        ws.p[i] = ws.p[i] + coarse.correction(ws, i, now.row)


@ti.func
def _group_free(model: ti.template(), g):
    """1.0 if no particle of sewn group g is pinned, else 0.0."""
    free = 1.0
    for k in range(model.weld_start[g], model.weld_start[g + 1]):
        if model.particle_inv_mass[model.weld_member[k]] <= 0:
            free = 0.0
    return free


@ti.func
def weld_start(model: ti.template(), ws: ti.template(), g):
    """Sewn group g's start as one particle: r = b and the diagonal summed on its
    representative (0 and the sum on its other members), z = p = r / diagonal on all."""
    first = model.weld_start[g]
    b = ti.Vector([0.0, 0.0, 0.0])
    diagonal = ti.Vector([0.0, 0.0, 0.0])
    for k in range(first, model.weld_start[g + 1]):
        b += ws.r[model.weld_member[k]]
        diagonal += ws.diagonal[model.weld_member[k]]
    b *= _group_free(model, g)
    z = b / diagonal
    for k in range(first, model.weld_start[g + 1]):
        i = model.weld_member[k]
        ws.r[i] = b if k == first else 0.0 * b
        ws.diagonal[i] = diagonal
        ws.z[i] = z
        ws.p[i] = z


@ti.func
def start_sums(model: ti.template(), ws: ti.template(), block):
    """The partial sums r . z and r . r of `block` (after the groups' start)."""
    begin, end = block_range(block, model.particle_count)
    rz, rr = 0.0, 0.0
    for i in range(begin, end):
        rz += ws.r[i].dot(ws.z[i])
        rr += ws.r[i].dot(ws.r[i])
    ws.partial[block] = ti.Vector([rz, rr])


@ti.func
def weld_product(model: ti.template(), ws: ti.template(), g):
    """Sewn group g's row of P^T A P p: A p summed on its representative, 0 on the others
    (0 on all in a pinned group). p . Ap's partial sums stand: p is the same on a group."""
    first = model.weld_start[g]
    total = ti.Vector([0.0, 0.0, 0.0])
    for k in range(first, model.weld_start[g + 1]):
        total += ws.ap[model.weld_member[k]]
    total *= _group_free(model, g)
    for k in range(first, model.weld_start[g + 1]):
        ws.ap[model.weld_member[k]] = total if k == first else 0.0 * total


@ti.func
def begin_solve(ws: ti.template(), now: ti.template()):
    """The start's r . z, r . r and b . b (r = b), in the worker's row; no iteration yet."""
    total = block_sum(ws, ws.partial, ti.Vector([0.0, 0.0]))
    if ti.static(ws.two_level):
        total[0] += coarse.solve(ws, ws.r, now.row)
    ws.scalar[now.row * ROW + RZ] = total[0]
    ws.scalar[now.row * ROW + RR] = total[1]
    ws.scalar[now.row * ROW + BB] = total[1]
    ws.iterations[now.row * ROW] = 0


@ti.func
def step_length(ws: ti.template(), now: ti.template()):
    """alpha = r . z / p . Ap."""
    ws.scalar[now.row * ROW + ALPHA] = ws.scalar[now.row * ROW + RZ] / block_sum(ws, ws.partial_pap, 0.0)


@ti.func
def next_direction(ws: ti.template(), now: ti.template()):
    """beta = new r . z / old r . z; the new r . z and r . r; one more iteration."""
    sums = block_sum(ws, ws.partial, ti.Vector([0.0, 0.0]))
    if ti.static(ws.two_level):
        sums[0] += coarse.solve(ws, ws.r, now.row)
    ws.scalar[now.row * ROW + BETA] = sums[0] / ws.scalar[now.row * ROW + RZ]
    ws.scalar[now.row * ROW + RZ] = sums[0]
    ws.scalar[now.row * ROW + RR] = sums[1]
    ws.iterations[now.row * ROW] = ws.iterations[now.row * ROW] + 1


@ti.func
def project_velocity(model: ti.template(), state: ti.template(), ws: ti.template(), a):
    """altitude_projection[a] = G_a . v_n."""
    project_altitude(model, ws, state.particle_velocity, a)


@ti.func
def gather_block(model: ti.template(), state: ti.template(), forces: ti.template(), block):
    """particle_force = f_n on the particles of `block` (springs evaluated)."""
    begin, end = block_range(block, model.particle_count)
    for i in range(begin, end):
        state.particle_force[i] = gather_force(model, state, forces, i, True)


@ti.func
def above_tolerance(ws: ti.template(), row):
    """|r|^2 > tolerance^2 |b|^2, in float64, on the worker's row (its first slot)."""
    return (ti.f64(ws.scalar[row + RR])
            > ws.settings[CG_TOLERANCE_SQUARED] * ti.f64(ws.scalar[row + BB]))


@ti.func
def unconverged(ws: ti.template(), now: ti.template()):
    """|r| > tolerance |b| and fewer than the cap's iterations (the settings: MOST_CG): CG
    goes on (b = 0, no load on a free particle: dv = 0 at once)."""
    row = now.row * ROW
    return above_tolerance(ws, row) and ws.iterations[row] < ti.i32(ws.settings[MOST_CG])


@ti.func
def count_ran_out(ws: ti.template(), now: ti.template()):
    """One more step whose CG stopped at its cap with |r| > tolerance |b| (RAN_OUT counts
    them in a launch: after_launch takes and clears it)."""
    row = now.row * ROW
    if above_tolerance(ws, row):
        ws.iterations[row + RAN_OUT] = ws.iterations[row + RAN_OUT] + 1


def linearisation(model, forces, ws, start: Loop) -> tuple:
    """The forces f at the State's positions and velocities, every term's linearisation
    there (a Fabric's hinges between its bending phases: implicit_elements), the forces
    gathered per particle, then `start` (a Loop over the blocks writing the right-hand side
    b, the 3x3 diagonal and the CG start r = b, p = z = r / diagonal) and the start's sums."""
    linear = force_loops(model, forces) + implicit_elements.linear_loops(model, forces, ws)
    if model.spring_count:
        linear += (Loop(model.spring_count, linearise_spring, model, STATE, forces, ws, ITEM),)
    if model.altitude_count:
        linear += (Loop(model.altitude_count, linearise_altitude, model, STATE, ws, ITEM),)
    gather = blocks(ws, gather_block, model, STATE, forces, ITEM)
    if model.altitude_count:
        begin = (Phase(gather, Loop(model.altitude_count, project_velocity, model, STATE, ws,
                                    ITEM)),
                 Phase(start))
    else:
        begin = (Phase(gather, start),)
    if model.sewn:
        begin += (Phase(Loop(model.weld_count, weld_start, model, ws, ITEM)),
                  Phase(blocks(ws, start_sums, model, ws, ITEM)))
    bending = bending_phases(model, *implicit_elements.bending_loops(model, ws))
    solve_start = (Once(begin_solve, ws, NOW),)
    if ws.two_level:
        solve_start = ((Phase(Loop(1, coarse_level, model, forces, ws, ITEM, NOW)),)
                       + solve_start
                       + (Phase(blocks(ws, coarse_start, model, ws, ITEM, NOW)),))
    return (wind.phases(model, forces) + ((Phase(*linear),) if linear else ()) + bending
            + begin + solve_start)


def system_product(model, forces, ws) -> tuple:
    """ap = A p and its partial sums of p . ap."""
    project = ()
    if model.altitude_count:
        project = (Loop(model.altitude_count, project_altitude, model, ws, ws.p, ITEM),)
    weld = ((Phase(Loop(model.weld_count, weld_product, model, ws, ITEM)),) if model.sewn
            else ())
    return (implicit_elements.product_phases(model, ws, project)
            + (Phase(blocks(ws, apply_block, model, forces, ws, ITEM, NOW)),) + weld)


def solve(model, forces, ws) -> Until:
    """Preconditioned CG from the start `linearisation` left, until |r| <= tolerance |b|
    or the cap's iterations (ws.settings: CG_TOLERANCE_SQUARED, MOST_CG): dv in ws.dv."""
    iteration = (system_product(model, forces, ws)
                 + (Once(step_length, ws, NOW),
                    Phase(blocks(ws, update_block, model, ws, ITEM, NOW)),
                    Once(next_direction, ws, NOW),
                    Phase(blocks(ws, turn_block, model, ws, ITEM, NOW))))
    return Until(unconverged, *iteration, args=(ws, NOW))
