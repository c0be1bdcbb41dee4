"""A six-stage, second-order explicit Runge-Kutta whose stability polynomial is fitted to the
spectrum of Rayleigh-damped cloth: where damping limits symplectic Euler's step, accurate
explicit steps longer than its per force evaluation (1.76x on issue 53's 32² denim sheet,
2.11x at 64²; below 1x where damping barely limits it: docs/integrators.md, "A stabilized
explicit step").

A Fabric damps every element in proportion to its stiffness (Rayleigh damping, beta the
damping time): a mode of angular frequency w has damping rate g = beta w^2, and the
eigenvalues of x'' = -w^2 x - g x' lie on the circle |1 + beta lambda| = 1 (under-damped) or
on the negative real axis (over-damped, beta w > 2). Symplectic Euler's step is then limited
by the damping, h^2 w^2 + 2 h beta w^2 <= 4, far below its undamped 2 / w on a fine mesh
(docs/performance.md, "What limits the explicit step"). A Runge-Kutta method of s stages
applies to each mode a polynomial R(h lambda) of degree s; it is stable where |R| <= 1 on
every h lambda of the body. Which polynomial holds that spectrum at the largest step depends
on one number, gamma = beta w_max / 2 (the stiffest mode's damping ratio). POLYNOMIALS holds,
for a grid of gamma, the order-2 polynomial of degree 6 that does at every step up to the
largest, found as Ketcheson & Ahmadia find optimal stability polynomials ("Optimal
stability polynomials for numerical integration of initial value problems", CAMCoS 7(2),
2012). Each holds the set with a margin: |R| is at most 0.9 (or the mode's own decay) away
from 0, so that modes a little off the Rayleigh set (the membrane's undamped geometric
stiffness, the pins) stay stable, as in damped Chebyshev methods. There is no row past
gamma = 1.47: beyond it the polynomials hug the over-damped modes, and a garment diverged
at half their predicted step (tools/stability_polynomials.py says why each condition). For
each body the integrator takes the row whose exact |R| on that body's own spectrum allows
the largest step (fit, stable_step). The polynomial is written as

    Y_0 = y_n,   Y_k = y_n + alpha_k h f(Y_{k-1}) (k = 1 .. 6),   y_{n+1} = Y_6,

with y = (x, v), f = (v, M^-1 f(x, v)), so R(z) = 1 + alpha_6 z (1 + alpha_5 z (1 + ...)):
alpha_6 = 1 and alpha_5 = 1/2 (order 2 for any smooth forces: the weights sum to 1 and the
last stage is taken at the middle of the step), alpha_k = c_{7-k} / c_{6-k} below, c the
polynomial's coefficients (the chains of stabilized Runge-Kutta methods: van der Houwen &
Sommeijer, "On the internal stability of explicit, m-stage Runge-Kutta methods for large
m-values", ZAMM 60, 1980). The step costs six force evaluations, each as a symplectic
Euler step does.

The rule needs damping: on an undamped mode |R(i y)| > 1 for small y (every order-2
polynomial of this family but the one of the imaginary axis), so a body with no damping, or
whose damping leaves some stiff part undamped, has no stable step (stable_dt 0, dt="auto"
refused).
"""

import math
import weakref

import numpy as np
import taichi as ti

from ..body.modes import row_bounds, stiffest_mode
from ..physics import wind
from ..physics.forces import gather_force, spring_phases
from ..runtime import backend
from ..runtime.plan import ITEM, NOW, STATE, Loop, Once, Phase, Repeat
from ..runtime.team import MAX_WORKERS
from ..state import store_particle
from . import fused
from .base import Integrator, add_settings
from .rk4 import ROW, first_stage, next_stage  # the stage counter, per worker

