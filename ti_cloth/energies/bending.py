"""A Fabric's bending by the mid-edge shape operator of Grinspun, Gingold, Reisman & Zorin,
"Computing discrete shape operators on general meshes", Eurographics 2006 (eq. 4), in the
tangent form of Weischedel, "A discrete geometric view on shear-deformable shell models"
(2012) and Chen, Sastry, van Rees & Vouga, "Physical simulation of environmentally induced
thin shell deformation", ACM TOG 37(4), 2018 (eq. 5, "MidedgeTan"). Across each interior
edge e (a hinge: the edge a-b and the vertices c, d opposite it) the dihedral angle theta_e is
measured between the two face normals; a triangle's curvature in its rest frame is

    k = sum_i t_i K_i,   t_i = tan(theta_i / 2),   K_i = -2 |grad lambda_i| u_i u_i^T,

over its three edges i (edge i is opposite corner i; u_i = grad(lambda_i) / |grad lambda_i|,
the inward normal of edge i; a boundary edge has t_i = 0). The energy is
A/2 (k - k_rest) : D : (k - k_rest) with D = Fabric.flexural, i.e. 1/2 dt^T B dt with
dt_i = t_i - t_rest_i and B_ij = A <K_i, K_j>_D, a 3 x 3 positive semi-definite matrix per
triangle. The rest angles come from the rest mesh, so a curved rest shape is kept (a flat
rest sheet bends by isometric.py instead). Unlike a bending spring, or an energy on each
hinge alone (Bridson, Marino & Fedkiw 2003; Grinspun et al. 2003, "Discrete shells"), which on
a regular grid is three times stiffer across the diagonals than along the axes, this operator
bends a grid the same way in every direction (tests/test_fabric.py measures both).

The dihedral angle: with (a, b) the edge as the first face winds it and c, d the opposite
vertices, n1 = (b - a) x (c - a) / |.|, n2 = (d - a) x (b - a) / |.|, e = (b - a) / |b - a|:
theta = atan2((n1 x n2) . e, n1 . n2). Its gradient (Bridson et al. 2003; Tamstorf &
Grinspun, "Discrete bending forces and their Jacobians", Graphical Models 75, 2013, eq. 8):
grad_c = -n1 / h1, grad_d = -n2 / h2 (h the heights of c and d over the edge's line),
grad_a = -(1 - s1) grad_c - (1 - s2) grad_d, grad_b = -s1 grad_c - s2 grad_d, with s the
parameter of c's (d's) foot along a -> b. A face whose winding runs against the first face's
across the edge gets the hinge's t with the opposite sign (face_sign).

Everything each solver needs of it, together:

- rest data from the host mesh: the hinges and their stencils, rest angles, B per triangle
  (hinges, bending_stencils, dihedral_angles, bending_matrices); the energy in float64
  (bending_energy);
- force in three loops (bending_phases): every hinge's angle, tangent, rate and gradient
  (hinge_angles), every triangle's moments dE/dt_i (face_moments), every hinge's corner forces
  -(M_1 + M_2) grad t (hinge_forces), each gathered per particle in a fixed order;
- Hessian: Gauss-Newton, sum_ij B_ij grad t_i grad t_j^T, positive semi-definite (B is a Gram
  matrix; the moments' term sum_i M_i Hess t_i is dropped as a spring's compressed lateral
  term is): its product takes every hinge's s = grad t . p, then every hinge's response
  (linearise_hinge, project_hinge, hinge_product); the preconditioner takes the diagonal
  blocks without the cross terms between a triangle's hinges (hinge_weight);
- projection: XPBD on a triangle's three hinge tangents with compliance B^-1 (xpbd_bending;
  a hinge missing from a triangle has c = 0 and no gradient, so its row leaves the others'
  equations alone), each triangle swept only in the passes its stiffness at the step needs
  (faces.passes_needed).
"""

import numpy as np
import taichi as ti

from ..runtime.plan import DT, ITEM, STATE, Loop, Phase, Sweep
from .bending_law import face_matrix
from .faces import (
    clear_passes,
    count_pass,
    face_intact,
    motion_in_step,
    multiplier_step,
    needs_pass,
    stiffness_ratio,
)

