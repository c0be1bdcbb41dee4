"""Position-level projection: the lecture's mass-weighted spring relaxation and XPBD.

Springs are visited colour by colour (Model.spring_colouring: no two springs of a colour share
a particle), so a pass equals a sequential Gauss-Seidel sweep in colour order and is
deterministic. The updates are per spring: pbd's and xpbd's phases and strain limiting's
sweep them (runtime/plan.py's Sweep).
"""


import taichi as ti

from ..runtime import backend
from .forces import altitude_gradient


@backend.kernel_argument
class SweepOrder:
    """A model's spring and altitude-spring colourings, as one kernel argument (pbd's
    phases sweep them)."""

    def __init__(self, model):
        self.colours = model.spring_colouring()
        self.altitude_colours = model.altitude_colouring()


@ti.func
def relax(model: ti.template(), state: ti.template(), colours: ti.template(), t, stiffness,
          tearable: ti.template(), max_strain, stretched_only: ti.template()):
    """Project the spring at position t of the colour order (SpringColouring's packed
    values): the lecture's relaxation.

    For a spring (p, q) with target length L = (1 + max_strain) L0:
    delta = (|q - p| - L) / |q - p|, dx = delta (q - p),
    p += w_p / (w_p + w_q) dx, q -= w_q / (w_p + w_q) dx, where w = 1/m and the lecture's
    m_q / (m_p + m_q) = w_p / (w_p + w_q); pins (w = 0) do not move. stiffness[kind] scales the
    correction (1 = the lecture's full projection; 0 leaves that kind alone). PBD uses
    max_strain = 0; strain limiting (Provot 1995) uses stretched_only, which leaves springs no
    longer than L."""
    alive = True
    if ti.static(tearable):
        alive = state.spring_alive[colours.order[t]] != 0
    p, q = colours.ends[t][0], colours.ends[t][1]
    wp, wq = model.particle_inv_mass[p], model.particle_inv_mass[q]
    d = state.particle_position[q] - state.particle_position[p]
    length = d.norm()
    target = (1.0 + max_strain) * colours.rest[t]
    if ti.static(stretched_only):
        alive = alive and length > target
    if alive and wp + wq > 0 and length > 0:
        delta = (length - target) / length
        dx = stiffness[colours.kind[t]] * delta * d
        state.particle_position[p] = state.particle_position[p] + wp / (wp + wq) * dx
        state.particle_position[q] = state.particle_position[q] - wq / (wp + wq) * dx


@ti.func
def _altitude_constraint(model: ti.template(), state: ti.template(), a):
    """(corners, n, h, g, w, sum_c w_c g_c^2) of altitude spring a now: the constraint
    C = h - h0 has gradient g_c n on corner c (forces.altitude_gradient); w = 1/m per corner."""
    corner = model.altitude_indices[a]
    n, h, g = altitude_gradient(state.particle_position, corner)
    weight = ti.Vector([model.particle_inv_mass[corner[c]] for c in ti.static(range(4))])
    return corner, n, h, g, weight, (weight * g * g).sum()


@ti.func
def relax_altitude(model: ti.template(), state: ti.template(), a, stiffness):
    """Project altitude spring a (Selle et al. 2008; forces.altitude_gradient) to its rest
    altitude: C = h - h0 with gradient g_c n on corner c, so corner c moves by
    -stiffness C w_c g_c n / sum_l w_l g_l^2 (the lecture's mass-weighted projection of one
    constraint, w = 1/m)."""
    corner, n, h, g, weight, norm = _altitude_constraint(model, state, a)
    if norm > 0 and n.norm() > 0:
        scale = -stiffness * (h - model.altitude_rest_length[a]) / norm
        for c in ti.static(range(4)):
            x = state.particle_position[corner[c]]
            state.particle_position[corner[c]] = x + scale * weight[c] * g[c] * n


