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

The system is solved matrix-free by conjugate_gradients.py; CG starts from dv = 0 (starting
from the previous step's dv was measured: no fewer iterations on a swinging 24 x 24 cloth).
benchmarks/implicit_solver.py compares this with Taichi's sparse Cholesky.
"""


import math

import taichi as ti

from ..inputs import limits
from ..inputs.validation import count, finite_number, require
from ..runtime.plan import ITEM, NOW, STATE, Once, Phase
from ..state import store_particle
from . import conjugate_gradients, fused
from .base import Integrator, report_unconverged, take_ran_out
from .conjugate_gradients import (
    BB,
    RAN_OUT,
    RR,
    TYPICAL_ITERATIONS,
    Preconditioner,
    block_range,
    blocks,
    start_row,
    system_row,
)


@ti.func
def _start_block(model: ti.template(), state: ti.template(), forces: ti.template(),
                 ws: ti.template(), block, now: ti.template()):
    """Particles of `block`: right-hand side b = h (f_n + h K v_n), the 3x3 diagonal of A
    (preconditioner) and the CG start dv = 0, r = b, p = z = r / diagonal; the block's
    partial sums of r . z and b . b."""
    dt = now.dt
    begin, end = block_range(block, model.particle_count)
    rz, bb = 0.0, 0.0
    for i in range(begin, end):
        kv, diagonal, free = system_row(model, state, forces, ws, i, dt)
        b = free * dt * (state.particle_force[i] - dt * kv)
        row_rz, row_bb = start_row(ws, i, b, diagonal, free)
        rz += row_rz
        bb += row_bb
    ws.partial[block] = ti.Vector([rz, bb])


@ti.func
def _advance_block(model: ti.template(), state: ti.template(), ws: ti.template(), block,
                   now: ti.template()):
    """v_{n+1} = v_n + dv, x_{n+1} = x_n + h v_{n+1} on the particles of `block`."""
    begin, end = block_range(block, model.particle_count)
    for i in range(begin, end):
        v = state.particle_velocity[i] + ws.dv[i]
        store_particle(state, i, state.particle_position[i] + now.dt * v, v, now.step)


class ImplicitEuler(Integrator):
    """Baraff-Witkin linearised backward Euler (module doc), one CG solve per step.

    tolerance: CG stops when |r| <= tolerance |b| (relative residual), in (0, 1).
    max_iterations: CG iterations per step at most, >= 1; a step that needs more keeps its
        best iterate (still damped, not exact), is counted in unconverged_solves and, the first
        time, warned of. last_iterations and last_residual report the latest solve.
    preconditioner, aggregate_size: CG's (conjugate_gradients.Preconditioner).
    Order 1. Unconditionally stable for the linearised springs: stiff springs and large steps
    damp out (numerical dissipation grows with h k / m) instead of blowing up.
    """

    name = "implicit_euler"
    order = 1
    step_limited = False
    runtime_options = ("tolerance", "max_iterations")

    def __init__(self, *, tolerance: float = 1e-5, max_iterations: int = 200,
                 preconditioner: str = "two-level", aggregate_size: int | None = None):
        self.tolerance = finite_number("ImplicitEuler.tolerance", tolerance, 0.0, strict=True)
        require(self.tolerance < 1.0, "ImplicitEuler.tolerance", tolerance, "a number in (0, 1)")
        self.max_iterations = count("ImplicitEuler.max_iterations", max_iterations, limits.ITERATIONS)
        self.preconditioner = Preconditioner("ImplicitEuler", preconditioner, aggregate_size)
        self.last_iterations = 0
        self.last_residual = 0.0
        self.unconverged_solves = self.ran_out_pending = 0
        self.warned_unconverged = False

    def options(self):
        return {"tolerance": self.tolerance, "max_iterations": self.max_iterations,
                **self.preconditioner.options()}

    def settings_values(self):
        """conjugate_gradients' slots CG_TOLERANCE_SQUARED and MOST_CG."""
        return (self.tolerance ** 2, float(self.max_iterations))

    def copy_reports(self, stepper):
        self.last_iterations = stepper.last_iterations
        self.last_residual = stepper.last_residual
        report_unconverged(self, stepper,
                           f"CG stopped at max_iterations={self.max_iterations} with its "
                           f"relative residual above tolerance={self.tolerance:g}",
                           "such a step is damped, not the implicit step asked for. Raise "
                           "the cap or take smaller steps")

    def workspace(self, model, state):
        return self.preconditioner.workspace(self, model, state)

    def buffer_key(self):
        return (type(self), *self.preconditioner.key())

    def step_work(self, model):
        return (2 + 2 * TYPICAL_ITERATIONS) * fused.spring_work(model)

    def after_launch(self, work):
        self.last_iterations = int(work.iterations[0])
        bb = work.scalar[BB]
        self.last_residual = math.sqrt(work.scalar[RR] / bb) if bb > 0 else 0.0
        self.ran_out_pending += take_ran_out(work, RAN_OUT)

    def linearisation(self, model, forces, ws):
        """f_n and the linearisation at x_n, the CG start b = h (f_n + h K v_n) (a part of
        the step plan.run can launch alone: benchmarks/implicit_solver.py)."""
        start = blocks(ws, _start_block, model, STATE, forces, ws, ITEM, NOW)
        return conjugate_gradients.linearisation(model, forces, ws, start)

    def system_product(self, model, forces, ws):
        """ws.ap = A ws.p (likewise)."""
        return conjugate_gradients.system_product(model, forces, ws)

    def phases(self, model, forces, ws):
        """The linearisation, preconditioned CG until converged (conjugate_gradients.py), the
        step."""
        return (self.linearisation(model, forces, ws)
                + (conjugate_gradients.solve(model, forces, ws),
                   Once(conjugate_gradients.count_ran_out, ws, NOW))
                + (Phase(blocks(ws, _advance_block, model, STATE, ws, ITEM, NOW)),))
