"""A flat Fabric sheet's bending by the isometric model (Bergou, Wardetzky, Harmon, Zorin &
Grinspun, "A quadratic bending model for inextensible surfaces", SGP 2006), generalised to
the mid-edge operator's B (bending.py): on each hinge w = sum_k K_k x_k, K the cotangent
weights of its two rest triangles, so that under any deformation that keeps lengths
|w| = 2 |e| sin(theta / 2); the energy per triangle is 1/2 sum_ij B'_ij w_i . w_j with
B'_ij = s_i s_j B_ij / (4 |e_i| |e_j|): the mid-edge energy with sin(theta / 2) in place of
tan(theta / 2), the same for small angles and in the continuum limit. It is quadratic in the
positions, 1/2 x^T Q x with one constant Q, merged per particle when the Model is built. It
has no rest angle, so it serves a sheet whose rest hinges are all flat (is_flat) and that
cannot tear. Everything each solver needs of it, together:

- rest data: the cotangent weights, the reduced matrices and Q as a CSR per particle
  (cotangent_weights, isometric_parts, isometric_matrix); the energy in
  float64 (isometric_energy);
- force: one particle loop summing its row of Q times its neighbours' position and velocity
  differences, in increasing neighbour order (isometric_forces, isometric_sum);
- Hessian: Q itself, positive semi-definite as it is (isometric_velocity, isometric_product);
- projection: XPBD's share of the step, a Gauss-Seidel step per particle on Q's rows
  (xpbd_particle, below).

XPBD (integrators/xpbd.py) takes this energy as what it is, quadratic with a constant Q, so
its part of the backward Euler step is linear. With x_o the step's origin (x_n; BDF2's x^),
d the displacement the bending has given the particles so far in the step
(work.bend_shift), the step asks M d = -h^2 Q x - h beta Q (x - x_o) at its end. A pass
updates each particle in turn, in colours of particles no two of which Q couples
(Model.element_colourings), on its row of Q in increasing neighbour order:

    delta_i = (w_i r_i - d_i) / (1 + w_i c_i),   x_i += delta_i,   d_i += delta_i,

r_i particle i's row of the right side, w_i its inverse mass (a pin moves not), c_i = h^2
Q_ii + h beta Q_ii its row's diagonal. That is Gauss-Seidel on M + h^2 Q + h beta Q,
symmetric positive definite, so it converges whatever the step and the stiffness. Every
particle is updated in every pass: skipped after the passes its stiffness ratio w_i c_i asked
at XPBD.bending_tolerance (as the mid-edge bending's triangles are), each step left that
part of the bending's load unresolved, and a cantilever rested 1.14e-4 m (0.3 % of its
overhang) lower at 1/480 s and at 1/960 s alike, 10x less at a tolerance of 0.01 (measured).
Converged, it is backward Euler's step of the energy, as the other projections' are (its
gradients, constant, leave nothing out). It replaced a Gauss-Seidel solve per triangle (the
3 x 3 of its hinges on each axis, 21 colours of triangles against 10 of particles on a
grid) that was 64 % of a tethered
step of issue 53's 64² sheet (docs/performance.md, "XPBD's isometric bending particle by
particle"); a cantilever that XPBD settles with it rests 18x nearer implicit Euler's
equilibrium than with the triangles' solve (7.2e-6 against 1.3e-4 m at 1/480 s, both
converged: tests/test_fabric.py).
"""

import numpy as np
import taichi as ti

from ..runtime.plan import DT, ITEM, STATE, Loop, Sweep
from .bending import hinges, intact_hinges, second_edge

# A flat rest sheet's bending needs no angle: the isometric model (module doc). Rest angles
# below this [rad] (a planar mesh's rounding) count as flat.
FLAT_REST_ANGLE = 1e-6


def cotangent_weights(positions: np.ndarray, indices: np.ndarray,
                      second: np.ndarray | None = None) -> np.ndarray:
    """K (H, 4) of hinges [a, b, c, d] at rest (Bergou, Wardetzky, Harmon, Zorin & Grinspun,
    "A quadratic bending model for inextensible surfaces", SGP 2006, sec. 4.1):
    w = sum_k K_k x_k = (cot b1 + cot b2) a + (cot a1 + cot a2) b - (cot a1 + cot b1) c
    - (cot a2 + cot b2) d, with a1, b1 the rest angles at a and b in triangle (a, b, c) and
    a2, b2 in (a, b, d). In each triangle (cot b1 a + cot a1 b) / (cot a1 + cot b1) is the
    foot of c's altitude, so w is |e| (u1 + u2), u the unit vectors from c and d to the edge
    in their triangles: 0 on the flat rest sheet and |w| = 2 |e| sin(theta / 2) in any
    isometric deformation of it. second (H, 2): the second triangle's particles at a and b
    where they are others (across a seam: bending.second_edge), its angles measured there."""
    a, b, c, d = (positions[indices[:, k]] for k in range(4))
    a_2, b_2 = (a, b) if second is None else (positions[second[:, 0]], positions[second[:, 1]])

    def cot(apex, p, q):
        u, v = p - apex, q - apex
        return np.sum(u * v, 1) / np.linalg.norm(np.cross(u, v), axis=1)

    a1, b1 = cot(a, b, c), cot(b, a, c)
    a2, b2 = cot(a_2, b_2, d), cot(b_2, a_2, d)
    return np.stack([b1 + b2, a1 + a2, -(a1 + b1), -(a2 + b2)], 1)


