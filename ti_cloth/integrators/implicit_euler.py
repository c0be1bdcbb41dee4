"""Linearised backward Euler (Baraff & Witkin 1998), solved by matrix-free conjugate gradients.

One Newton step of backward Euler: with K = df/dx and D = df/dv at (x_n, v_n),

    (M - h D - h^2 K) dv = h (f_n + h K v_n),   v_{n+1} = v_n + dv,   x_{n+1} = x_n + h v_{n+1}.

Per spring (Stuyck eq. 4.5), with n the unit direction and l the current length,
df_i/dx_i = -k (n n^T + c (I - n n^T)), c = 1 - L / l. Under compression c < 0 makes K
indefinite; c is clamped at 0 (Choi & Ko 2002) so the system matrix stays symmetric positive
definite and CG applies. A Fabric's triangles and hinges enter K and D through their
Gauss-Newton Hessians, projected likewise (implicit_elements.py). Damping: axial df_i/dv_i = -kd n n^T, relative (eq. 4.7) -kd I, drag
-drag m I. An altitude spring (Selle et al. 2008; energies/altitude.py) contributes
-k G G^T to K and -kd G G^T to D, G = g (x) n its altitude's gradient: its curvature term
-k (h - h0) d^2h/dx^2 is dropped, as c's compressed part is, keeping A positive definite. Wind is treated explicitly (it enters f_n only). Pins: dv is filtered to zero on
particles of inverse mass 0 (Baraff & Witkin's modified CG with S = 0 there).

The system is never assembled: each CG iteration gathers A p per particle over its springs in
the Model's fixed adjacency order, and every dot product is summed in fixed blocks, so a run is
bit-for-bit repeatable. Jacobi (3x3-diagonal) preconditioner; CG starts from dv = 0 (starting
from the previous step's dv was measured: no fewer iterations on a swinging 24 x 24 cloth).
benchmarks/implicit_solver.py compares this with Taichi's sparse Cholesky.
"""


import math

import taichi as ti

from ..energies import ROWS
from ..energies.altitude import (
    linearise_altitude,
    project_altitude,
)
from ..energies.bending import bending_phases
from ..energies.springs import linearise_spring
from ..inputs import limits
from ..inputs.validation import count, finite_number, require
from ..physics import wind
from ..physics.forces import force_loops, gather_force
from ..runtime import backend
from ..runtime.plan import ITEM, NOW, STATE, Loop, Once, Phase, Until
from ..runtime.team import MAX_WORKERS
from ..state import store_particle
from . import fused, implicit_elements
from .base import Integrator

BLOCK = 64                      # particles per partial sum of a dot product
TYPICAL_ITERATIONS = 20         # CG iterations a step is assumed to take (sizing launches)
ALPHA, RZ, RR, BB, BETA = range(5)  # slots of a row of the workspace's scalar field
ROW = 16                        # slots per row (a worker's row fills its own cache line)


@backend.kernel_argument
class _Workspace:
    """CG vectors, per-spring linearisation and the partial sums of one State's solve."""

    def __init__(self, particle_count: int, spring_count: int, altitude_count: int,
                 face_count: int, hinge_count: int):
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
        fields.finalize(self)


@ti.func
def _project_velocity(model: ti.template(), state: ti.template(), ws: ti.template(), a):
    """altitude_projection[a] = G_a . v_n."""
    project_altitude(model, ws, state.particle_velocity, a)


@ti.func
def _total(ws: ti.template(), partial: ti.template(), zero):
    """Sum of the per-block partial sums `partial`, in block order (deterministic), from
    `zero` (0.0 or a zero vector, its type)."""
    total = zero
    for block in range(ws.block_count):
        total += partial[block]
    return total


@ti.func
def _block_range(block, count):
    return block * BLOCK, ti.min((block + 1) * BLOCK, count)


@ti.func
def _gather_block(model: ti.template(), state: ti.template(), forces: ti.template(), block):
    """particle_force = f_n on the particles of `block` (springs evaluated)."""
    begin, end = _block_range(block, model.particle_count)
    for i in range(begin, end):
        state.particle_force[i] = gather_force(model, state, forces, i, True)


