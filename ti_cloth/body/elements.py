"""The elements a Fabric body is made of (numpy, on the host): membrane triangles and bending
hinges, their rest data, and their energies in float64 (the kernels' twins are in
physics/elements.py).

Membrane: constant-strain triangles (linear FEM) with the plane-stress orthotropic
Saint Venant-Kirchhoff law. Each triangle has a rest material frame (warp, weft) in its plane;
F = sum_c x_c (x) grad(lambda_c) is the deformation gradient from that frame (3 x 2,
lambda_c the barycentric coordinates, their gradients constant on the rest triangle), the
Green strain is E = 1/2 (F^T F - I), and the energy A/2 e^T C e with e = (E11, E22, 2 E12)
and C = Fabric.membrane (Bonet & Wood, "Nonlinear continuum mechanics for finite element
analysis", 2008, eq. 6.11 and 7.13 with plane-stress orthotropy; Volino, Magnenat-Thalmann &
Faure, "A simple approach to nonlinear tensile stiffness for accurate cloth simulation",
ACM TOG 28(4), 2009, sec. 3).

Bending: the mid-edge shape operator of Grinspun, Gingold, Reisman & Zorin, "Computing
discrete shape operators on general meshes", Eurographics 2006 (eq. 4), in the tangent form of
Weischedel, "A discrete geometric view on shear-deformable shell models" (2012) and
Chen, Sastry, van Rees & Vouga, "Physical simulation of environmentally induced thin shell
deformation", ACM TOG 37(4), 2018 (eq. 5, "MidedgeTan"). Across each interior edge e
(a hinge: the edge a-b and the vertices c, d opposite it) the dihedral angle theta_e is
measured between the two face normals; a triangle's curvature in its rest frame is

    k = sum_i t_i K_i,   t_i = tan(theta_i / 2),   K_i = -2 |grad lambda_i| u_i u_i^T,

over its three edges i (edge i is opposite corner i; u_i = grad(lambda_i) / |grad lambda_i|,
the inward normal of edge i; a boundary edge has t_i = 0). The energy is
A/2 (k - k_rest) : D : (k - k_rest) with D = Fabric.flexural, i.e. 1/2 dt^T B dt with
dt_i = t_i - t_rest_i and B_ij = A <K_i, K_j>_D, a 3 x 3 positive semi-definite matrix per
triangle. The rest angles come from the rest mesh, so a curved rest shape is kept. Unlike a
bending spring, or an energy on each hinge alone (Bridson, Marino & Fedkiw 2003; Grinspun et
al. 2003, "Discrete shells"), which on a regular grid is three times stiffer across the
diagonals than along the axes, this operator bends a grid the same way in every direction
(tests/test_fabric.py measures both).

A flat rest sheet (is_flat) bends by the isometric model instead (Bergou, Wardetzky, Harmon,
Zorin & Grinspun 2006; isometric_matrix): the same B on vectors w_i with |w_i| = 2 |e_i|
sin(theta_i / 2), an energy quadratic in the positions, 1/2 x^T Q x with Q constant.

The dihedral angle: with (a, b) the edge as the first face winds it and c, d the opposite
vertices, n1 = (b - a) x (c - a) / |.|, n2 = (d - a) x (b - a) / |.|, e = (b - a) / |b - a|:
theta = atan2((n1 x n2) . e, n1 . n2). Its gradient (Bridson et al. 2003; Tamstorf &
Grinspun, "Discrete bending forces and their Jacobians", Graphical Models 75, 2013, eq. 8):
grad_c = -n1 / h1, grad_d = -n2 / h2 (h the heights of c and d over the edge's line),
grad_a = -(1 - s1) grad_c - (1 - s2) grad_d, grad_b = -s1 grad_c - s2 grad_d, with s the
parameter of c's (d's) foot along a -> b. A face whose winding runs against the first face's
across the edge gets the hinge's t with the opposite sign (face_sign).
"""

from __future__ import annotations

import numpy as np

from ..inputs.validation import as_array, require
from .mesh import Mesh