def is_flat(cloth) -> bool:
    """Whether every hinge of `cloth` is flat at rest (FLAT_REST_ANGLE): its bending is then
    the isometric model (isometric_matrix), else the mid-edge tangents."""
    return cloth.hinge_count > 0 and bool(np.all(np.abs(cloth.hinge_rest_angle)
                                                 <= FLAT_REST_ANGLE))


def isometric_parts(cloth) -> tuple:
    """(K (H, 4) the hinges' cotangent weights, B' (F, 3, 3) = s_i s_j B_ij / (4 |e_i| |e_j|),
    0 across a boundary edge): the isometric model's constants (isometric_matrix)."""
    weights = cotangent_weights(cloth.rest_position, cloth.hinge_indices, second_edge(cloth))
    ends = cloth.rest_position[cloth.hinge_indices[:, :2]]
    lengths = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)
    _, _, face_hinge, face_sign = hinges(cloth.face_indices, cloth.particle_weld)
    present = face_hinge >= 0
    scale = np.where(present, face_sign / (2.0 * lengths[np.where(present, face_hinge, 0)]), 0.0)
    return weights, cloth.face_bending * scale[:, :, None] * scale[:, None, :]


def isometric_matrix(cloth) -> tuple:
    """The isometric bending energy of a flat rest sheet, 1/2 sum_kl Q_kl x_k . x_l with a
    constant Q (Bergou et al. 2006, eq. 8-9, generalised from one hinge to the mid-edge
    operator's coupling of a triangle's hinges): with w_i = sum_k K_ik x_k of the hinge across
    edge i (cotangent_weights), a triangle holds

        1/2 sum_ij B'_ij w_i . w_j,   B'_ij = s_i s_j B_ij / (4 |e_i| |e_j|),

    B the mid-edge matrix (bending_matrices) and s its orientation signs. On the flat rest
    sheet w_i = 2 |e_i| sin(theta_i / 2) n (1 + O(theta)) along the normal, with the sign of
    s_i theta_i, so for small angles this is the mid-edge energy 1/2 dt^T B dt (t = tan(theta /
    2) and sin(theta / 2) agree to O(theta^3)); under refinement theta ~ h / R and both converge
    to the same continuum. Q = sum_f K_f^T B'_f K_f is positive semi-definite, the same in x, y
    and z, and its rows sum to 0 (a translation moves nothing); the force is
    -sum_l Q_kl ((x_l - x_k) + beta (v_l - v_k)) with Rayleigh damping beta. Returns (start
    (N + 1,), other, stiffness (-Q_kl), damping (-beta Q_kl)): particle k's neighbours l != k
    in increasing order, as a CSR."""
    n = cloth.particle_count
    weights, reduced = isometric_parts(cloth)
    hinge = np.maximum(cloth.face_hinge, 0)
    corners = cloth.hinge_indices[hinge]                                        # (F, 3, 4)
    k = weights[hinge] * (cloth.face_hinge >= 0)[:, :, None]
    local = np.einsum("fik,fij,fjl->fikjl", k, reduced, k)                      # Q per face
    rows = np.broadcast_to(corners[:, :, :, None, None], local.shape).ravel()
    cols = np.broadcast_to(corners[:, None, None, :, :], local.shape).ravel()
    damped = local * cloth.face_damping[:, None, None, None, None]
    keep = (rows != cols) & (local.ravel() != 0.0)     # absent hinges' slots (k = 0) left out
    unique, inverse = np.unique(rows[keep] * n + cols[keep], return_inverse=True)
    stiffness = -np.bincount(inverse, weights=local.ravel()[keep], minlength=len(unique))
    damping = -np.bincount(inverse, weights=damped.ravel()[keep], minlength=len(unique))
    row, other = np.divmod(unique, n)
    start = np.concatenate([[0], np.cumsum(np.bincount(row, minlength=n))])
    return start, other, stiffness, damping


def isometric_energy(cloth, positions: np.ndarray, alive: np.ndarray | None = None) -> float:
    """The isometric model's 1/2 sum_ij B'_ij w_i . w_j summed over triangles [J]
    (isometric_matrix); with `alive` ((F,) bool: not torn), a torn triangle holds none and a
    hinge beside one is gone."""
    if not cloth.hinge_count:
        return 0.0
    weights, reduced = isometric_parts(cloth)
    w = (np.einsum("hk,hkx->hx", weights, positions[cloth.hinge_indices])
         * intact_hinges(cloth, alive)[:, None])
    w = np.concatenate([w, np.zeros((1, 3))])[cloth.face_hinge]          # (F, 3, 3)
    return float(0.5 * np.einsum("fix,fij,fjx->", w, reduced, w))