@ti.func
def _start_block(model: ti.template(), state: ti.template(), forces: ti.template(),
                 ws: ti.template(), block, now: ti.template()):
    """Particles of `block`: right-hand side b = h (f_n + h K v_n), the 3x3 diagonal of A
    (preconditioner) and the CG start dv = 0, r = b, p = z = r / diagonal; the block's
    partial sums of r . z and b . b."""
    dt, drag = now.dt, forces.drag
    begin, end = _block_range(block, model.particle_count)
    rz, bb = 0.0, 0.0
    for i in range(begin, end):
        free = ti.cast(model.particle_inv_mass[i] > 0, float)
        kv = ti.Vector([0.0, 0.0, 0.0])
        diagonal = model.particle_mass[i] * (1.0 + dt * drag) * ti.Vector([1.0, 1.0, 1.0])
        for term in ti.static(ROWS):          # energies.ROWS, in a fixed order
            kv, diagonal = term.implicit_start(model, state, forces, ws, i, dt, kv, diagonal)
        b = free * dt * (state.particle_force[i] - dt * kv)
        if free == 0:
            diagonal = ti.Vector([1.0, 1.0, 1.0])   # a pin's row is the identity (b = 0 there)
        z = b / diagonal
        ws.dv[i] = ti.Vector([0.0, 0.0, 0.0])
        ws.r[i] = b
        ws.z[i] = z
        ws.p[i] = z
        ws.diagonal[i] = diagonal
        rz += b.dot(z)
        bb += b.dot(b)
    ws.partial[block] = ti.Vector([rz, bb])


@ti.func
def _apply_block(model: ti.template(), forces: ti.template(), ws: ti.template(), block,
                 now: ti.template()):
    """ap = A p on the particles of `block` (rows of pinned particles 0), and its partial
    sum of p . ap."""
    dt, drag = now.dt, forces.drag
    begin, end = _block_range(block, model.particle_count)
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
def _update_block(model: ti.template(), ws: ti.template(), block, now: ti.template()):
    """dv += alpha p, r -= alpha ap, z = r / diag on the particles of `block`; its partial
    sums of r . z and r . r."""
    alpha = ws.scalar[now.row * ROW + ALPHA]
    begin, end = _block_range(block, model.particle_count)
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
def _turn_block(model: ti.template(), ws: ti.template(), block, now: ti.template()):
    """p = z + beta p on the particles of `block`."""
    beta = ws.scalar[now.row * ROW + BETA]
    begin, end = _block_range(block, model.particle_count)
    for i in range(begin, end):
        ws.p[i] = ws.z[i] + beta * ws.p[i]


@ti.func
def _advance_block(model: ti.template(), state: ti.template(), ws: ti.template(), block,
                   now: ti.template()):
    """v_{n+1} = v_n + dv, x_{n+1} = x_n + h v_{n+1} on the particles of `block`."""
    begin, end = _block_range(block, model.particle_count)
    for i in range(begin, end):
        v = state.particle_velocity[i] + ws.dv[i]
        store_particle(state, i, state.particle_position[i] + now.dt * v, v, now.step)


@ti.func
def _begin_solve(ws: ti.template(), now: ti.template()):
    """The start's r . z, r . r and b . b (r = b), in the worker's row; no iteration yet."""
    total = _total(ws, ws.partial, ti.Vector([0.0, 0.0]))
    ws.scalar[now.row * ROW + RZ] = total[0]
    ws.scalar[now.row * ROW + RR] = total[1]
    ws.scalar[now.row * ROW + BB] = total[1]
    ws.iterations[now.row * ROW] = 0


@ti.func
def _step_length(ws: ti.template(), now: ti.template()):
    """alpha = r . z / p . Ap."""
    ws.scalar[now.row * ROW + ALPHA] = ws.scalar[now.row * ROW + RZ] / _total(ws, ws.partial_pap, 0.0)


@ti.func
def _next_direction(ws: ti.template(), now: ti.template()):
    """beta = new r . z / old r . z; the new r . z and r . r; one more iteration."""
    sums = _total(ws, ws.partial, ti.Vector([0.0, 0.0]))
    ws.scalar[now.row * ROW + BETA] = sums[0] / ws.scalar[now.row * ROW + RZ]
    ws.scalar[now.row * ROW + RZ] = sums[0]
    ws.scalar[now.row * ROW + RR] = sums[1]
    ws.iterations[now.row * ROW] = ws.iterations[now.row * ROW] + 1


