"""A Fabric's elements in implicit Euler's system (implicit_euler.py): their linearisation at
x_n and their share of the matrix-free product A p, A = M + h^2 H + h beta H_GN.

Membrane triangle f (physics/elements.membrane_forces; StVK on the Green strain E, S = C e):
its Hessian is exactly A (J^T C J + S (x) I) (Bonet & Wood eq. 7.13-7.15), J = de/dx with
de(u) = (warp . dwarp, weft . dweft, warp . dweft + weft . dwarp) for (dwarp, dweft) the
columns of dF = sum_c u_c (x) grad lambda_c; the Gauss-Newton part A J^T C J is positive
semi-definite; the geometric part S (x) I is not under compression, so S is projected onto its
non-negative eigenvalues (the projection of Teran et al. 2005 for this term; Choi & Ko 2002's
clamp for springs). Rayleigh damping adds h beta A J^T C J.

Bending (E = 1/2 dt^T B dt per triangle, body/elements.py): the Gauss-Newton Hessian
sum_ij B_ij grad t_i grad t_j^T, positive semi-definite (B is a Gram matrix); the moments'
term sum_i M_i Hess t_i is dropped as a spring's compressed lateral term is. Its product with
p takes two loops: every hinge's s = grad t . p, then every hinge's response
(sum over its two triangles of (h^2 + h beta) B_i. s) grad t.

Each element writes its response per corner, which particles gather in the Model's fixed order
(physics/elements.gather_corners): deterministic, no float atomics, as for forces. The
preconditioner takes the 3x3 diagonals of the membrane blocks exactly and of the bending
blocks without the cross terms between a triangle's hinges (still positive).
"""

import taichi as ti

from ..physics.elements import face_columns, gather_corners, isometric_sum, store_corners
from ..runtime import backend
from ..runtime.plan import Loop, Phase


def add_fields(ws, fields, face_count: int, hinge_count: int) -> None:
    """The linearisation and per-corner products of face_count triangles and hinge_count
    hinges, on the workspace ws (allocated with its FieldGroup)."""
    real = backend.real()
    faces, hinges = max(face_count, 1), max(hinge_count, 1)
    ws.face_warp = fields.vector(3, real, faces)        # F's columns at x_n
    ws.face_weft = fields.vector(3, real, faces)
    ws.face_stress = fields.vector(3, real, faces)      # projected S: s11, s22, s12
    ws.face_product = fields.vector(3, real, 3 * faces)
    ws.face_diagonal = fields.vector(3, real, 3 * faces)
    ws.hinge_gradient = fields.vector(3, real, 4 * hinges)
    ws.hinge_projection = fields.scalar(real, hinges)
    ws.hinge_product = fields.vector(3, real, 4 * hinges)
    ws.hinge_diagonal = fields.vector(3, real, 4 * hinges)


@ti.func
def _projected_stress(s11, s22, s12):
    """The 2x2 symmetric stress with its negative eigenvalues set to 0."""
    mean = 0.5 * (s11 + s22)
    half = 0.5 * (s11 - s22)
    radius = ti.sqrt(half * half + s12 * s12)
    high, low = mean + radius, mean - radius
    result = ti.Vector([s11, s22, s12])
    if high <= 0:
        result = ti.Vector([0.0, 0.0, 0.0])
    elif low < 0:       # high v v^T = high (S - low I) / (high - low)
        result = (high / (high - low)) * ti.Vector([s11 - low, s22 - low, s12])
    return result


@ti.func
def _face_product(model: ti.template(), ws: ti.template(), f, vectors: ti.template(),
                  stiff, geometric):
    """face_product[3 f + c] = (stiff A J^T C J + geometric A S (x) I) u on triangle f's corner
    c, u = vectors."""
    dwarp, dweft = face_columns(model, vectors, f)
    warp, weft, s = ws.face_warp[f], ws.face_weft[f], ws.face_stress[f]
    c = model.face_moduli[f]
    d11 = warp.dot(dwarp)
    d22 = weft.dot(dweft)
    ds11 = c[0] * d11 + c[1] * d22
    ds22 = c[1] * d11 + c[2] * d22
    ds12 = c[3] * (warp.dot(dweft) + weft.dot(dwarp))
    area = model.face_area[f]
    store_corners(model, ws.face_product, f,
                  area * (stiff * (ds11 * warp + ds12 * weft) + geometric * (s[0] * dwarp + s[2] * dweft)),
                  area * (stiff * (ds12 * warp + ds22 * weft) + geometric * (s[2] * dwarp + s[1] * dweft)))