STAGES = 6
POLYNOMIALS = (   # gamma, a3, a4, a5, a6 (tools/stability_polynomials.py)
    (0.4000, 1.529712570e-01, 2.969606946e-02, 3.464954407e-03, 2.495105602e-04),  # h w_max 6.354
    (0.4421, 1.518900000e-01, 2.899382418e-02, 3.306842874e-03, 2.235490420e-04),  # h w_max 6.513
    (0.4887, 1.506140993e-01, 2.818521331e-02, 3.129243816e-03, 1.967510507e-04),  # h w_max 6.693
    (0.5401, 1.493975267e-01, 2.749592568e-02, 2.966542684e-03, 1.737371040e-04),  # h w_max 6.900
    (0.5970, 1.479025857e-01, 2.664919967e-02, 2.781104673e-03, 1.513279031e-04),  # h w_max 7.143
    (0.6599, 1.464437056e-01, 2.582591583e-02, 2.599522361e-03, 1.305578627e-04),  # h w_max 7.425
    (0.7293, 1.449209331e-01, 2.503463169e-02, 2.426564010e-03, 1.123962924e-04),  # h w_max 7.770
    (0.8061, 1.427484904e-01, 2.392451491e-02, 2.208766989e-03, 9.271829749e-05),  # h w_max 8.228
    (0.8910, 1.397297628e-01, 2.254404566e-02, 1.965543428e-03, 7.425291229e-05),  # h w_max 8.895
    (0.9848, 1.342869980e-01, 2.037313531e-02, 1.631058608e-03, 5.436457539e-05),  # h w_max 9.672
    (1.0885, 1.291507619e-01, 1.815813490e-02, 1.272137033e-03, 3.399335910e-05),  # h w_max 9.526
    (1.2032, 1.248001938e-01, 1.595065594e-02, 9.663764296e-04, 2.178819393e-05),  # h w_max 9.017
    (1.3298, 1.196838229e-01, 1.372437091e-02, 7.227986826e-04, 1.403222184e-05),  # h w_max 8.681
    (1.4699, 1.143138579e-01, 1.168555383e-02, 5.323340928e-04, 8.850232741e-06),  # h w_max 8.611
)
MODES = 600                     # modes of a body's spectrum checked, w / w_max in (0, 1]
STEPS_CHECKED = 400             # steps h' <= h at which |R| <= 1 is checked


def coefficients(row) -> np.ndarray:
    """c_1 .. c_6 of R(z) = 1 + sum c_k z^k for a row of POLYNOMIALS."""
    return np.array([1.0, 0.5, *row[1:]])


