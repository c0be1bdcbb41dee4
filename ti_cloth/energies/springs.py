"""Stuyck's springs (chapter 4): a spring between particles i and j with rest length L,
stiffness k and damping kd stores E = 1/2 k (|x_i - x_j| - L)^2 (eq. 4.4); everything each
solver needs of it, together:

- force: Hookean, eq. 4.5, with relative (eq. 4.7) or axial damping (spring_force), each
  spring evaluated once per step into State.spring_force (spring_forces), which every particle
  gathers in a fixed order (physics/forces.py);
- Hessian: -df_i/dx_i = k (n n^T + c (I - n n^T)), c = max(1 - L / l, 0) (its projection onto
  positive semi-definite: a compressed spring's negative lateral term dropped), applied to a
  vector (stiffness_times) or as implicit Euler's 3 x 3 block of h^2 K + h D
  (spring_block, block_times, linearise_spring);
- projections: the lecture's mass-weighted relaxation (relax), XPBD (Macklin et al. 2016,
  xpbd_update) and the exact implicit relative damping of one spring (damp), visited colour by
  colour (Model.spring_colouring), so a pass is a Gauss-Seidel sweep with fixed bits;
- energy on the host, float64 (spring_energies).

Which pairs are springs, their kinds and rest lengths come from the mesh (body/topology.py).
"""

import numpy as np
import taichi as ti

from ..runtime.plan import DT, ITEM, STATE, Loop, Sweep


@ti.func
def spring_force(xi, xj, vi, vj, rest, k, kd, relative: ti.template()):
    """Force of one spring on particle i (the force on j is its negation).

    Elastic part: Stuyck eq. 4.5, f_i = -k (|x_ij| - L) x_ij / |x_ij|.
    Damping: relative = Stuyck eq. 4.7, -kd (v_i - v_j); axial = -kd ((v_i - v_j) . n) n.
    A spring of zero current length has no direction: its elastic and axial parts are zero.
    """
    xij = xi - xj
    vij = vi - vj
    length = xij.norm()
    f = ti.Vector([0.0, 0.0, 0.0])
    if length > 0:
        # -k (l - L) n - kd (vij . n) n = s x_ij, n = x_ij / l: one division and one scaling
        # of x_ij (kernels compute in IEEE arithmetic, unfused: runtime/backend.py)
        s = -k * (length - rest)
        if ti.static(not relative):
            s -= kd * vij.dot(xij) / length
        f = (s / length) * xij
    if ti.static(relative):
        f -= kd * vij
    return f


@ti.func
def spring_forces(model: ti.template(), state: ti.template(), forces: ti.template(), s):
    """spring_force[s] = force of spring s on its first end (eq. 4.5, 4.7), 0 once torn.
    (Altitude springs: altitude_forces; they do not tear.)"""
    i, j = model.spring_indices[s][0], model.spring_indices[s][1]
    f = ti.Vector([0.0, 0.0, 0.0])
    alive = True
    if ti.static(forces.tearable):
        alive = state.spring_alive[s] != 0
    if alive:
        f = spring_force(state.particle_position[i], state.particle_position[j],
                         state.particle_velocity[i], state.particle_velocity[j],
                         model.spring_rest_length[s], model.spring_stiffness[s],
                         model.spring_damping[s], model.relative_damping)
    state.spring_force[s] = f


def force_loops(model, forces) -> tuple:
    """The loop of the first force phase that evaluates every spring (spring_forces)."""
    if not model.spring_count:
        return ()
    return (Loop(model.spring_count, spring_forces, model, STATE, forces, ITEM),)


@ti.func
def gather(model: ti.template(), state: ti.template(), i, f):
    """f with the forces of particle i's springs: - those of which it is the second end, +
    those of which it is the first (Model adjacency, a fixed order)."""
    split = model.particle_spring_split[i]
    for a in range(model.particle_spring_start[i], split):
        f -= state.spring_force[model.adjacency_spring[a]]
    for a in range(split, model.particle_spring_start[i + 1]):
        f += state.spring_force[model.adjacency_spring[a]]
    return f


@ti.func
def stiffness_times(k, n, c, d):
    """k (n n^T + c (I - n n^T)) d: the spring's -df_i/dx_i applied to d."""
    along = n.dot(d) * n
    return k * (along + c * (d - along))