# |theta / 2| past which t = tan(theta / 2) continues along its tangent line (a crease folded
# flat, theta -> pi, would make t and its slope unbounded)
HALF_ANGLE_LIMIT = 0.45 * np.pi


def material_frames(positions: np.ndarray, triangles: np.ndarray, warp) -> tuple:
    """(gradients (T, 3, 2), areas (T,)): each triangle's barycentric gradients in its rest
    material frame, and its rest area [m^2]. The frame's first axis is `warp` (one (3,)
    direction, or (T, 3) per triangle) projected into the triangle's plane; where it is
    (nearly) normal to the triangle, the triangle's first edge."""
    p = positions[triangles]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    normal = np.cross(e1, e2)
    area2 = np.linalg.norm(normal, axis=1)
    n = normal / area2[:, None]
    warp = np.broadcast_to(np.asarray(warp, np.float64), p[:, 0].shape)
    u = warp - np.sum(warp * n, axis=1, keepdims=True) * n
    length = np.linalg.norm(u, axis=1)
    fallback = length < 1e-6 * np.linalg.norm(warp, axis=1)
    u[fallback] = e1[fallback]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(n, u)
    # rest edges in the frame, as the columns of Dm; grad lambda_1, lambda_2 are Dm^-1's rows
    dm = np.stack([np.stack([np.sum(e1 * u, 1), np.sum(e2 * u, 1)], 1),
                   np.stack([np.sum(e1 * w, 1), np.sum(e2 * w, 1)], 1)], 1)       # (T, 2, 2)
    inverse = np.linalg.inv(dm)
    gradients = np.stack([-inverse[:, 0] - inverse[:, 1], inverse[:, 0], inverse[:, 1]], 1)
    return gradients, 0.5 * area2


def deformation_gradients(positions: np.ndarray, triangles: np.ndarray,
                          gradients: np.ndarray) -> np.ndarray:
    """F (T, 3, 2) = sum_c x_c (x) grad lambda_c."""
    return np.einsum("tci,tcj->tij", positions[triangles], gradients)


def green_strains(positions, triangles, gradients) -> np.ndarray:
    """(T, 3): (E11, E22, 2 E12) of E = 1/2 (F^T F - I), in the warp/weft frame."""
    f = deformation_gradients(positions, triangles, gradients)
    a, b = f[:, :, 0], f[:, :, 1]
    return np.stack([0.5 * (np.sum(a * a, 1) - 1.0), 0.5 * (np.sum(b * b, 1) - 1.0),
                     np.sum(a * b, 1)], 1)


def membrane_energy(cloth, positions: np.ndarray, alive: np.ndarray | None = None) -> float:
    """sum over triangles (those `alive`, (F,) bool, when given: not torn) of A/2 e^T C e [J]
    (module doc)."""
    if not cloth.face_count:
        return 0.0
    e = green_strains(positions, cloth.face_indices, cloth.face_gradient)
    c11, c12, c22, c33 = cloth.face_moduli.T
    density = 0.5 * (c11 * e[:, 0] ** 2 + 2 * c12 * e[:, 0] * e[:, 1] + c22 * e[:, 1] ** 2
                     + c33 * e[:, 2] ** 2)
    if alive is not None:
        density = density * alive
    return float(np.sum(cloth.face_area * density))