# |theta / 2| past which t = tan(theta / 2) continues along its tangent line (a crease folded
# flat, theta -> pi, would make t and its slope unbounded)
HALF_ANGLE_LIMIT = 0.45 * np.pi


def hinges(triangles: np.ndarray, weld: np.ndarray | None = None) -> tuple:
    """The interior edges of a triangle mesh as hinges (edges on exactly two triangles; a
    boundary edge, or one on three or more triangles, has none). With `weld` ((N,) each
    particle's representative, welded: particles a garment's seams sew together share one),
    edges are matched by their ends' representatives, so an edge sewn to another is a hinge
    across the seam: its a, b and c are the first triangle's particles, d the second's.

    Returns (indices (H, 4) [a, b, c, d]: the edge a -> b as its first triangle winds it, c
    opposite in that triangle, d in the other; faces (H, 2): 3 f + i of the two triangles,
    i the edge's local index (edge i is opposite corner i); face_hinge (T, 3): the hinge of
    each triangle edge or -1; face_sign (T, 3): +1, or -1 where the triangle winds the edge
    the same way as the hinge's first triangle (meshes not consistently oriented))."""
    t = len(triangles)
    local = np.arange(3)
    start = triangles[:, (local + 1) % 3].ravel()
    end = triangles[:, (local + 2) % 3].ravel()
    same = (lambda p: p) if weld is None else (lambda p: weld[p])
    key = np.stack([np.minimum(same(start), same(end)), np.maximum(same(start), same(end))], 1)
    order = np.lexsort((np.arange(3 * t), key[:, 1], key[:, 0]))
    sorted_key = key[order]
    boundary = np.concatenate([[True], np.any(sorted_key[1:] != sorted_key[:-1], axis=1), [True]])
    group_start = np.flatnonzero(boundary[:-1])
    group_size = np.diff(np.flatnonzero(boundary))
    pair = group_start[group_size == 2]
    pair = pair[sorted_key[pair, 0] != sorted_key[pair, 1]]     # no edge sewn to a point
    first, second = order[pair], order[pair + 1]                  # codes 3 f + i, f in order
    face_hinge = np.full(3 * t, -1, np.int64)
    face_hinge[first] = face_hinge[second] = np.arange(len(pair))
    face_sign = np.ones(3 * t, np.int64)
    face_sign[second] = np.where(same(start[second]) == same(start[first]), -1, 1)
    f1, i1 = np.divmod(first, 3)
    f2, i2 = np.divmod(second, 3)
    indices = np.stack([start[first], end[first], triangles[f1, i1], triangles[f2, i2]], 1)
    return (indices.astype(np.int64), np.stack([first, second], 1).astype(np.int64),
            face_hinge.reshape(t, 3), face_sign.reshape(t, 3))


def welded(seams: np.ndarray, n: int) -> np.ndarray:
    """(N,) each particle's representative: the least index of the particles the seam pairs
    (P, 2) join to it, directly or through others (a corner where three panels meet); itself
    for a particle on no seam."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if not len(seams):
        return np.arange(n)
    graph = coo_matrix((np.ones(len(seams)), (seams[:, 0], seams[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    least = np.full(label.max() + 1, n)
    np.minimum.at(least, label, np.arange(n))
    return least[label]


def weld_groups(weld: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(start (G + 1,), member (M,)): the groups of two or more particles that share a
    representative (welded), as a CSR in increasing order, so the representative (the
    least) comes first in each."""
    order = np.argsort(weld, kind="stable")
    size = np.bincount(weld, minlength=len(weld))
    grouped = order[size[weld[order]] >= 2]
    start = np.concatenate([[0], np.cumsum(size[size >= 2])])
    return start.astype(np.int64), grouped.astype(np.int64)


def second_edge(cloth) -> np.ndarray:
    """(H, 2): the particles of each hinge's second triangle at its ends a and b: a and b
    themselves, but across a seam (hinges' weld) the other panel's particles sewn to them."""
    if not cloth.hinge_count:
        return np.zeros((0, 2), np.int64)
    weld = cloth.particle_weld
    f2, i2 = np.divmod(cloth.hinge_faces[:, 1], 3)
    ends = cloth.face_indices[f2[:, None], (i2[:, None] + [1, 2]) % 3]           # (H, 2)
    turned = weld[ends[:, 0]] != weld[cloth.hinge_indices[:, 0]]
    return np.where(turned[:, None], ends[:, ::-1], ends)