@ti.func
def _corner_diagonal(warp, weft, s, c, g0, g1):
    """The diagonal of a corner's blocks (J^T C J, S (x) I) for grad lambda = (g0, g1)."""
    e11 = g0 * warp
    e22 = g1 * weft
    shear = g1 * warp + g0 * weft
    stiff = c[0] * e11 * e11 + 2.0 * c[1] * e11 * e22 + c[2] * e22 * e22 + c[3] * shear * shear
    return stiff, s[0] * g0 * g0 + 2.0 * s[2] * g0 * g1 + s[1] * g1 * g1


@ti.func
def linearise_face(model: ti.template(), state: ti.template(), forces: ti.template(),
                   ws: ti.template(), stages: ti.template(), f, now: ti.template()):
    """Triangle f at x_n: F's columns, the projected elastic stress, its stiffness times v_n
    (face_product, for the right-hand side) and the diagonal of its blocks of A."""
    warp, weft = face_columns(model, state.particle_position, f)
    c = model.face_moduli[f]
    e11 = 0.5 * (warp.dot(warp) - 1.0)
    e22 = 0.5 * (weft.dot(weft) - 1.0)
    s = _projected_stress(c[0] * e11 + c[1] * e22, c[1] * e11 + c[2] * e22,
                          c[3] * warp.dot(weft))
    if ti.static(forces.tearable):
        if state.face_alive[f] == 0:         # torn: no stiffness (F = 0 zeroes J and S)
            warp, weft = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
            s = ti.Vector([0.0, 0.0, 0.0])
    ws.face_warp[f] = warp
    ws.face_weft[f] = weft
    ws.face_stress[f] = s
    _face_product(model, ws, f, state.particle_velocity, 1.0, 1.0)
    h = now.dt
    stiff = h * h + h * model.face_damping[f]
    area = model.face_area[f]
    g = model.face_gradient[f]
    first_stiff, first_geometric = _corner_diagonal(warp, weft, s, c, g[0], g[1])
    second_stiff, second_geometric = _corner_diagonal(warp, weft, s, c, g[2], g[3])
    zero_stiff, zero_geometric = _corner_diagonal(warp, weft, s, c, -g[0] - g[2], -g[1] - g[3])
    ws.face_diagonal[3 * f] = area * (stiff * zero_stiff + h * h * zero_geometric)
    ws.face_diagonal[3 * f + 1] = area * (stiff * first_stiff + h * h * first_geometric)
    ws.face_diagonal[3 * f + 2] = area * (stiff * second_stiff + h * h * second_geometric)


@ti.func
def _project_hinge(model: ti.template(), ws: ti.template(), e, vectors: ti.template()):
    """hinge_projection[e] = grad t_e . vectors over the hinge's corners."""
    corner = model.hinge_indices[e]
    total = 0.0
    for k in ti.static(range(4)):
        total += ws.hinge_gradient[4 * e + k].dot(vectors[corner[k]])
    ws.hinge_projection[e] = total


@ti.func
def _bending_row(b, i):
    """Row i of a triangle's symmetric B stored as (00, 11, 22, 01, 02, 12)."""
    row = ti.Vector([b[4], b[5], b[2]])
    if i == 0:
        row = ti.Vector([b[0], b[3], b[4]])
    elif i == 1:
        row = ti.Vector([b[3], b[1], b[5]])
    return row


@ti.func
def _hinge_weight(model: ti.template(), f, i, dt, rhs: ti.template()):
    """(h^2 + h beta) B_ii of hinge i of triangle f, or B_ii for the right-hand side."""
    b = model.face_bending[f]
    weight = b[2]
    if i == 0:
        weight = b[0]
    elif i == 1:
        weight = b[1]
    if ti.static(not rhs):
        weight *= dt * dt + dt * model.face_damping[f]
    return weight