def hinges(triangles: np.ndarray) -> tuple:
    """The interior edges of a triangle mesh as hinges (edges on exactly two triangles; a
    boundary edge, or one on three or more triangles, has none).

    Returns (indices (H, 4) [a, b, c, d]: the edge a -> b as its first triangle winds it, c
    opposite in that triangle, d in the other; faces (H, 2): 3 f + i of the two triangles,
    i the edge's local index (edge i is opposite corner i); face_hinge (T, 3): the hinge of
    each triangle edge or -1; face_sign (T, 3): +1, or -1 where the triangle winds the edge
    the same way as the hinge's first triangle (meshes not consistently oriented))."""
    t = len(triangles)
    local = np.arange(3)
    start = triangles[:, (local + 1) % 3].ravel()
    end = triangles[:, (local + 2) % 3].ravel()
    key = np.stack([np.minimum(start, end), np.maximum(start, end)], 1)
    order = np.lexsort((np.arange(3 * t), key[:, 1], key[:, 0]))
    sorted_key = key[order]
    boundary = np.concatenate([[True], np.any(sorted_key[1:] != sorted_key[:-1], axis=1), [True]])
    group_start = np.flatnonzero(boundary[:-1])
    group_size = np.diff(np.flatnonzero(boundary))
    pair = group_start[group_size == 2]
    first, second = order[pair], order[pair + 1]                  # codes 3 f + i, f in order
    face_hinge = np.full(3 * t, -1, np.int64)
    face_hinge[first] = face_hinge[second] = np.arange(len(pair))
    face_sign = np.ones(3 * t, np.int64)
    face_sign[second] = np.where(start[second] == start[first], -1, 1)
    f1, i1 = np.divmod(first, 3)
    f2, i2 = np.divmod(second, 3)
    indices = np.stack([start[first], end[first], triangles[f1, i1], triangles[f2, i2]], 1)
    return (indices.astype(np.int64), np.stack([first, second], 1).astype(np.int64),
            face_hinge.reshape(t, 3), face_sign.reshape(t, 3))


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


def hinge_angles(positions: np.ndarray, indices: np.ndarray, gradient: bool = False):
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


def bending_matrices(gradients: np.ndarray, areas: np.ndarray, face_sign: np.ndarray,
                     flexural: np.ndarray) -> np.ndarray:
    """B (T, 3, 3) = A s_i s_j <K_i, K_j>_D, D = (D11, D22, D12) per triangle (T, 3)."""
    k = curvature_bases(gradients)
    d11, d22, d12 = flexural.T
    inner = (d11[:, None, None] * k[:, :, None, 0, 0] * k[:, None, :, 0, 0]
             + d22[:, None, None] * k[:, :, None, 1, 1] * k[:, None, :, 1, 1]
             + 2 * d12[:, None, None] * k[:, :, None, 0, 1] * k[:, None, :, 0, 1])
    sign = face_sign[:, :, None] * face_sign[:, None, :]
    return areas[:, None, None] * sign * inner


def tangents(theta: np.ndarray) -> np.ndarray:
    """t = tan(theta / 2), continued along its tangent line past |theta / 2| =
    HALF_ANGLE_LIMIT."""
    half = 0.5 * np.asarray(theta, np.float64)
    limit = HALF_ANGLE_LIMIT
    beyond = np.sign(half) * (np.tan(limit) + (np.abs(half) - limit) / np.cos(limit) ** 2)
    return np.where(np.abs(half) > limit, beyond, np.tan(half))


def hinge_tangents(cloth, positions: np.ndarray) -> np.ndarray:
    """dt_e = t(theta_e) - t(theta_rest_e) per hinge (H,) (tangents)."""
    theta = hinge_angles(positions, cloth.hinge_indices)
    return tangents(theta) - tangents(cloth.hinge_rest_angle)


def face_tangents(cloth, values: np.ndarray) -> np.ndarray:
    """A per-hinge quantity (H,) on each triangle's three edges (T, 3), 0 on boundary edges."""
    padded = np.concatenate([values, [0.0]])
    return padded[cloth.face_hinge]                    # face_hinge = -1 reads the 0 at the end