@ti.func
def spring_block(k, kd, n, c, dt, relative: ti.template()):
    """h^2 k (n n^T + c (I - n n^T)) + h D, D = kd n n^T (axial) or kd I (relative): the
    spring's block of A, symmetric, as (xx, yy, zz, xy, xz, yz)."""
    stiff = dt * dt * k
    damp = dt * kd
    lateral = stiff * c
    along = stiff - lateral
    if ti.static(not relative):
        along += damp
    diagonal = lateral + along * n * n
    if ti.static(relative):
        diagonal += damp
    return ti.Vector([diagonal[0], diagonal[1], diagonal[2], along * n[0] * n[1],
                      along * n[0] * n[2], along * n[1] * n[2]])


@ti.func
def block_times(m, d):
    """The symmetric 3x3 block m (xx, yy, zz, xy, xz, yz) times d."""
    return ti.Vector([m[0] * d[0] + m[3] * d[1] + m[4] * d[2],
                      m[3] * d[0] + m[1] * d[1] + m[5] * d[2],
                      m[4] * d[0] + m[5] * d[1] + m[2] * d[2]])


@ti.func
def linearise_spring(model: ti.template(), state: ti.template(), forces: ti.template(),
                     ws: ti.template(), s):
    """Spring s: direction and clamped lateral factor at x_n."""
    i, j = model.spring_indices[s][0], model.spring_indices[s][1]
    d = state.particle_position[i] - state.particle_position[j]
    length = d.norm()
    n = ti.Vector([0.0, 0.0, 0.0])
    c = 0.0
    if length > 0:
        n = d / length
        c = ti.max(1.0 - model.spring_rest_length[s] / length, 0.0)
    elif model.spring_rest_length[s] == 0:
        c = 1.0    # a zero-length spring is linear: -df/dx = k I
    if ti.static(forces.tearable):
        if state.spring_alive[s] == 0:
            c, n = 0.0, ti.Vector([0.0, 0.0, 0.0])
    ws.spring_normal[s] = n
    ws.spring_lateral[s] = c


@ti.func
def implicit_start(model: ti.template(), state: ti.template(), forces: ti.template(),
                   ws: ti.template(), i, dt, kv, diagonal):
    """(kv, diagonal) with particle i's springs: their stiffness times v_n (K v_n's row, the
    linearisation's normal and lateral factor) and their blocks of h^2 K + h D, each kept per
    adjacency slot for the products (ws.adjacency_block; a torn spring damps no more) and
    added to the 3x3 diagonal (implicit Euler)."""
    vi = state.particle_velocity[i]
    for a in range(model.particle_spring_start[i], model.particle_spring_start[i + 1]):
        s = model.adjacency_spring[a]
        j = model.adjacency_other[a]
        n, c = ws.spring_normal[s], ws.spring_lateral[s]
        k, kd = model.spring_stiffness[s], model.spring_damping[s]
        kv += stiffness_times(k, n, c, vi - state.particle_velocity[j])
        if ti.static(forces.tearable):
            if state.spring_alive[s] == 0:
                kd = 0.0
        m = spring_block(k, kd, n, c, dt, model.relative_damping)
        ws.adjacency_block[a] = m
        diagonal += ti.Vector([m[0], m[1], m[2]])
    return kv, diagonal


@ti.func
def implicit_product(model: ti.template(), ws: ti.template(), i, dt, ap):
    """ap with particle i's rows of the springs' blocks times the direction ws.p."""
    pi = ws.p[i]
    for a in range(model.particle_spring_start[i], model.particle_spring_start[i + 1]):
        ap += block_times(ws.adjacency_block[a], pi - ws.p[model.adjacency_other[a]])
    return ap


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
def clear_multiplier(work: ti.template(), s):
    work.value[s] = 0.0


def xpbd_nodes(model, forces, work) -> tuple:
    """(loops clearing the multipliers, sweeps) of XPBD over the springs (xpbd.py's workspace
    `work`: the spring colouring and one multiplier per spring in its order), none without
    springs."""
    if not model.spring_count:
        return (), ()
    return ((Loop(model.spring_count, clear_multiplier, work, ITEM),),
            (Sweep(work.colours, xpbd_update, model, STATE, work.colours, ITEM, work.value, DT,
                   forces.tearable),))


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


def spring_energies(cloth, positions: np.ndarray, alive: np.ndarray | None = None) -> np.ndarray:
    """1/2 k (|x_i - x_j| - L)^2 of each spring [J] (Stuyck eq. 4.4) at `positions` (N, 3),
    0 for a torn one (alive False), float64 on the host; shape (spring_count,)."""
    i, j = cloth.spring_indices.T
    stretch = np.linalg.norm(positions[i] - positions[j], axis=1) - cloth.spring_rest_length
    per_spring = 0.5 * cloth.spring_stiffness * stretch ** 2
    if alive is not None:
        per_spring = per_spring * alive
    return per_spring