@ti.func
def linearise_hinge(model: ti.template(), state: ti.template(), forces: ti.template(),
                    ws: ti.template(), stages: ti.template(), e, now: ti.template()):
    """Hinge e at x_n (after hinge_angles left grad t in hinge_force, before hinge_forces):
    its gradient, grad t . v_n and the hinge-diagonal part of its blocks of A."""
    faces = model.hinge_faces[e]
    weight = (_hinge_weight(model, faces[0] // 3, faces[0] % 3, now.dt, False)
              + _hinge_weight(model, faces[1] // 3, faces[1] % 3, now.dt, False))
    for k in ti.static(range(4)):
        gradient = state.hinge_force[4 * e + k]
        ws.hinge_gradient[4 * e + k] = gradient
        ws.hinge_diagonal[4 * e + k] = weight * gradient * gradient
    _project_hinge(model, ws, e, state.particle_velocity)


@ti.func
def _hinge_product(model: ti.template(), ws: ti.template(), e, dt, rhs: ti.template()):
    """hinge_product[4 e + k] = sum over hinge e's triangles of (h^2 + h beta) (B s)_i
    grad_k t_e (B s without the factor for the right-hand side), s the projections."""
    faces = model.hinge_faces[e]
    moment = 0.0
    for side in ti.static(range(2)):
        f, i = faces[side] // 3, faces[side] % 3
        row = _bending_row(model.face_bending[f], i)
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
def bend_velocity(model: ti.template(), state: ti.template(), forces: ti.template(),
                  ws: ti.template(), stages: ti.template(), e, now: ti.template()):
    """hinge_product = the bending stiffness times v_n on hinge e's corners."""
    _hinge_product(model, ws, e, now.dt, True)


@ti.func
def stretch_direction(model: ti.template(), state: ti.template(), forces: ti.template(),
                      ws: ti.template(), stages: ti.template(), f, now: ti.template()):
    """face_product = triangle f's membrane block of A times p."""
    h = now.dt
    _face_product(model, ws, f, ws.p, h * h + h * model.face_damping[f], h * h)


@ti.func
def project_direction(model: ti.template(), state: ti.template(), forces: ti.template(),
                      ws: ti.template(), stages: ti.template(), e, now: ti.template()):
    _project_hinge(model, ws, e, ws.p)


@ti.func
def bend_direction(model: ti.template(), state: ti.template(), forces: ti.template(),
                   ws: ti.template(), stages: ti.template(), e, now: ti.template()):
    """hinge_product = hinge e's bending block of A times p."""
    _hinge_product(model, ws, e, now.dt, False)


@ti.func
def stiffness_times(model: ti.template(), ws: ti.template(), i):
    """Particle i's rows of the elements' products (stiffness times v_n after the
    linearisation, the blocks of A times p after product_phases); the isometric bending's
    (a constant Q) are isometric_velocity's and isometric_product's."""
    return gather_corners(model, ws.face_product, ws.hinge_product, i)


@ti.func
def isometric_velocity(model: ti.template(), state: ti.template(), i):
    """Particle i's row of Q v_n, the isometric bending's stiffness times v_n (its Hessian is
    the constant Q of body/elements.isometric_matrix, positive semi-definite as it is)."""
    return -isometric_sum(model, state.particle_velocity, state.particle_velocity, i, 1.0, 0.0)


@ti.func
def isometric_product(model: ti.template(), ws: ti.template(), i, dt):
    """Particle i's row of (h^2 + h beta) Q p, the isometric bending's block of A times p."""
    return -isometric_sum(model, ws.p, ws.p, i, dt * dt, dt)


@ti.func
def diagonal(model: ti.template(), ws: ti.template(), i, dt):
    """The elements' share of particle i's 3x3 diagonal of A (preconditioner); the isometric
    bending's Q_ii = sum of -Q_il over its neighbours (rows sum to 0), the same on each axis."""
    total = gather_corners(model, ws.face_diagonal, ws.hinge_diagonal, i)
    if ti.static(model.isometric):
        weight = 0.0
        for c in range(model.particle_bend_start[i], model.particle_bend_start[i + 1]):
            weight += dt * dt * model.bend_stiffness[c] + dt * model.bend_damping[c]
        total += weight * ti.Vector([1.0, 1.0, 1.0])
    return total


def linear_loops(model) -> tuple:
    """Loops of the first phase (beside the forces): every triangle's linearisation."""
    return (Loop(model.face_count, linearise_face),) if model.face_count else ()


def bending_loops(model) -> tuple:
    """(with the moments, with the hinge forces): physics/elements.bending_phases' extra
    loops that linearise every hinge and apply its stiffness to v_n."""
    if not model.hinge_count or model.isometric:
        return (), ()
    return (Loop(model.hinge_count, linearise_hinge),), (Loop(model.hinge_count, bend_velocity),)


def product_phases(model, first: tuple) -> tuple:
    """The phases before the particles gather A p: `first` (the caller's loops on p) with every
    triangle's product and every hinge's projection, then every hinge's product."""
    loops = first
    if model.face_count:
        loops += (Loop(model.face_count, stretch_direction),)
    hinges = model.hinge_count and not model.isometric
    if hinges:
        loops += (Loop(model.hinge_count, project_direction),)
    phases = (Phase(*loops),) if loops else ()
    if hinges:
        phases += (Phase(Loop(model.hinge_count, bend_direction)),)
    return phases