def bending_energy(cloth, positions: np.ndarray, alive: np.ndarray | None = None,
                   isometric: bool = False) -> float:
    """sum over triangles of 1/2 dt^T B dt [J] (module doc), or with `isometric` (a flat rest
    sheet: is_flat) the isometric model's 1/2 sum_ij B'_ij w_i . w_j (isometric_matrix); with
    `alive` ((F,) bool: not torn), a torn triangle holds none and a hinge beside one is gone."""
    if not cloth.hinge_count:
        return 0.0
    intact = np.ones(cloth.hinge_count, bool)
    if alive is not None:
        intact = alive[cloth.hinge_faces // 3].all(axis=1)
    if isometric:
        weights, reduced = isometric_parts(cloth)
        w = np.einsum("hk,hkx->hx", weights, positions[cloth.hinge_indices]) * intact[:, None]
        w = np.concatenate([w, np.zeros((1, 3))])[cloth.face_hinge]          # (F, 3, 3)
        return float(0.5 * np.einsum("fix,fij,fjx->", w, reduced, w))
    dt = face_tangents(cloth, hinge_tangents(cloth, positions) * intact)
    return float(0.5 * np.einsum("ti,tij,tj->", dt, cloth.face_bending, dt))


def warp_directions(mesh: Mesh, warp) -> np.ndarray:
    """The warp direction of Cloth(warp=...): a given (3,) direction, or "uv": in each triangle
    the direction in which its texture coordinate u grows at constant v (d x / d u, from the
    mesh's uvs; (T, 3)); by default a grid's first axis (its columns), or x."""
    if isinstance(warp, str):
        require(warp == "uv", "warp", warp, '"uv" or a direction [x, y, z]')
        require(mesh.uvs is not None, "warp", warp,
                "a direction, or a mesh with texture coordinates (Mesh.uvs, one per vertex)")
        return uv_warp(mesh)
    if warp is not None:
        direction = as_array("warp", warp, np.float64, (3,))
        require(np.linalg.norm(direction) > 0, "warp", direction.tolist(), "a non-zero direction")
        return direction
    if mesh.grid_shape is not None:
        return mesh.vertices[1] - mesh.vertices[0]
    return np.array([1.0, 0.0, 0.0])


def uv_warp(mesh: Mesh) -> np.ndarray:
    """d x / d u of each triangle (T, 3): with edges d1, d2 and their uv differences
    (a1, b1), (a2, b2), [d1 d2] = J [[a1, a2], [b1, b2]], and J's first column is
    (b2 d1 - b1 d2) / (a1 b2 - a2 b1) (the tangent of normal mapping). A triangle whose uvs
    have (almost) no area has none: refused, naming it."""
    p = mesh.vertices[mesh.triangles]
    uv = mesh.uvs[mesh.triangles]
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    (a1, b1), (a2, b2) = (uv[:, 1] - uv[:, 0]).T, (uv[:, 2] - uv[:, 0]).T
    det = a1 * b2 - a2 * b1
    scale = np.maximum(np.abs(uv - uv[:, :1]).max(axis=(1, 2)), np.finfo(float).tiny) ** 2
    flat = np.flatnonzero(np.abs(det) <= 1e-9 * scale)
    require(len(flat) == 0, f"uvs of triangles {flat[:5].tolist()}", "(no area)",
            'a uv triangle of non-zero area for warp="uv" (or give warp a direction)')
    return (b2[:, None] * d1 - b1[:, None] * d2) / det[:, None]


def rest_rank_one(cloth) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The elements' stiffness linearised about rest as sums of rank-one terms g g^T, for the
    stability analyses (modes.py): [(indices (R, k), stiffness vectors g (R, k, 3), damping
    vectors (R, k, 3))], one group for the membranes (k = 3) and one for bending (k = 12: a
    triangle's three hinges, four corners each; a particle may appear in several slots, whose
    vectors add). At rest the stress and moments vanish, so the Gauss-Newton terms are the
    exact Hessian: membrane A J^T C J = sum_m g_m g_m^T with g = sqrt(A) L^T J (C = L L^T, J the
    Green strain's gradient); bending sum_ij B_ij G_i G_j^T = sum_m g_m g_m^T with
    g_m = sqrt(lambda_m) sum_i V_im G_i (B = V diag(lambda) V^T, G_i = t'(theta) grad theta of
    hinge i); on a flat rest sheet (is_flat) the isometric model's constant Q = sum_ij B'_ij
    K_i K_j^T (x) I (isometric_matrix), nine terms a triangle (g = sqrt(lambda_m) sum_i V_im
    K_i along each axis; it holds the mid-edge Hessian's normal part and adds the in-plane one,
    an upper bound for either model). Rayleigh damping is beta times the same: its vectors are
    sqrt(beta) g."""
    if not cloth.face_count:
        return []
    x = cloth.particle_position
    gradients, area = cloth.face_gradient, cloth.face_area
    f = deformation_gradients(x, cloth.face_indices, gradients)       # (T, 3, 2) at rest
    warp, weft = f[:, :, 0], f[:, :, 1]
    gx, gy = gradients[:, :, 0:1], gradients[:, :, 1:2]               # (T, 3 corners, 1)
    jacobian = np.stack([warp[:, None] * gx, weft[:, None] * gy,
                         warp[:, None] * gy + weft[:, None] * gx], 1)  # (T, 3 strains, 3, 3)
    c11, c12, c22, c33 = cloth.face_moduli.T
    moduli = np.zeros((cloth.face_count, 3, 3))
    moduli[:, 0, 0], moduli[:, 0, 1], moduli[:, 1, 0] = c11, c12, c12
    moduli[:, 1, 1], moduli[:, 2, 2] = c22, c33
    factor = np.linalg.cholesky(moduli)                                # C = L L^T
    membrane = np.sqrt(area)[:, None, None, None] * np.einsum("tsm,tscx->tmcx", factor, jacobian)
    beta = np.sqrt(cloth.face_damping)
    groups = [(np.repeat(cloth.face_indices, 3, axis=0), membrane.reshape(-1, 3, 3),
               np.repeat(beta, 3)[:, None, None] * membrane.reshape(-1, 3, 3))]
    if cloth.hinge_count and is_flat(cloth):
        weights, reduced = isometric_parts(cloth)
        values, vectors = np.linalg.eigh(reduced)
        modes = vectors * np.sqrt(np.maximum(values, 0.0))[:, None, :]       # V sqrt(lambda)
        per_face = np.concatenate([weights, np.zeros((1, 4))])[cloth.face_hinge]  # (F, 3, 4)
        scalar = np.einsum("fim,fik->fmik", modes, per_face).reshape(-1, 3, 12)
        bending = (scalar[:, :, None, :, None]                             # (F, mode, axis,
                   * np.eye(3)[None, None, :, None, :]).reshape(-1, 12, 3)  # slot, xyz)
        hinge_corners = np.concatenate([cloth.hinge_indices, np.zeros((1, 4), np.int64)])
        corners = np.repeat(hinge_corners[cloth.face_hinge].reshape(-1, 12), 9, axis=0)
        groups.append((corners, bending, np.repeat(beta, 9)[:, None, None] * bending))
    elif cloth.hinge_count:
        theta, grad = hinge_angles(x, cloth.hinge_indices, gradient=True)
        half = 0.5 * theta
        slope = np.where(np.abs(half) > HALF_ANGLE_LIMIT, 0.5 / np.cos(HALF_ANGLE_LIMIT) ** 2,
                         0.5 / np.cos(half) ** 2)
        hinge_vectors = np.concatenate([slope[:, None, None] * grad, np.zeros((1, 4, 3))])
        hinge_corners = np.concatenate([cloth.hinge_indices, np.zeros((1, 4), np.int64)])
        per_face = hinge_vectors[cloth.face_hinge]                      # (T, 3 hinges, 4, 3)
        values, vectors = np.linalg.eigh(cloth.face_bending)
        weights = vectors * np.sqrt(np.maximum(values, 0.0))[:, None, :]   # V sqrt(lambda)
        bending = np.einsum("tim,tikx->tmikx", weights, per_face).reshape(-1, 3, 12, 3)
        corners = np.repeat(hinge_corners[cloth.face_hinge].reshape(-1, 12), 3, axis=0)
        bending = bending.reshape(-1, 12, 3)
        groups.append((corners, bending, np.repeat(beta, 3)[:, None, None] * bending))
    return groups


# A flat rest sheet's bending needs no angle: the isometric model (module doc of
# isometric_matrix). Rest angles below this [rad] (a planar mesh's rounding) count as flat.
FLAT_REST_ANGLE = 1e-6


def cotangent_weights(positions: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """K (H, 4) of hinges [a, b, c, d] at rest (Bergou, Wardetzky, Harmon, Zorin & Grinspun,
    "A quadratic bending model for inextensible surfaces", SGP 2006, sec. 4.1):
    w = sum_k K_k x_k = (cot b1 + cot b2) a + (cot a1 + cot a2) b - (cot a1 + cot b1) c
    - (cot a2 + cot b2) d, with a1, b1 the rest angles at a and b in triangle (a, b, c) and
    a2, b2 in (a, b, d). In each triangle (cot b1 a + cot a1 b) / (cot a1 + cot b1) is the
    foot of c's altitude, so w is |e| (u1 + u2), u the unit vectors from c and d to the edge
    in their triangles: 0 on the flat rest sheet and |w| = 2 |e| sin(theta / 2) in any
    isometric deformation of it."""
    a, b, c, d = (positions[indices[:, k]] for k in range(4))

    def cot(apex, p, q):
        u, v = p - apex, q - apex
        return np.sum(u * v, 1) / np.linalg.norm(np.cross(u, v), axis=1)

    a1, b1 = cot(a, b, c), cot(b, a, c)
    a2, b2 = cot(a, b, d), cot(b, a, d)
    return np.stack([b1 + b2, a1 + a2, -(a1 + b1), -(a2 + b2)], 1)


def is_flat(cloth) -> bool:
    """Whether every hinge of `cloth` is flat at rest (FLAT_REST_ANGLE): its bending is then
    the isometric model (isometric_matrix), else the mid-edge tangents."""
    return cloth.hinge_count > 0 and bool(np.all(np.abs(cloth.hinge_rest_angle)
                                                 <= FLAT_REST_ANGLE))


def isometric_parts(cloth) -> tuple:
    """(K (H, 4) the hinges' cotangent weights, B' (F, 3, 3) = s_i s_j B_ij / (4 |e_i| |e_j|),
    0 across a boundary edge): the isometric model's constants (isometric_matrix)."""
    weights = cotangent_weights(cloth.particle_position, cloth.hinge_indices)
    ends = cloth.particle_position[cloth.hinge_indices[:, :2]]
    lengths = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)
    _, _, face_hinge, face_sign = hinges(cloth.face_indices)
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
    keep = rows != cols
    unique, inverse = np.unique(rows[keep] * n + cols[keep], return_inverse=True)
    stiffness = -np.bincount(inverse, weights=local.ravel()[keep], minlength=len(unique))
    damping = -np.bincount(inverse, weights=damped.ravel()[keep], minlength=len(unique))
    row, other = np.divmod(unique, n)
    start = np.concatenate([[0], np.cumsum(np.bincount(row, minlength=n))])
    return start, other, stiffness, damping


def isometric_faces(cloth) -> tuple:
    """(stencil (F, 6), weights (F, 3, 6)): each triangle's bending stencil (bending_stencils)
    with w_i = sum_s weights[i, s] x_stencil[s] (the cotangent weights of the hinge across its
    edge i, isometric_matrix); a particle in two slots has its weights in the first and none in
    the second, so the slots' particles with weights are distinct (XPBD's per-triangle solve)."""
    stencil = bending_stencils(cloth)
    weights = np.zeros((cloth.face_count, 3, 6))
    present = cloth.face_hinge >= 0
    hinge = np.where(present, cloth.face_hinge, 0)
    cot = cotangent_weights(cloth.particle_position, cloth.hinge_indices)[hinge]   # (F, 3, 4)
    corners = cloth.hinge_indices[hinge]                                          # (F, 3, 4)
    for k in range(4):
        for s in range(6):
            weights[:, :, s] += np.where(present & (corners[:, :, k] == stencil[:, None, s])
                                         & _first_slot(stencil, s)[:, None], cot[:, :, k], 0.0)
    return stencil, weights


def _first_slot(stencil: np.ndarray, s: int) -> np.ndarray:
    """(F,) bool: slot s holds its particle's first appearance in the triangle's stencil."""
    return ~np.any(stencil[:, :s] == stencil[:, s:s + 1], axis=1)
