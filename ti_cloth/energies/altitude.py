"""Selle et al. 2008's altitude springs: a corner p of a tetrahedron over the face (a, b, c)
opposite it keeps its rest altitude h0, E = 1/2 k (h - h0)^2, h = (x_p - x_a) . n the signed
height of p over the face (geometry.point_over_triangle). The gradient of h is g_c n over the
corners, g = (1, -w_a, -w_b, -w_c) with w the barycentric coordinates of p's foot (the foot's
tangential terms cancel), so the force -k (h - h0) g_c n has no net force or torque.
Everything each solver needs of it, together:

- rest data from the host mesh: four springs per tetrahedron (altitude_springs) and the host
  twin of the gradient (altitude_frames);
- force with damping on the altitude's rate (altitude_forces), once per spring into a force
  per corner that each corner gathers in a fixed order;
- Hessian (Gauss-Newton, k G G^T with G = g (x) n; its curvature term dropped): implicit
  Euler's linearisation, projection and product (linearise_altitude, project_altitude,
  altitudes_times);
- projections: pbd's (relax_altitude) and XPBD's (xpbd_altitude);
- energy on the host, float64 (altitude_energy).
"""

import numpy as np
import taichi as ti

from ..geometry import point_over_triangle, points_over_triangles
from ..inputs.validation import as_array, require
from ..runtime.plan import DT, ITEM, STATE, Loop, Sweep


def altitude_springs(positions: np.ndarray, tetrahedra) -> tuple[np.ndarray, np.ndarray]:
    """Selle et al. 2008's point-face altitude springs of tetrahedra: four per tetrahedron,
    each a corner p and the face (a, b, c) opposite it, ordered so that the rest altitude
    h0 = (x_p - x_a) . n, n = (x_b - x_a) x (x_c - x_a) / |...|, is positive.

    Returns (indices (4T, 4) [p, a, b, c], rest altitudes (4T,) [m]). Raises ValueError
    naming the tetrahedron for one of zero volume (no altitude to keep).
    """
    tets = as_array("altitude_tetrahedra", tetrahedra, np.int64, (None, 4))
    bad = np.flatnonzero((tets < 0).any(axis=1) | (tets >= len(positions)).any(axis=1))
    require(len(bad) == 0, f"altitude_tetrahedra[{bad[:1].tolist()}]", tets[bad[:1]].tolist(),
            f"four particle indices in [0, {len(positions) - 1}]")
    corners = positions[tets]
    volume = np.linalg.det(corners[:, 1:] - corners[:, :1]) / 6.0
    longest = np.max(np.linalg.norm(corners[:, :, None] - corners[:, None], axis=3), axis=(1, 2))
    flat = np.flatnonzero(np.abs(volume) <= 1e-9 * longest ** 3)
    if len(flat):
        t = int(flat[0])
        raise ValueError(f"altitude_tetrahedra[{t}] (particles {tets[t].tolist()}) must have a "
                         f"volume > 0 m^3, got {volume[t]:.3g} m^3 ({len(flat)} flat tetrahedra)")
    faces = np.array([[0, 1, 2, 3], [1, 0, 2, 3], [2, 0, 1, 3], [3, 0, 1, 2]])
    indices = tets[:, faces].reshape(-1, 4)
    _, rest, _ = altitude_frames(positions, indices)
    indices[rest < 0] = indices[rest < 0][:, [0, 1, 3, 2]]
    return indices, np.abs(rest)


def altitude_frames(positions: np.ndarray, indices: np.ndarray):
    """(n (A, 3), h (A,), g (A, 4)) of altitude springs [p, a, b, c] at `positions`, in numpy:
    the face normal, the signed altitude of p and the weights of the altitude's gradient
    (1, -w_a, -w_b, -w_c), w the barycentric coordinates of p's foot on the face's plane (the
    host twin of altitude_gradient; zero for a face of zero area)."""
    n, h, wb, wc, has_area = points_over_triangles(*(positions[indices[:, corner]]
                                                     for corner in range(4)))
    g = np.stack([np.where(has_area, 1.0, 0.0), wb + wc - 1.0, -wb, -wc], axis=1)
    return n, h, g