class ImplicitEuler(Integrator):
    """Baraff-Witkin linearised backward Euler (module doc), one CG solve per step.

    tolerance: CG stops when |r| <= tolerance |b| (relative residual), in (0, 1).
    max_iterations: CG iterations per step at most, >= 1; a step that needs more keeps its
        best iterate (still damped, not exact). last_iterations and last_residual report the
        latest solve.
    Order 1. Unconditionally stable for the linearised springs: stiff springs and large steps
    damp out (numerical dissipation grows with h k / m) instead of blowing up.
    """

    name = "implicit_euler"
    order = 1
    step_limited = False

    def __init__(self, *, tolerance: float = 1e-5, max_iterations: int = 200):
        self.tolerance = finite_number("ImplicitEuler.tolerance", tolerance, 0.0, strict=True)
        require(self.tolerance < 1.0, "ImplicitEuler.tolerance", tolerance, "a number in (0, 1)")
        self.max_iterations = count("ImplicitEuler.max_iterations", max_iterations, limits.ITERATIONS)
        self.last_iterations = 0
        self.last_residual = 0.0

    def options(self):
        return {"tolerance": self.tolerance, "max_iterations": self.max_iterations}

    def copy_reports(self, stepper):
        self.last_iterations = stepper.last_iterations
        self.last_residual = stepper.last_residual

    def workspace(self, model, state):
        return self.buffers(state, lambda: _Workspace(model.particle_count, model.spring_count,
                                                      model.altitude_count, model.face_count,
                                                      model.hinge_count))

    def step_work(self, model):
        return (2 + 2 * TYPICAL_ITERATIONS) * fused.spring_work(model)

    def after_launch(self, work):
        self.last_iterations = int(work.iterations[0])
        bb = work.scalar[BB]
        self.last_residual = math.sqrt(work.scalar[RR] / bb) if bb > 0 else 0.0

    @ti.func
    def unconverged(self, ws: ti.template(), now: ti.template()):
        """|r|^2 > tolerance^2 |b|^2 (in float64) and iterations left: CG goes on (b = 0,
        no load on a free particle: dv = 0 at once)."""
        row = now.row
        return (ti.f64(ws.scalar[row * ROW + RR]) > ti.f64(self.tolerance ** 2) * ti.f64(ws.scalar[row * ROW + BB])
                and ws.iterations[row * ROW] < self.max_iterations)

    def linearisation(self, model, forces, ws):
        """f_n, the linearisation at x_n and the CG start (r = b, p = z = r / diagonal); a
        Fabric's hinges are linearised between its bending phases (implicit_elements)."""
        linear = force_loops(model, forces) + implicit_elements.linear_loops(model, forces, ws)
        if model.spring_count:
            linear += (Loop(model.spring_count, linearise_spring, model, STATE, forces, ws, ITEM),)
        if model.altitude_count:
            linear += (Loop(model.altitude_count, linearise_altitude, model, STATE, ws, ITEM),)
        gather = Loop(ws.block_count, _gather_block, model, STATE, forces, ITEM)
        start = Loop(ws.block_count, _start_block, model, STATE, forces, ws, ITEM, NOW)
        if model.altitude_count:
            begin = (Phase(gather, Loop(model.altitude_count, _project_velocity, model, STATE, ws,
                                        ITEM)),
                     Phase(start))
        else:
            begin = (Phase(gather, start),)
        bending = bending_phases(model, *implicit_elements.bending_loops(model, ws))
        return (wind.phases(model, forces) + ((Phase(*linear),) if linear else ()) + bending
                + begin + (Once(_begin_solve, ws, NOW),))

    def system_product(self, model, forces, ws):
        """ap = A p and its partial sums of p . ap."""
        project = ()
        if model.altitude_count:
            project = (Loop(model.altitude_count, project_altitude, model, ws, ws.p, ITEM),)
        return (implicit_elements.product_phases(model, ws, project)
                + (Phase(Loop(ws.block_count, _apply_block, model, forces, ws, ITEM, NOW)),))

    def phases(self, model, forces, ws):
        """The linearisation, preconditioned CG until converged (three synchronisation points
        per iteration: after A p, the update, the new direction; every worker sums the same
        partial sums in block order, so all take the same decisions), the step."""
        iteration = (self.system_product(model, forces, ws)
                     + (Once(_step_length, ws, NOW),
                        Phase(Loop(ws.block_count, _update_block, model, ws, ITEM, NOW)),
                        Once(_next_direction, ws, NOW),
                        Phase(Loop(ws.block_count, _turn_block, model, ws, ITEM, NOW))))
        return (self.linearisation(model, forces, ws)
                + (Until(self.unconverged, *iteration, args=(ws, NOW)),)
                + (Phase(Loop(ws.block_count, _advance_block, model, STATE, ws, ITEM, NOW)),))