@ti.func
def isometric_sum(model: ti.template(), first: ti.template(), second: ti.template(), i,
                  a, b):
    """sum_l (a k_il (first_l - first_i) + b d_il (second_l - second_i)) over particle i's
    neighbours l in increasing order, k = -Q and d = -beta Q the isometric bending's
    stiffness and damping (energies/isometric.isometric_matrix): a = b = 1 on positions and
    velocities is its force, a = h^2, b = h on one direction implicit Euler's product."""
    x = first[i]
    v = second[i]
    total = ti.Vector([0.0, 0.0, 0.0])
    for c in range(model.particle_bend_start[i], model.particle_bend_start[i + 1]):
        other = model.bend_other[c]
        total += (a * model.bend_stiffness[c] * (first[other] - x)
                  + b * model.bend_damping[c] * (second[other] - v))
    return total


@ti.func
def isometric_forces(model: ti.template(), state: ti.template(), i):
    """particle_bend_force[i] = the isometric bending force on particle i (with the membranes,
    before any particle moves: it reads its neighbours' positions and velocities)."""
    state.particle_bend_force[i] = isometric_sum(model, state.particle_position,
                                                 state.particle_velocity, i, 1.0, 1.0)


def force_loops(model, forces) -> tuple:
    """The loop of the first force phase that sums every particle's bending force
    (isometric_forces), for a model bent by this model (Model.isometric)."""
    if not model.isometric:
        return ()
    return (Loop(model.particle_count, isometric_forces, model, STATE, ITEM),)


@ti.func
def isometric_velocity(model: ti.template(), state: ti.template(), i):
    """Particle i's row of Q v_n, the isometric bending's stiffness times v_n (its Hessian is
    the constant Q of energies/isometric.isometric_matrix, positive semi-definite as it is)."""
    return -isometric_sum(model, state.particle_velocity, state.particle_velocity, i, 1.0, 0.0)


@ti.func
def isometric_product(model: ti.template(), ws: ti.template(), i, dt):
    """Particle i's row of (h^2 + h beta) Q p, the isometric bending's block of A times p."""
    return -isometric_sum(model, ws.p, ws.p, i, dt * dt, dt)


@ti.func
def implicit_start(model: ti.template(), state: ti.template(), forces: ti.template(),
                   ws: ti.template(), i, dt, kv, diagonal):
    """(kv, diagonal) with particle i's row of Q v_n (its diagonal is faces.implicit_start's,
    with the triangles')."""
    if ti.static(model.isometric):
        kv += isometric_velocity(model, state, i)
    return kv, diagonal


@ti.func
def implicit_product(model: ti.template(), ws: ti.template(), i, dt, ap):
    """ap with particle i's row of (h^2 + h beta) Q p."""
    if ti.static(model.isometric):
        ap += isometric_product(model, ws, i, dt)
    return ap


@ti.func
def clear_shift(work: ti.template(), i):
    """No bending displacement of particle i yet in the step (module doc: d)."""
    work.bend_shift[i] = ti.Vector([0.0, 0.0, 0.0])


@ti.func
def xpbd_particle(model: ti.template(), state: ti.template(), work: ti.template(), i, dt):
    """Particle i's Gauss-Seidel step of the bending's share of the step (module doc), its
    displacement kept in work.bend_shift[i]."""
    x = state.particle_position[i]
    origin = state.particle_prev_position[i]
    right = ti.Vector([0.0, 0.0, 0.0])
    diagonal = 0.0
    for c in range(model.particle_bend_start[i], model.particle_bend_start[i + 1]):
        other = model.bend_other[c]
        k, d = model.bend_stiffness[c], model.bend_damping[c]
        apart = state.particle_position[other] - x
        right += dt * dt * k * apart + dt * d * (apart - (state.particle_prev_position[other]
                                                          - origin))
        diagonal += dt * dt * k + dt * d           # Q_ii = -sum_l Q_il: its rows sum to 0
    w = model.particle_inv_mass[i]
    step = (w * right - work.bend_shift[i]) / (1.0 + w * diagonal)
    state.particle_position[i] = x + step
    work.bend_shift[i] = work.bend_shift[i] + step


@ti.func
def xpbd_at(model: ti.template(), state: ti.template(), work: ti.template(), t, dt):
    """XPBD for the particle at position t of the bending's colouring."""
    xpbd_particle(model, state, work, work.bending_colours.order[t], dt)


def xpbd_nodes(model, forces, work) -> tuple:
    """(loops clearing the bending's displacement, sweeps: its particles colour by colour)
    of XPBD's isometric bending (xpbd.py's workspace `work`), none for a model without it."""
    if not model.hinge_count or not model.isometric:
        return (), ()
    return ((Loop(model.particle_count, clear_shift, work, ITEM),),
            (Sweep(work.bending_colours, xpbd_at, model, STATE, work, ITEM, DT),))