@ti.func
def xpbd_update(model: ti.template(), state: ti.template(), colours: ti.template(), t,
                multiplier: ti.template(), dt, tearable: ti.template()):
    """The XPBD update of the spring at position t of the colour order, whose multiplier is
    multiplier[t] (Macklin et al. 2016, eq. 18; damping as Macklin et al. 2019, "Small
    steps", with beta = kd).

    Spring (p, q), C = |x_p - x_q| - L, n = (x_p - x_q) / |x_p - x_q|, compliance
    alpha~ = 1 / (k h^2), gamma = alpha~ (h^2 kd) / h = kd / (k h):
    dlambda = (-C - alpha~ lambda - gamma n . ((x_p - x_p^n) - (x_q - x_q^n)))
              / ((1 + gamma)(w_p + w_q) + alpha~),
    x_p += w_p dlambda n, x_q -= w_q dlambda n, lambda += dlambda. At convergence this is the
    implicit step of the Hookean energy 1/2 k C^2 (Stuyck eq. 4.4) with axial damping kd.
    Springs with k = 0 are not constraints."""
    alive = colours.stiffness[t] > 0
    if ti.static(tearable):
        alive = alive and state.spring_alive[colours.order[t]] != 0
    p, q = colours.ends[t][0], colours.ends[t][1]
    wp, wq = model.particle_inv_mass[p], model.particle_inv_mass[q]
    d = state.particle_position[p] - state.particle_position[q]
    length = d.norm()
    if alive and wp + wq > 0 and length > 0:
        n = d / length
        k = colours.stiffness[t]
        compliance = 1.0 / (k * dt * dt)
        gamma = 0.0 if ti.static(model.relative_damping) else colours.damping[t] / (k * dt)
        motion = (state.particle_position[p] - state.particle_prev_position[p]
                  - state.particle_position[q] + state.particle_prev_position[q])
        dlambda = ((-(length - colours.rest[t]) - compliance * multiplier[t]
                    - gamma * n.dot(motion))
                   / ((1.0 + gamma) * (wp + wq) + compliance))
        multiplier[t] = multiplier[t] + dlambda
        state.particle_position[p] = state.particle_position[p] + wp * dlambda * n
        state.particle_position[q] = state.particle_position[q] - wq * dlambda * n


@ti.func
def xpbd_altitude(model: ti.template(), state: ti.template(), a, multiplier: ti.template(), dt):
    """XPBD for altitude spring a: C = h - h0, gradient g_c n on corner c, compliance
    1 / (k h^2) and damping kd on the altitude's rate, as xpbd_update with sum_c w_c g_c^2 for
    w_p + w_q."""
    k = model.altitude_stiffness[a]
    corner, n, h, g, weight, norm = _altitude_constraint(model, state, a)
    if k > 0 and norm > 0 and n.norm() > 0:
        compliance = 1.0 / (k * dt * dt)
        gamma = model.altitude_damping[a] / (k * dt)
        motion = 0.0
        for c in ti.static(range(4)):
            motion += g[c] * n.dot(state.particle_position[corner[c]]
                                   - state.particle_prev_position[corner[c]])
        dlambda = ((-(h - model.altitude_rest_length[a]) - compliance * multiplier[a]
                    - gamma * motion) / ((1.0 + gamma) * norm + compliance))
        multiplier[a] = multiplier[a] + dlambda
        for c in ti.static(range(4)):
            x = state.particle_position[corner[c]]
            state.particle_position[corner[c]] = x + weight[c] * dlambda * g[c] * n


@ti.func
def damp(model: ti.template(), state: ti.template(), colours: ti.template(), t, dt,
         tearable: ti.template()):
    """Relative damping (Stuyck eq. 4.7, f_p = -kd (v_p - v_q)) of the spring at position t of
    the colour order, solved implicitly on velocities: for one spring the backward Euler step
    is exact, v_p - v_q shrinking by 1 / (1 + h kd (w_p + w_q)), split by inverse mass so
    momentum is kept. A pass of it over every spring in colour order is the product of these
    exact steps (a further pass would damp again, not converge)."""
    alive = colours.damping[t] > 0
    if ti.static(tearable):
        alive = alive and state.spring_alive[colours.order[t]] != 0
    p, q = colours.ends[t][0], colours.ends[t][1]
    wp, wq = model.particle_inv_mass[p], model.particle_inv_mass[q]
    if alive and wp + wq > 0:
        rate = dt * colours.damping[t] * (wp + wq)
        dv = (state.particle_velocity[p] - state.particle_velocity[q]) * (rate / (1.0 + rate))
        state.particle_velocity[p] = state.particle_velocity[p] - wp / (wp + wq) * dv
        state.particle_velocity[q] = state.particle_velocity[q] + wq / (wp + wq) * dv