def bending_stencils(cloth) -> np.ndarray:
    """(F, 6): each triangle's corners, then across each edge i the vertex opposite in the
    neighbouring triangle (corner i itself across a boundary edge): the particles its
    bending energy moves."""
    stencil = np.concatenate([cloth.face_indices, cloth.face_indices], axis=1)
    face, edge = np.nonzero(cloth.face_hinge >= 0)
    hinge = cloth.face_hinge[face, edge]
    first = cloth.hinge_faces[hinge, 0] // 3 == face
    stencil[face, 3 + edge] = np.where(first, cloth.hinge_indices[hinge, 3],
                                       cloth.hinge_indices[hinge, 2])
    return stencil


def dihedral_angles(positions: np.ndarray, indices: np.ndarray, gradient: bool = False):
    """Dihedral angles theta (H,) of hinges [a, b, c, d] at `positions` (module doc), and with
    `gradient` their gradients (H, 4, 3) too."""
    a, b, c, d = (positions[indices[:, k]] for k in range(4))
    edge = b - a
    length = np.linalg.norm(edge, axis=1)
    m1, m2 = np.cross(edge, c - a), np.cross(d - a, edge)
    area1, area2 = np.linalg.norm(m1, axis=1), np.linalg.norm(m2, axis=1)
    n1, n2 = m1 / area1[:, None], m2 / area2[:, None]
    theta = np.arctan2(np.sum(np.cross(n1, n2) * edge, 1) / length, np.sum(n1 * n2, 1))
    if not gradient:
        return theta
    grad_c = -n1 * (length / area1)[:, None]           # h1 = area1 / length
    grad_d = -n2 * (length / area2)[:, None]
    s1 = (np.sum((c - a) * edge, 1) / length ** 2)[:, None]
    s2 = (np.sum((d - a) * edge, 1) / length ** 2)[:, None]
    grad = np.stack([-(1 - s1) * grad_c - (1 - s2) * grad_d, -s1 * grad_c - s2 * grad_d,
                     grad_c, grad_d], 1)
    return theta, grad


def curvature_bases(gradients: np.ndarray) -> np.ndarray:
    """K_i (T, 3, 2, 2) = -2 |grad lambda_i| u_i u_i^T (module doc)."""
    length = np.linalg.norm(gradients, axis=2)
    return -2.0 * np.einsum("tci,tcj->tcij", gradients, gradients) / length[:, :, None, None]


def curvature_components(gradients: np.ndarray, face_sign: np.ndarray) -> np.ndarray:
    """b (T, 3, 3): b[t, d, i] = s_i (K_i)_d, d = 11, 22, 12, so that a triangle's change of
    curvature is k_d = sum_i b[t, d, i] dt_i (body/bending_curve.py's law reads it)."""
    k = curvature_bases(gradients)
    return face_sign[:, None, :] * np.stack([k[:, :, 0, 0], k[:, :, 1, 1], k[:, :, 0, 1]], 1)


def bending_matrices(components: np.ndarray, areas: np.ndarray,
                     flexural: np.ndarray) -> np.ndarray:
    """B (T, 3, 3) = A s_i s_j <K_i, K_j>_D = A sum_d c_d D_d b_di b_dj, D = (D11, D22, D12)
    per triangle (T, 3), b the curvature_components, c = (1, 1, 2)."""
    weights = flexural * np.array([1.0, 1.0, 2.0])
    return areas[:, None, None] * np.einsum("td,tdi,tdj->tij", weights, components, components)


def tangents(theta: np.ndarray) -> np.ndarray:
    """t = tan(theta / 2), continued along its tangent line past |theta / 2| =
    HALF_ANGLE_LIMIT."""
    half = 0.5 * np.asarray(theta, np.float64)
    limit = HALF_ANGLE_LIMIT
    beyond = np.sign(half) * (np.tan(limit) + (np.abs(half) - limit) / np.cos(limit) ** 2)
    return np.where(np.abs(half) > limit, beyond, np.tan(half))