UNFITTED = coefficients(POLYNOMIALS[len(POLYNOMIALS) // 2])   # before fit(), or nothing sprung


def chain(c) -> tuple[float, ...]:
    """alpha_1 .. alpha_4 of the stages (module doc; alpha_5 = 1/2 and alpha_6 = 1 are fixed)."""
    return tuple(float(c[6 - k] / c[5 - k]) for k in range(1, 5))


def spectrum(w_max: float, beta: float, drag: float) -> np.ndarray:
    """The eigenvalues [1/s] of the modes w in (0, w_max] with damping rate drag + beta w^2,
    and of a rigid motion under drag alone (0 and -drag)."""
    w = w_max * np.concatenate([np.geomspace(1e-4, 0.05, MODES // 4),
                                np.linspace(0.05, 1.0, MODES - MODES // 4)])
    g = drag + beta * w * w
    root = np.sqrt(g * g - 4.0 * w * w + 0j)
    return np.concatenate([(-g + root) / 2, (-g - root) / 2, [0.0, -drag]])


def reach(c, lam: np.ndarray) -> float:
    """The largest step [s] h with |R(h' lambda)| <= 1 for every lambda and every h' <= h
    (checked at STEPS_CHECKED steps, then bisected once more); 0 when none (and for an empty
    spectrum: body_spectrum's undamped body)."""
    if not lam.size:
        return 0.0
    scale = float(np.max(np.abs(lam)))
    if scale == 0:
        return math.inf

    def stable(h):
        z = h * lam
        total = np.zeros_like(z)
        for ck in c[::-1]:                      # Horner: z (c1 + z (c2 + ... z c6))
            total = (total + ck) * z
        return bool(np.all(np.abs(1.0 + total) <= 1.0 + 1e-12))   # rounding of a rest mode

    steps = np.linspace(1.0, 4.0 * STAGES * STAGES, STEPS_CHECKED) / scale
    good = 0.0
    for h in steps:
        if not stable(h):
            break
        good = h
    else:
        return good
    low, high = good, h
    for _ in range(30):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if stable(mid) else (low, mid)
    return low


def body_spectrum(cloth, drag: float, pinned) -> np.ndarray | None:
    """The eigenvalues of `cloth`'s modes as the stability rule sees them (module doc): its
    stiffest mode's w_max (modes.stiffest_mode), every mode damped as the least damped
    particle is relative to its stiffness (modes.row_bounds without drag: beta = min g_i / w_i^2),
    plus drag (drag alone where nothing is sprung). None when nothing is sprung and there is
    no drag (any step is stable); empty when a stiff part is undamped and there is no drag (no
    step is stable)."""
    return _fitted(cloth, drag, pinned)[0]


def best_polynomial(lam: np.ndarray) -> tuple[np.ndarray, float]:
    """The coefficients of the row of POLYNOMIALS that allows the largest step on `lam`, and
    that step [s] (0 when none is stable: an undamped mode)."""
    found = [(reach(coefficients(row), lam), index) for index, row in enumerate(POLYNOMIALS)]
    step, index = max(found)
    return coefficients(POLYNOMIALS[index]), step


# A body's spectrum and best row, kept while the Cloth lives (its arrays are read-only): a
# Simulation with dt="auto" fits, then asks for its stable step, and a study builds one body
# at many steps; each would otherwise run Lanczos and the rows' checks again (0.6 s at 32²).
_FITS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _fitted(cloth, drag: float, pinned):
    """(body_spectrum, best_polynomial of it or None), memoised per cloth, drag and pins."""
    key = (float(drag), np.asarray(pinned, bool).tobytes())
    fits = _FITS.setdefault(cloth, {})
    if key not in fits:
        lam = _spectrum_of(cloth, drag, pinned)
        fits[key] = (lam, None if lam is None else best_polynomial(lam))
    return fits[key]


def _spectrum_of(cloth, drag: float, pinned) -> np.ndarray | None:
    w2, _ = stiffest_mode(cloth, 0.0, pinned)
    if w2 <= 0:
        return None if drag <= 0 else np.array([0.0, -drag], complex)
    omega2, gamma = row_bounds(cloth, 0.0, pinned)
    stiff = omega2 > 0
    beta = float(np.min(gamma[stiff] / omega2[stiff]))
    if beta <= 0 and drag <= 0:
        return np.zeros(0, complex)     # undamped: |R(i y)| > 1 at every step (reach: 0)
    return spectrum(math.sqrt(w2), beta, drag)


@backend.kernel_argument
class _Stages:
    """Start-of-step state, each worker's count of the stages done in this step, and the
    chain's alpha_1 .. alpha_4 (run-time settings)."""

    def __init__(self, particle_count: int):
        real = backend.real()
        fields = backend.FieldGroup()
        self.x0 = fields.vector(3, real, particle_count)
        self.v0 = fields.vector(3, real, particle_count)
        self.stage = fields.scalar(ti.i32, MAX_WORKERS * ROW)     # rk4's counter
        add_settings(self, fields)
        fields.finalize(self)


@ti.func
def chain_stage(model: ti.template(), state: ti.template(), forces: ti.template(),
                work: ti.template(), i, now: ti.template()):
    """Stage k of particle i (module doc): f(Y_{k-1}) at the current state (its total force
    gathered and kept in particle_force), then Y_k = y_n + alpha_k h f(Y_{k-1}), the step's
    result at the last stage. The stage (0 to 5) is the worker's count."""
    stage = work.stage[now.row * ROW]
    state.particle_force[i] = gather_force(model, state, forces, i, True)
    kx = state.particle_velocity[i]
    kv = model.particle_inv_mass[i] * state.particle_force[i]
    if stage == 0:
        work.x0[i] = state.particle_position[i]
        work.v0[i] = kx
    alpha = 1.0
    if stage < 4:
        alpha = ti.cast(work.settings[stage], float)
    elif stage == 4:
        alpha = 0.5
    h = alpha * now.dt
    if stage < STAGES - 1:
        state.particle_position[i] = work.x0[i] + h * kx
        state.particle_velocity[i] = work.v0[i] + h * kv
    else:
        store_particle(state, i, work.x0[i] + h * kx, work.v0[i] + h * kv, now.step)


class StabilizedRK2(Integrator):
    """Six stages of explicit Runge-Kutta, order 2, whose stability polynomial is the one of
    POLYNOMIALS that holds the body's damped spectrum at the largest step (module doc).

    polynomial: the coefficients (c_1 .. c_6) of R(z) = 1 + sum c_k z^k, c_1 = 1 and
        c_2 = 1/2; None (the default) takes the best for the body each time a Simulation is
        built with it (fit). A run-time option: changing it compiles nothing.

    Stability: |R(h lambda)| <= 1 on every mode of the body, the modes damped as its least
    damped particle (stable_step). Needs damping: undamped springs leave no stable step.
    """

    name = "stabilized_rk2"
    order = 2
    runtime_options = ("polynomial",)

    def __init__(self, *, polynomial=None):
        if polynomial is not None:
            c = np.asarray(polynomial, np.float64)
            if c.shape != (STAGES,) or not np.all(np.isfinite(c)) or np.any(c <= 0) \
                    or c[0] != 1.0 or c[1] != 0.5:
                raise ValueError(f"polynomial must be {STAGES} positive coefficients c_1 .. "
                                 f"c_{STAGES} with c_1 = 1 and c_2 = 0.5 (order 2), got "
                                 f"{polynomial!r}")
            polynomial = tuple(float(x) for x in c)
        self.polynomial = polynomial
        self.given = polynomial is not None     # else fit() takes each body's own

    def options(self):
        return {"polynomial": self.polynomial}

    def fit(self, cloth, drag: float, pinned) -> None:
        """Take the polynomial of POLYNOMIALS best for `cloth` (unless one was given: an
        integrator lent to several simulations fits each one's body in turn)."""
        if not self.given:
            best = _fitted(cloth, drag, pinned)[1]
            c = UNFITTED if best is None else best[0]
            self.polynomial = tuple(float(x) for x in c)

    def settings_values(self):
        """alpha_1 .. alpha_4 of the chain (module doc)."""
        c = self.polynomial or UNFITTED
        return chain(np.asarray(c))

    def stable_step(self, cloth, drag: float, pinned) -> float:
        """The largest h with |R(h lambda)| <= 1 on the body's spectrum (body_spectrum), for
        the polynomial given or fitted, else the best of POLYNOMIALS; inf when nothing is
        sprung and there is no drag, 0 when some stiff mode is undamped."""
        lam, best = _fitted(cloth, drag, pinned)
        if lam is None:
            return math.inf
        if self.polynomial is None or np.array_equal(self.polynomial, best[0]):
            return best[1]
        return reach(np.asarray(self.polynomial), lam)

    def workspace(self, model, state):
        return self.buffers(state, lambda: _Stages(model.particle_count))

    def step_work(self, model):
        return STAGES * fused.spring_work(model)

    def phases(self, model, forces, work):
        """Six times: the wind and the springs at the stage's state, then every particle's
        stage, counted per worker (compiled once, as rk4's)."""
        stage = (wind.phases(model, forces) + spring_phases(model, forces)
                 + (Phase(Loop(model.particle_count, chain_stage, model, STATE, forces, work,
                               ITEM, NOW)),
                    Once(next_stage, work, NOW)))
        return (Once(first_stage, work, NOW), Repeat(STAGES, *stage))