@ti.func
def altitude_gradient(positions: ti.template(), corner):
    """(n, h, g) of the altitude spring (Selle et al. 2008) with corners `corner` (p, a, b, c)
    at `positions`: the face's unit normal, p's signed altitude over it
    (geometry.point_over_triangle) and g = (1, -w_a, -w_b, -w_c), w the barycentric
    coordinates of p's foot, so grad h = g_c n and -k (h - h0) g_c n is the exact force of
    the energy 1/2 k (h - h0)^2, along n, with zero net force and torque (zero for a face of
    zero area)."""
    n, h, w = point_over_triangle(positions[corner[0]], positions[corner[1]], positions[corner[2]],
                             positions[corner[3]])
    return n, h, ti.Vector([1.0, -w[0], -w[1], -w[2]])


@ti.func
def altitude_forces(model: ti.template(), state: ti.template(), a):
    """altitude_force[4 a + c] = force of altitude spring a on its corner c (p, a, b, c): with
    g = (1, -w_a, -w_b, -w_c) and the rate dh/dt = n . sum_c g_c v_c,
    f_c = -(k (h - h0) + kd dh/dt) g_c n (Stuyck eq. 4.5 and 4.7 with the altitude for the
    spring's length: damping acts on the altitude's rate)."""
    corner = model.altitude_indices[a]
    n, h, g = altitude_gradient(state.particle_position, corner)
    rate = 0.0
    for c in ti.static(range(4)):
        rate += g[c] * n.dot(state.particle_velocity[corner[c]])
    magnitude = -(model.altitude_stiffness[a] * (h - model.altitude_rest_length[a])
                  + model.altitude_damping[a] * rate)
    for c in ti.static(range(4)):
        state.altitude_force[4 * a + c] = magnitude * g[c] * n


def force_loops(model, forces) -> tuple:
    """The loop of the first force phase that evaluates every altitude spring
    (altitude_forces)."""
    if not model.altitude_count:
        return ()
    return (Loop(model.altitude_count, altitude_forces, model, STATE, ITEM),)


@ti.func
def gather(model: ti.template(), state: ti.template(), i, f):
    """f with the forces of particle i's altitude springs on it, in the Model's fixed order
    (compiled only for a body with altitude springs)."""
    if ti.static(model.altitude_count > 0):
        for a in range(model.particle_altitude_start[i], model.particle_altitude_start[i + 1]):
            f += state.altitude_force[model.adjacency_altitude[a]]
    return f


@ti.func
def linearise_altitude(model: ti.template(), state: ti.template(), ws: ti.template(), a):
    """Altitude spring a: normal and corner weights at x_n."""
    corner = model.altitude_indices[a]
    n, _, g = altitude_gradient(state.particle_position, corner)
    ws.altitude_normal[a] = n
    for c in ti.static(range(4)):
        ws.altitude_weight[4 * a + c] = g[c]


@ti.func
def project_altitude(model: ti.template(), ws: ti.template(), vectors: ti.template(), a):
    """altitude_projection[a] = G_a . vectors = n . sum_c g_c vectors[corner c]."""
    corner = model.altitude_indices[a]
    total = 0.0
    for c in ti.static(range(4)):
        total += ws.altitude_weight[4 * a + c] * ws.altitude_normal[a].dot(vectors[corner[c]])
    ws.altitude_projection[a] = total


@ti.func
def altitudes_times(model: ti.template(), ws: ti.template(), i, dt):
    """Particle i's rows of (h^2 K + h D) times the vector altitude_projection was taken of,
    over its altitude springs: (h^2 k + h kd) g_i n (G . vector)."""
    result = ti.Vector([0.0, 0.0, 0.0])
    if ti.static(model.altitude_count > 0):
        for a in range(model.particle_altitude_start[i], model.particle_altitude_start[i + 1]):
            code = model.adjacency_altitude[a]
            e = code // 4
            result += ((dt * dt * model.altitude_stiffness[e] + dt * model.altitude_damping[e])
                       * ws.altitude_weight[code] * ws.altitude_projection[e]
                       * ws.altitude_normal[e])
    return result


@ti.func
def altitude_block(model: ti.template(), ws: ti.template(), e, dt, weight_i, weight_j):
    """The 3x3 block (h^2 k + h kd) g_i g_j n n^T of altitude spring e (its linearisation)
    coupling two sets of its corners that each move as one (a coarse level's aggregates:
    integrators/coarse.py), each set given by the sum of its corners' weights g."""
    n = ws.altitude_normal[e]
    return ((dt * dt * model.altitude_stiffness[e] + dt * model.altitude_damping[e])
            * weight_i * weight_j * n.outer_product(n))


