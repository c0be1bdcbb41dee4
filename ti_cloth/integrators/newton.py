"""A backward Euler sub-step solved to convergence by Newton's method: the implicit stage that
implicit midpoint and TR-BDF2 are made of.

From an origin (x^, v^) and a sub-step s, find v with

    g(v) = M (v - v^) - s f(x^ + s v, v) = 0,

f the total force (springs, a Fabric's membrane and bending, altitude springs, gravity, drag,
wind). Newton's iteration k linearises f at the iterate, x_k = x^ + s v_k:

    (M - s D - s^2 K) dv = -g(v_k) = s f(x_k, v_k) - M (v_k - v^),   v_{k+1} = v_k + dv,

with the terms' K = df/dx and D = df/dv (energies.ROWS, their indefinite parts projected away:
conjugate_gradients.py solves the system, to a relative residual cg_tolerance). The residual is
the exact force, so the iteration converges to the exact implicit solution whatever the
Hessians leave out; it stops when the largest position update s |dv| is at most `tolerance`
[m], after at least LEAST_NEWTON iterations (or after most_newton). The first update, from
the predictor, says how far the predictor was, not how far its result is: a small step
makes it small however inexact its linear solve, and with CG cut at a tenth of its residual
one iteration a step at 1/960 s left a denim sheet 120 mm off in 0.3 s where two leave
0.7 mm (docs/performance.md). It starts from the explicit predictor v_0 = v^. A pin
(inverse mass 0) keeps v^: its row is the identity and its right-hand side 0. Implicit Euler
(implicit_euler.py) is one such iteration from x_n with s = h, its linearisation at x_n
instead of at the predictor.

Every sum is over fixed blocks in block order and the largest update a maximum (exact in
any order): the bits do not depend on the plan or the thread count.
"""

import copy
from typing import ClassVar

import taichi as ti

from ..inputs import limits
from ..inputs.validation import count, finite_number, require
from ..runtime.plan import ITEM, NOW, STATE, Once, Phase, Until
from . import conjugate_gradients, fused
from .base import Integrator, report_unconverged, take_ran_out
from .conjugate_gradients import (
    CG,
    CG_TOTAL,
    CHANGE,
    MOST_NEWTON,
    NEWTON,
    NEWTON_TOLERANCE,
    RAN_OUT,
    ROW,
    TYPICAL_ITERATIONS,
    Preconditioner,
    block_range,
    blocks,
    start_row,
    system_row,
)

TYPICAL_NEWTON = 3         # Newton iterations a solve is assumed to take (sizing launches)
LEAST_NEWTON = 2           # iterations before the update test can stop a solve (module doc)
# what a solve stopped at its cap means, and what to do (the warning: base.report_unconverged)
UNCONVERGED = ("such a step is not the implicit step asked for, and implicit midpoint's "
               "doubles its half step's error. Newton stalls whatever the cap where the "
               "cloth starts a step compressed (a gathered garment, a fold): its triangles "
               "buckle faster than a large step resolves (docs/integrators.md, \"Compressed "
               "cloth\"): a Fabric's compression below 1 (0.05) lets TR-BDF2 converge on "
               "mildly compressed cloth; use xpbd for garments; elsewhere raise most_newton or "
               "take smaller steps")


@ti.func
def _start_block(model: ti.template(), state: ti.template(), forces: ti.template(),
                 ws: ti.template(), block, now: ti.template()):
    """Particles of `block`: b = s f(x_k, v_k) - M (v_k - v^), the 3x3 diagonal of
    A = M (1 + s drag) - s D - s^2 K and the CG start dv = 0, r = b, p = z = r / diagonal;
    the block's partial sums of r . z and b . b."""
    s = now.dt
    begin, end = block_range(block, model.particle_count)
    rz, bb = 0.0, 0.0
    for i in range(begin, end):
        _, diagonal, free = system_row(model, state, forces, ws, i, s)
        b = free * (s * state.particle_force[i]
                    - model.particle_mass[i] * (state.particle_velocity[i] - ws.origin_velocity[i]))
        row_rz, row_bb = start_row(ws, i, b, diagonal, free)
        rz += row_rz
        bb += row_bb
    ws.partial[block] = ti.Vector([rz, bb])