def hinge_tangents(cloth, positions: np.ndarray) -> np.ndarray:
    """dt_e = t(theta_e) - t(theta_rest_e) per hinge (H,) (tangents)."""
    theta = dihedral_angles(positions, cloth.hinge_indices)
    return tangents(theta) - tangents(cloth.hinge_rest_angle)


def face_tangents(cloth, values: np.ndarray) -> np.ndarray:
    """A per-hinge quantity (H,) on each triangle's three edges (T, 3), 0 on boundary edges."""
    padded = np.concatenate([values, [0.0]])
    return padded[cloth.face_hinge]                    # face_hinge = -1 reads the 0 at the end


def intact_hinges(cloth, alive: np.ndarray | None) -> np.ndarray:
    """(H,) bool: the hinges whose two triangles are both intact (alive: (F,) bool, None: all)."""
    if alive is None:
        return np.ones(cloth.hinge_count, bool)
    return alive[cloth.hinge_faces // 3].all(axis=1)


def bending_energy(cloth, positions: np.ndarray, alive: np.ndarray | None = None) -> float:
    """sum over triangles of 1/2 dt^T B dt [J] (module doc), A psi(k) where the rigidity
    depends on curvature (body/bending_curve.py); with `alive` ((F,) bool: not torn), a torn
    triangle holds none and a hinge beside one is gone."""
    if not cloth.hinge_count:
        return 0.0
    dt = face_tangents(cloth, hinge_tangents(cloth, positions) * intact_hinges(cloth, alive))
    per_face = 0.5 * np.einsum("ti,tij,tj->t", dt, cloth.face_bending, dt)
    k = np.einsum("tdi,ti->td", cloth.face_components, dt)
    for c, curve in enumerate(cloth.bending_curves):       # psi(k) A where a curve bends it
        faces = cloth.face_curve == c
        per_face[faces] = cloth.face_area[faces] * curve.density(k[faces])
    return float(per_face.sum())


@ti.func
def half_angle_tangent(sine, cosine, radius):
    """(t, dt/dtheta) of t = tan(theta / 2) for the angle theta whose sine and cosine are
    (sine, cosine) / radius (radius > 0): sine / (radius + cosine), the half-angle identity,
    without a trigonometric call; continued along its tangent line past HALF_ANGLE_LIMIT, where
    theta nears pi and the identity would lose its digits."""
    limit = ti.static(HALF_ANGLE_LIMIT)
    t, slope = 0.0, 0.0
    if cosine > ti.static(np.cos(2 * HALF_ANGLE_LIMIT)) * radius:
        t = sine / (radius + cosine)
        slope = 0.5 * (1.0 + t * t)             # d tan(theta / 2) / d theta
    else:
        edge_slope = 0.5 / (ti.cos(limit) ** 2)
        half = 0.5 * ti.atan2(sine, cosine)
        sign = 1.0 if half > 0 else -1.0
        t = sign * (ti.tan(limit) + 2.0 * edge_slope * (ti.abs(half) - limit))
        slope = edge_slope
    return t, slope


@ti.func
def hinge_gradient(model: ti.template(), positions: ti.template(), e):
    """(t, grad t on corners a, b, c, d) of hinge e [a, b, c, d] at `positions`, t = tan(theta /
    2) continued (half_angle_tangent) of its dihedral angle; the angle and its gradient: module doc
    (Tamstorf & Grinspun 2013, eq. 8), with the face normals left unnormalised (m1 = |m1| n1):
    theta's sine and cosine are (m1 x m2) . e / |e| and m1 . m2 over |m1| |m2| (three square
    roots and four divisions a hinge, no trigonometric call). A hinge with an edge or face of
    zero length or area has no angle: t and its gradient 0."""
    return corner_gradient(positions, model.hinge_indices[e])


@ti.func
def corner_gradient(positions: ti.template(), corner):
    """hinge_gradient of the hinge on the particles corner = [a, b, c, d]."""
    xa = positions[corner[0]]
    edge = positions[corner[1]] - xa
    to_c = positions[corner[2]] - xa
    to_d = positions[corner[3]] - xa
    m1 = edge.cross(to_c)
    m2 = to_d.cross(edge)
    length2 = edge.dot(edge)
    area1 = m1.dot(m1)                          # (twice the triangle's area)^2
    area2 = m2.dot(m2)
    zero = ti.Vector([0.0, 0.0, 0.0])
    grad_a, grad_b, grad_c, grad_d = zero, zero, zero, zero
    t = 0.0
    if length2 > 0 and area1 > 0 and area2 > 0:
        length = ti.sqrt(length2)
        inverse = 1.0 / length
        t, slope = half_angle_tangent(m1.cross(m2).dot(edge) * inverse, m1.dot(m2),
                            ti.sqrt(area1) * ti.sqrt(area2))   # their product ~ h^8
        grad_c = -(slope * length / area1) * m1
        grad_d = -(slope * length / area2) * m2
        s1 = to_c.dot(edge) * inverse * inverse
        s2 = to_d.dot(edge) * inverse * inverse
        grad_a = -(1.0 - s1) * grad_c - (1.0 - s2) * grad_d
        grad_b = -s1 * grad_c - s2 * grad_d
    return t, grad_a, grad_b, grad_c, grad_d


@ti.func
def hinge_intact(model: ti.template(), state: ti.template(), e):
    """Whether both triangles of hinge e are intact (a torn one takes the hinge with it)."""
    faces = model.hinge_faces[e]
    return state.face_alive[faces[0] // 3] != 0 and state.face_alive[faces[1] // 3] != 0


@ti.func
def hinge_angles(model: ti.template(), state: ti.template(), forces: ti.template(), e):
    """Hinge e: hinge_tangent = t - t_rest, hinge_rate = dt/dt, and the gradient of t on each
    corner into hinge_force[4 e + k] (hinge_forces scales it); all zero for a hinge without
    an angle or (tearing) beside a torn triangle."""
    corner = model.hinge_indices[e]
    t, grad_a, grad_b, grad_c, grad_d = hinge_gradient(model, state.particle_position, e)
    if ti.static(forces.tearable):
        if not hinge_intact(model, state, e):
            zero = ti.Vector([0.0, 0.0, 0.0])
            grad_a, grad_b, grad_c, grad_d = zero, zero, zero, zero
    strain, rate = 0.0, 0.0
    if grad_c.norm_sqr() > 0:
        strain = t - model.hinge_rest_tangent[e]
        rate = (grad_a.dot(state.particle_velocity[corner[0]])
                + grad_b.dot(state.particle_velocity[corner[1]])
                + grad_c.dot(state.particle_velocity[corner[2]])
                + grad_d.dot(state.particle_velocity[corner[3]]))
    state.hinge_tangent[e] = strain
    state.hinge_rate[e] = rate
    state.hinge_force[4 * e] = grad_a
    state.hinge_force[4 * e + 1] = grad_b
    state.hinge_force[4 * e + 2] = grad_c
    state.hinge_force[4 * e + 3] = grad_d


@ti.func
def face_hinge_tangents(model: ti.template(), state: ti.template(), f):
    """(dt, its rate) of triangle f's three hinges (0 across a boundary edge)."""
    hinge = model.face_hinge[f]
    dt = ti.Vector([0.0, 0.0, 0.0])
    rate = ti.Vector([0.0, 0.0, 0.0])
    for i in ti.static(range(3)):
        if hinge[i] >= 0:
            dt[i] = state.hinge_tangent[hinge[i]]
            rate[i] = state.hinge_rate[hinge[i]]
    return dt, rate


@ti.func
def face_moments(model: ti.template(), state: ti.template(), f):
    """face_moment[3 f + i] = dE_f/dt_i = sum_j B_ij (dt_j + beta rate_j), the moment of
    triangle f's bending energy 1/2 dt^T B dt on the hinge across its edge i (0 across a
    boundary edge, which has no hinge); B the secant matrix B(k) where the fabric's rigidity
    depends on curvature (bending_law.py: then sum_j B_ij dt_j is still dE_f/dt_i)."""
    dt, rate = face_hinge_tangents(model, state, f)
    q = dt + model.face_damping[f] * rate
    b = face_matrix(model, f, dt, False)       # symmetric: 00, 11, 22, 01, 02, 12
    state.face_moment[3 * f] = b[0] * q[0] + b[3] * q[1] + b[4] * q[2]
    state.face_moment[3 * f + 1] = b[3] * q[0] + b[1] * q[1] + b[5] * q[2]
    state.face_moment[3 * f + 2] = b[4] * q[0] + b[5] * q[1] + b[2] * q[2]


@ti.func
def hinge_forces(model: ti.template(), state: ti.template(), e):
    """hinge_force[4 e + k] = -(M_1 + M_2) grad_k t: the bending force of hinge e on its
    corner k, M the moments of its two triangles (face_moments)."""
    faces = model.hinge_faces[e]
    moment = state.face_moment[faces[0]] + state.face_moment[faces[1]]
    for k in ti.static(range(4)):
        state.hinge_force[4 * e + k] = -moment * state.hinge_force[4 * e + k]


def force_loops(model, forces) -> tuple:
    """The loop of the first force phase that measures every hinge (hinge_angles), for a
    model with hinges bent by the tangents (not Model.isometric); bending_phases follow."""
    if not model.hinge_count or model.isometric:
        return ()
    return (Loop(model.hinge_count, hinge_angles, model, STATE, forces, ITEM),)


def bending_phases(model, with_moments: tuple = (), with_forces: tuple = ()) -> tuple:
    """The phases after the first: the triangles' moments, then the hinges' forces (each with
    the caller's loops that read the same inputs: with_moments read the hinges' angles and
    gradients, with_forces everything the moments' phase wrote)."""
    if not model.hinge_count or model.isometric:
        return ()
    return (Phase(Loop(model.face_count, face_moments, model, STATE, ITEM), *with_moments),
            Phase(Loop(model.hinge_count, hinge_forces, model, STATE, ITEM), *with_forces))


@ti.func
def project_hinge(model: ti.template(), ws: ti.template(), e, vectors: ti.template()):
    """hinge_projection[e] = grad t_e . vectors over the hinge's corners."""
    corner = model.hinge_indices[e]
    total = 0.0
    for k in ti.static(range(4)):
        total += ws.hinge_gradient[4 * e + k].dot(vectors[corner[k]])
    ws.hinge_projection[e] = total


@ti.func
def bending_row(b, i):
    """Row i of a triangle's symmetric B stored as (00, 11, 22, 01, 02, 12)."""
    row = ti.Vector([b[4], b[5], b[2]])
    if i == 0:
        row = ti.Vector([b[0], b[3], b[4]])
    elif i == 1:
        row = ti.Vector([b[3], b[1], b[5]])
    return row


@ti.func
def hinge_weight(model: ti.template(), state: ti.template(), f, i, dt, rhs: ti.template()):
    """(h^2 + h beta) B_ii of hinge i of triangle f, or B_ii for the right-hand side (B the
    positive secant matrix at the step's start where the rigidity depends on curvature)."""
    b = face_matrix(model, f, face_hinge_tangents(model, state, f)[0], True)
    weight = b[2]
    if i == 0:
        weight = b[0]
    elif i == 1:
        weight = b[1]
    if ti.static(not rhs):
        weight *= dt * dt + dt * model.face_damping[f]
    return weight


@ti.func
def linearise_hinge(model: ti.template(), state: ti.template(), ws: ti.template(), e,
                    now: ti.template()):
    """Hinge e at x_n (after hinge_angles left grad t in hinge_force, before hinge_forces):
    its gradient, grad t . v_n and the hinge-diagonal part of its blocks of A."""
    faces = model.hinge_faces[e]
    weight = (hinge_weight(model, state, faces[0] // 3, faces[0] % 3, now.dt, False)
              + hinge_weight(model, state, faces[1] // 3, faces[1] % 3, now.dt, False))
    for k in ti.static(range(4)):
        gradient = state.hinge_force[4 * e + k]
        ws.hinge_gradient[4 * e + k] = gradient
        ws.hinge_diagonal[4 * e + k] = weight * gradient * gradient
    project_hinge(model, ws, e, state.particle_velocity)


@ti.func
def store_secant(model: ti.template(), state: ti.template(), ws: ti.template(), f):
    """face_secant[f] = triangle f's positive secant matrix at the step's start (read by
    hinge_product where the rigidity depends on curvature)."""
    ws.face_secant[f] = face_matrix(model, f, face_hinge_tangents(model, state, f)[0], True)


@ti.func
def hinge_product(model: ti.template(), ws: ti.template(), e, dt, rhs: ti.template()):
    """hinge_product[4 e + k] = sum over hinge e's triangles of (h^2 + h beta) (B s)_i
    grad_k t_e (B s without the factor for the right-hand side), s the projections."""
    faces = model.hinge_faces[e]
    moment = 0.0
    for side in ti.static(range(2)):
        f, i = faces[side] // 3, faces[side] % 3
        b = model.face_bending[f]
        if ti.static(model.curved):
            b = ws.face_secant[f]
        row = bending_row(b, i)
        hinge = model.face_hinge[f]
        total = 0.0
        for j in ti.static(range(3)):
            if hinge[j] >= 0:
                total += row[j] * ws.hinge_projection[hinge[j]]
        if ti.static(not rhs):
            total *= dt * dt + dt * model.face_damping[f]
        moment += total
    for k in ti.static(range(4)):
        ws.hinge_product[4 * e + k] = moment * ws.hinge_gradient[4 * e + k]


@ti.func
def hinge_on_face(model: ti.template(), positions: ti.template(), f, e):
    """Hinge e of triangle f: (t, grad t on f's corners 0, 1, 2, grad t on the hinge's other
    corner, that corner's particle). Across a seam the hinge's corners sewn to f's (the same
    particle_weld) are measured at f's own, so that f reads no particle outside its stencil
    (bending_stencils: what XPBD's colouring keeps apart)."""
    face = model.face_indices[f]
    corner = model.hinge_indices[e]
    if ti.static(model.sewn):
        for k in ti.static(range(4)):
            for j in ti.static(range(3)):
                if model.particle_weld[corner[k]] == model.particle_weld[face[j]]:
                    corner[k] = face[j]
    t, ga, gb, gc, gd = corner_gradient(positions, corner)
    grads = [ga, gb, gc, gd]
    zero = ti.Vector([0.0, 0.0, 0.0])
    g0, g1, g2, other_grad = zero, zero, zero, zero
    other = corner[3]
    for k in ti.static(range(4)):
        p = corner[k]
        if p == face[0]:
            g0 = grads[k]
        elif p == face[1]:
            g1 = grads[k]
        elif p == face[2]:
            g2 = grads[k]
        else:
            other_grad = grads[k]
            other = p
    return t, g0, g1, g2, other_grad, other


@ti.func
def hinge_term(model: ti.template(), state: ti.template(), f, i: ti.template(),
                tearable: ti.template()):
    """The hinge across triangle f's edge i: (dt, grad t on f's corners 0, 1, 2, on the other
    corner, that corner's particle, grad t . (x - x_n)); all 0 across a boundary edge (the
    hinge is then hinge 0 of the model, read, never moved) or for a hinge without an angle."""
    face = model.face_indices[f]
    hinge = model.face_hinge[f][i]
    e = ti.max(hinge, 0)
    valid = ti.cast(hinge >= 0, float)
    if ti.static(tearable):
        if not hinge_intact(model, state, e):
            valid = 0.0
    t, g0, g1, g2, other_grad, other = hinge_on_face(model, state.particle_position, f, e)
    if other_grad.norm_sqr() == 0:      # no angle (hinge_angles)
        t = model.hinge_rest_tangent[e]
    g0, g1, g2, other_grad = valid * g0, valid * g1, valid * g2, valid * other_grad
    motion = (g0.dot(motion_in_step(state, face[0])) + g1.dot(motion_in_step(state, face[1]))
              + g2.dot(motion_in_step(state, face[2]))
              + other_grad.dot(motion_in_step(state, other)))
    return valid * (t - model.hinge_rest_tangent[e]), g0, g1, g2, other_grad, other, motion


@ti.func
def xpbd_bending(model: ti.template(), state: ti.template(), f, multiplier: ti.template(), dt,
                 tearable: ti.template()):
    """XPBD for triangle f's bending, its multipliers in multiplier[f]: the constraint is the
    tangents of the hinges across its three edges (0 and no gradient across a boundary or,
    tearing, beside a torn triangle). Returns the update's stiffness ratio
    (faces.stiffness_ratio; 0 for a torn triangle)."""
    ratio = 0.0
    if face_intact(state, f, tearable):
        ratio = bending_constraint(model, state, f, multiplier, dt, tearable)
    return ratio


@ti.func
def bending_constraint(model: ti.template(), state: ti.template(), f, multiplier: ti.template(), dt,
             tearable: ti.template()):
    face = model.face_indices[f]
    hinge = model.face_hinge[f]
    t0, g00, g10, g20, o0, p0, m0 = hinge_term(model, state, f, 0, tearable)
    t1, g01, g11, g21, o1, p1, m1 = hinge_term(model, state, f, 1, tearable)
    t2, g02, g12, g22, o2, p2, m2 = hinge_term(model, state, f, 2, tearable)
    g0s, g1s, g2s = [g00, g01, g02], [g10, g11, g12], [g20, g21, g22]
    others, other_grads = [p0, p1, p2], [o0, o1, o2]
    w0 = model.particle_inv_mass[face[0]]
    w1 = model.particle_inv_mass[face[1]]
    w2 = model.particle_inv_mass[face[2]]
    coupling = ti.Matrix.zero(float, 3, 3)
    for i in ti.static(range(3)):
        for j in ti.static(range(3)):
            shared = 0.0
            if others[i] == others[j]:
                shared = model.particle_inv_mass[others[i]] * other_grads[i].dot(other_grads[j])
            coupling[i, j] = (w0 * g0s[i].dot(g0s[j]) + w1 * g1s[i].dot(g1s[j])
                              + w2 * g2s[i].dot(g2s[j]) + shared)
    b = face_matrix(model, f, ti.Vector([t0, t1, t2]), True)     # 00, 11, 22, 01, 02, 12
    bending = ti.Matrix([[b[0], b[3], b[4]], [b[3], b[1], b[5]], [b[4], b[5], b[2]]])
    gamma = model.face_damping[f] / dt
    residual = ti.Vector([t0, t1, t2]) + gamma * ti.Vector([m0, m1, m2])
    stiffness = (dt * dt) * bending
    step = multiplier_step(stiffness, coupling, residual, multiplier[f], gamma)
    multiplier[f] = multiplier[f] + step
    moves = [w0 * (step[0] * g0s[0] + step[1] * g0s[1] + step[2] * g0s[2]),
             w1 * (step[0] * g1s[0] + step[1] * g1s[1] + step[2] * g1s[2]),
             w2 * (step[0] * g2s[0] + step[1] * g2s[1] + step[2] * g2s[2])]
    for k in ti.static(range(3)):
        state.particle_position[face[k]] = state.particle_position[face[k]] + moves[k]
    for i in ti.static(range(3)):
        if hinge[i] >= 0:      # across a boundary `others` is not in the triangle's stencil
            p = others[i]
            state.particle_position[p] = (state.particle_position[p]
                                          + model.particle_inv_mass[p] * step[i] * other_grads[i])
    return stiffness_ratio(stiffness, coupling, gamma)


@ti.func
def clear_multipliers(work: ti.template(), f):
    """Triangle f's multipliers 0 and no pass yet."""
    work.bending[f] = 0.0 * work.bending[f]
    clear_passes(work, f)


@ti.func
def xpbd_at(model: ti.template(), state: ti.template(), forces: ti.template(),
            work: ti.template(), t, dt):
    """XPBD for the triangle at position t of its colouring, in the passes it needs
    (faces.passes_needed)."""
    f = work.bending_colours.order[t]
    if needs_pass(work, f):
        count_pass(work, f, xpbd_bending(model, state, f, work.bending, dt, forces.tearable))


def xpbd_nodes(model, forces, work) -> tuple:
    """(loops clearing the multipliers, sweeps) of XPBD over the triangles' hinge tangents
    (xpbd.py's workspace `work`), none for a model without them."""
    if not model.hinge_count or model.isometric:
        return (), ()
    return ((Loop(model.face_count, clear_multipliers, work, ITEM),),
            (Sweep(work.bending_colours, xpbd_at, model, STATE, forces, work, ITEM,
                   DT).with_big_body(),))