@ti.func
def implicit_start(model: ti.template(), state: ti.template(), forces: ti.template(),
                   ws: ti.template(), i, dt, kv, diagonal):
    """(kv, diagonal) with particle i's altitude springs: k g_i n (G . v_n) and
    (h^2 k + h kd) g_i^2 n n on the diagonal (implicit Euler)."""
    if ti.static(model.altitude_count > 0):
        for a in range(model.particle_altitude_start[i], model.particle_altitude_start[i + 1]):
            code = model.adjacency_altitude[a]
            e = code // 4
            n = ws.altitude_normal[e]
            g = ws.altitude_weight[code]
            kv += model.altitude_stiffness[e] * g * ws.altitude_projection[e] * n
            diagonal += ((dt * dt * model.altitude_stiffness[e]
                          + dt * model.altitude_damping[e]) * g * g * n * n)
    return kv, diagonal


@ti.func
def implicit_product(model: ti.template(), ws: ti.template(), i, dt, ap):
    """ap with particle i's rows of the altitude springs' block times the direction."""
    return ap + altitudes_times(model, ws, i, dt)


@ti.func
def altitude_constraint(model: ti.template(), state: ti.template(), a):
    """(corners, n, h, g, w, sum_c w_c g_c^2) of altitude spring a now: the constraint
    C = h - h0 has gradient g_c n on corner c (altitude_gradient); w = 1/m per corner."""
    corner = model.altitude_indices[a]
    n, h, g = altitude_gradient(state.particle_position, corner)
    weight = ti.Vector([model.particle_inv_mass[corner[c]] for c in ti.static(range(4))])
    return corner, n, h, g, weight, (weight * g * g).sum()


@ti.func
def relax_altitude(model: ti.template(), state: ti.template(), a, stiffness):
    """Project altitude spring a (Selle et al. 2008; altitude_gradient) to its rest
    altitude: C = h - h0 with gradient g_c n on corner c, so corner c moves by
    -stiffness C w_c g_c n / sum_l w_l g_l^2 (the lecture's mass-weighted projection of one
    constraint, w = 1/m)."""
    corner, n, h, g, weight, norm = altitude_constraint(model, state, a)
    if norm > 0 and n.norm() > 0:
        scale = -stiffness * (h - model.altitude_rest_length[a]) / norm
        for c in ti.static(range(4)):
            x = state.particle_position[corner[c]]
            state.particle_position[corner[c]] = x + scale * weight[c] * g[c] * n


@ti.func
def xpbd_altitude(model: ti.template(), state: ti.template(), a, multiplier: ti.template(), dt):
    """XPBD for altitude spring a: C = h - h0, gradient g_c n on corner c, compliance
    1 / (k h^2) and damping kd on the altitude's rate, as xpbd_update with sum_c w_c g_c^2 for
    w_p + w_q."""
    k = model.altitude_stiffness[a]
    corner, n, h, g, weight, norm = altitude_constraint(model, state, a)
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
def clear_multiplier(work: ti.template(), a):
    work.altitude[a] = 0.0


@ti.func
def xpbd_at(model: ti.template(), state: ti.template(), work: ti.template(), t, dt):
    """XPBD for the altitude spring at position t of the altitude colouring."""
    xpbd_altitude(model, state, work.altitude_colours.order[t], work.altitude, dt)


def xpbd_nodes(model, forces, work) -> tuple:
    """(loops clearing the multipliers, sweeps) of XPBD over the altitude springs (xpbd.py's
    workspace `work`), none without them."""
    if not model.altitude_count:
        return (), ()
    return ((Loop(model.altitude_count, clear_multiplier, work, ITEM),),
            (Sweep(work.altitude_colours, xpbd_at, model, STATE, work, ITEM, DT),))


def altitude_energy(cloth, positions: np.ndarray) -> float:
    """sum 1/2 k (h - h0)^2 over the altitude springs [J], h the signed altitude of p over the
    face (a, b, c) (altitude_gradient)."""
    _, h, _ = altitude_frames(positions, cloth.altitude_indices)
    return float(np.sum(0.5 * cloth.altitude_stiffness * (h - cloth.altitude_rest_length) ** 2))