@ti.func
def _update_block(model: ti.template(), state: ti.template(), ws: ti.template(), block,
                  now: ti.template()):
    """v_{k+1} = v_k + dv and x_{k+1} = x^ + s v_{k+1} on the particles of `block`; the
    block's largest position update s |dv|."""
    s = now.dt
    begin, end = block_range(block, model.particle_count)
    change = 0.0
    for i in range(begin, end):
        v = state.particle_velocity[i] + ws.dv[i]
        state.particle_velocity[i] = v
        state.particle_position[i] = ws.origin_position[i] + s * v
        change = ti.max(change, s * ws.dv[i].norm())
    ws.partial_change[block] = change


@ti.func
def _begin_newton(ws: ti.template(), now: ti.template()):
    """No Newton iteration yet in the worker's row."""
    ws.iterations[now.row * ROW + NEWTON] = 0
    ws.iterations[now.row * ROW + CG_TOTAL] = 0


@ti.func
def _end_iteration(ws: ti.template(), now: ti.template()):
    """The iteration's largest update (a maximum over the blocks) and the counts."""
    change = 0.0
    for block in range(ws.block_count):
        change = ti.max(change, ws.partial_change[block])
    row = now.row * ROW
    ws.scalar[row + CHANGE] = change
    ws.iterations[row + NEWTON] = ws.iterations[row + NEWTON] + 1
    ws.iterations[row + CG_TOTAL] = ws.iterations[row + CG_TOTAL] + ws.iterations[row + CG]


@ti.func
def _moved_more(ws: ti.template(), row):
    """The last iteration moved a particle by more than the tolerance (the settings'
    NEWTON_TOLERANCE, compared in the working precision: `float` is Taichi's default_fp)."""
    return ws.scalar[row + CHANGE] > ti.cast(ws.settings[NEWTON_TOLERANCE], float)


@ti.func
def _unconverged(ws: ti.template(), now: ti.template()):
    """Fewer than LEAST_NEWTON iterations (and the cap, the settings' MOST_NEWTON), or the
    last one moved a particle by more than the tolerance and fewer than the cap have run."""
    row = now.row * ROW
    done = ws.iterations[row + NEWTON]
    most = ti.i32(ws.settings[MOST_NEWTON])
    return done < ti.min(LEAST_NEWTON, most) or (_moved_more(ws, row) and done < most)


@ti.func
def _count_ran_out(ws: ti.template(), now: ti.template()):
    """One more solve that stopped at most_newton with its last update above the tolerance
    (RAN_OUT counts them in a launch: after_launch takes and clears it)."""
    row = now.row * ROW
    if _moved_more(ws, row):
        ws.iterations[row + RAN_OUT] = ws.iterations[row + RAN_OUT] + 1


@ti.func
def predict(model: ti.template(), state: ti.template(), ws: ti.template(), i,
            now: ti.template()):
    """The explicit predictor of particle i's solve: x = x^ + s v^, v = v^."""
    v = ws.origin_velocity[i]
    state.particle_velocity[i] = v
    state.particle_position[i] = ws.origin_position[i] + now.dt * v


class NewtonSettings:
    """The options of a Newton-solved implicit integrator, checked (module doc).

    tolerance: Newton stops when no particle moved more than this [m] in its last
        iteration (after at least LEAST_NEWTON of them), > 0.
    most_newton: Newton iterations per solve at most, >= 1.
    cg_tolerance: each linear solve's relative residual, in (0, 1).
    most_cg: CG iterations per linear solve at most, >= 1.
    preconditioner, aggregate_size: each linear solve's (conjugate_gradients.Preconditioner).
    """

    def __init__(self, owner: str, tolerance: float, most_newton: int, cg_tolerance: float,
                 most_cg: int, preconditioner: str, aggregate_size: int | None):
        self.tolerance = finite_number(f"{owner}.tolerance", tolerance, 0.0, strict=True,
                                       unit="m")
        self.most_newton = count(f"{owner}.most_newton", most_newton, limits.ITERATIONS)
        self.cg_tolerance = finite_number(f"{owner}.cg_tolerance", cg_tolerance, 0.0,
                                          strict=True)
        require(self.cg_tolerance < 1.0, f"{owner}.cg_tolerance", cg_tolerance,
                "a number in (0, 1)")
        self.most_cg = count(f"{owner}.most_cg", most_cg, limits.ITERATIONS)
        self.preconditioner = Preconditioner(owner, preconditioner, aggregate_size)

    def options(self) -> dict:
        return {"tolerance": self.tolerance, "most_newton": self.most_newton,
                "cg_tolerance": self.cg_tolerance, "most_cg": self.most_cg,
                **self.preconditioner.options()}


def solve(model, forces, ws) -> tuple:
    """The nodes of one solve (module doc) from the origin in ws.origin_position and
    origin_velocity, the State holding the predictor; the State ends on the solution. DT and
    NOW are the sub-step s (wrap in plan.substep). Its tolerances and caps are ws's run-time
    settings (NewtonIntegrator.settings_values)."""
    start = blocks(ws, _start_block, model, STATE, forces, ws, ITEM, NOW)
    iteration = (conjugate_gradients.linearisation(model, forces, ws, start)
                 + (conjugate_gradients.solve(model, forces, ws),
                    Phase(blocks(ws, _update_block, model, STATE, ws, ITEM, NOW)),
                    Once(_end_iteration, ws, NOW)))
    return (Once(_begin_newton, ws, NOW),
            Until(_unconverged, *iteration, args=(ws, NOW)),
            Once(_count_ran_out, ws, NOW))


class NewtonIntegrator(Integrator):
    """An integrator whose step is `solves` backward-Euler stages solved by solve(): the
    options, workspace, launch sizing and reports they share.

    tolerance, most_newton, cg_tolerance, most_cg, preconditioner, aggregate_size: each
        solve's (NewtonSettings).
    last_newton and last_cg report the latest solve's Newton and CG iterations;
    unconverged_solves counts the solves (a step has `solves`) that stopped at most_newton
    with their last update above the tolerance (the first warned of).
    """

    step_limited = False
    solves: ClassVar[int]
    runtime_options = ("tolerance", "most_newton", "cg_tolerance", "most_cg")
    # Newton stopped at 0.1 mm and each CG at a tenth of its residual, as
    # benchmarks/trade_vs_newton.py runs them: on issue 53's 32² denim at 1/60 and 1/120 s
    # within 0.1 mm of the converged solves' error (docs/performance.md)
    presets = {"loose": {"tolerance": 1e-4, "cg_tolerance": 0.1}}

    def __init__(self, *, tolerance: float = 1e-6, most_newton: int = 8,
                 cg_tolerance: float = 1e-3, most_cg: int = 500,
                 preconditioner: str = "two-level", aggregate_size: int | None = None):
        self.settings = NewtonSettings(type(self).__name__, tolerance, most_newton,
                                       cg_tolerance, most_cg, preconditioner, aggregate_size)
        self.last_newton = self.last_cg = 0
        self.unconverged_solves = self.ran_out_pending = 0
        self.warned_unconverged = False

    def options(self):
        return self.settings.options()

    def settings_values(self):
        """conjugate_gradients' slots CG_TOLERANCE_SQUARED, MOST_CG, NEWTON_TOLERANCE and
        MOST_NEWTON."""
        s = self.settings
        return (s.cg_tolerance ** 2, float(s.most_cg), s.tolerance, float(s.most_newton))

    def take_settings(self, integrator):
        self.settings = copy.copy(integrator.settings)

    def workspace(self, model, state):
        return self.settings.preconditioner.workspace(self, model, state, newton=True)

    def buffer_key(self):
        return (type(self), *self.settings.preconditioner.key())

    def step_work(self, model):
        return (self.solves * TYPICAL_NEWTON * (2 + 2 * TYPICAL_ITERATIONS)
                * fused.spring_work(model))

    def after_launch(self, work):
        self.last_newton = int(work.iterations[NEWTON])
        self.last_cg = int(work.iterations[CG_TOTAL])
        self.ran_out_pending += take_ran_out(work, RAN_OUT)

    def copy_reports(self, stepper):
        self.last_newton, self.last_cg = stepper.last_newton, stepper.last_cg
        settings = self.settings
        report_unconverged(self, stepper,
                           f"Newton stopped at most_newton={settings.most_newton} with its "
                           f"last update above tolerance={settings.tolerance:g} m",
                           UNCONVERGED)
