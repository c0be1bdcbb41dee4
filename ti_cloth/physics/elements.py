"""A Fabric's elements as Taichi functions: membrane triangles and the mid-edge bending
operator (the model, its equations and sources: body/elements.py, whose float64 energies these
forces are the negative gradients of).

As for springs (forces.py), each element's forces are computed once per evaluation into a
force per corner, which every particle gathers in a fixed order (Model adjacency): no float
atomics, the same bits in every plan. Bending takes three loops: every hinge's angle (its
tangent t = tan(theta / 2), rate and gradient), every triangle's moments dE/dt_i, and every
hinge's corner forces -(M_1 + M_2) grad t from the moments of its two triangles. A flat sheet
(Model.isometric) bends by the isometric model instead: one loop in which every particle sums
its neighbours' rows of the constant Q (body/elements.isometric_matrix), no angle computed.
"""

import numpy as np
import taichi as ti

from ..body.elements import HALF_ANGLE_LIMIT
from ..runtime.plan import Loop, Phase


@ti.func
def face_columns(model: ti.template(), vectors: ti.template(), f):
    """The columns (warp, weft) of sum_c vectors[corner c] (x) grad lambda_c over triangle f's
    corners: the deformation gradient F when `vectors` are positions, its rate or its
    variation along a direction for velocities or directions."""
    corner = model.face_indices[f]
    g = model.face_gradient[f]                 # (grad lambda_1, grad lambda_2), x y each
    x0 = vectors[corner[0]]
    d1 = vectors[corner[1]] - x0
    d2 = vectors[corner[2]] - x0
    return d1 * g[0] + d2 * g[2], d1 * g[1] + d2 * g[3]


@ti.func
def store_corners(model: ti.template(), target: ti.template(), f, along_warp, along_weft):
    """target[3 f + c] = P grad lambda_c for triangle f's corners c, P the 3 x 2 matrix of
    columns (along_warp, along_weft) (grad lambda_0 = -grad lambda_1 - grad lambda_2)."""
    g = model.face_gradient[f]
    first = along_warp * g[0] + along_weft * g[1]
    second = along_warp * g[2] + along_weft * g[3]
    target[3 * f] = -(first + second)
    target[3 * f + 1] = first
    target[3 * f + 2] = second


@ti.func
def membrane_forces(model: ti.template(), state: ti.template(), forces: ti.template(),
                    work: ti.template(), stages: ti.template(), f, now: ti.template()):
    """face_force[3 f + c] = force of triangle f's membrane on its corner c:
    -A (F S) grad lambda_c, S = C (e + beta de/dt) with e = (E11, E22, 2 E12) the Green strain
    in the warp/weft frame (body/elements.py; Bonet & Wood eq. 6.11, 7.13) and beta the
    Rayleigh damping time."""
    warp, weft = face_columns(model, state.particle_position, f)
    warp_rate, weft_rate = face_columns(model, state.particle_velocity, f)
    beta = model.face_damping[f]
    e11 = 0.5 * (warp.dot(warp) - 1.0) + beta * warp.dot(warp_rate)
    e22 = 0.5 * (weft.dot(weft) - 1.0) + beta * weft.dot(weft_rate)
    shear = warp.dot(weft) + beta * (warp.dot(weft_rate) + weft.dot(warp_rate))
    c = model.face_moduli[f]
    s11 = c[0] * e11 + c[1] * e22
    s22 = c[1] * e11 + c[2] * e22
    s12 = c[3] * shear
    area = model.face_area[f]
    if ti.static(forces.tearable):
        if state.face_alive[f] == 0:         # torn: no membrane
            area = 0.0
    store_corners(model, state.face_force, f, -area * (s11 * warp + s12 * weft),   # -A (F S)
                  -area * (s12 * warp + s22 * weft))


@ti.func
def _tangent(sine, cosine, radius):
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
    2) continued (_tangent) of its dihedral angle; the angle and its gradient: body/elements.py
    (Tamstorf & Grinspun 2013, eq. 8), with the face normals left unnormalised (m1 = |m1| n1):
    theta's sine and cosine are (m1 x m2) . e / |e| and m1 . m2 over |m1| |m2| (three square
    roots and four divisions a hinge, no trigonometric call). A hinge with an edge or face of
    zero length or area has no angle: t and its gradient 0."""
    corner = model.hinge_indices[e]
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
        t, slope = _tangent(m1.cross(m2).dot(edge) * inverse, m1.dot(m2),
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
def hinge_angles(model: ti.template(), state: ti.template(), forces: ti.template(),
                 work: ti.template(), stages: ti.template(), e, now: ti.template()):
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
def face_moments(model: ti.template(), state: ti.template(), forces: ti.template(),
                 work: ti.template(), stages: ti.template(), f, now: ti.template()):
    """face_moment[3 f + i] = dE_f/dt_i = sum_j B_ij (dt_j + beta rate_j), the moment of
    triangle f's bending energy 1/2 dt^T B dt on the hinge across its edge i (0 across a
    boundary edge, which has no hinge)."""
    hinge = model.face_hinge[f]
    beta = model.face_damping[f]
    q = ti.Vector([0.0, 0.0, 0.0])
    for i in ti.static(range(3)):
        if hinge[i] >= 0:
            q[i] = state.hinge_tangent[hinge[i]] + beta * state.hinge_rate[hinge[i]]
    b = model.face_bending[f]                  # symmetric: 00, 11, 22, 01, 02, 12
    state.face_moment[3 * f] = b[0] * q[0] + b[3] * q[1] + b[4] * q[2]
    state.face_moment[3 * f + 1] = b[3] * q[0] + b[1] * q[1] + b[5] * q[2]
    state.face_moment[3 * f + 2] = b[4] * q[0] + b[5] * q[1] + b[2] * q[2]


@ti.func
def hinge_forces(model: ti.template(), state: ti.template(), forces: ti.template(),
                 work: ti.template(), stages: ti.template(), e, now: ti.template()):
    """hinge_force[4 e + k] = -(M_1 + M_2) grad_k t: the bending force of hinge e on its
    corner k, M the moments of its two triangles (face_moments)."""
    faces = model.hinge_faces[e]
    moment = state.face_moment[faces[0]] + state.face_moment[faces[1]]
    for k in ti.static(range(4)):
        state.hinge_force[4 * e + k] = -moment * state.hinge_force[4 * e + k]


@ti.func
def gather_corners(model: ti.template(), face_values: ti.template(),
                   hinge_values: ti.template(), i):
    """The sum of particle i's corner values of its triangles (face_values[3 f + c]) and its
    hinges (hinge_values[4 e + k]), in the Model's fixed order."""
    total = ti.Vector([0.0, 0.0, 0.0])
    for a in range(model.particle_face_start[i], model.particle_face_start[i + 1]):
        total += face_values[model.adjacency_face[a]]
    if ti.static(model.hinge_count > 0 and not model.isometric):
        for a in range(model.particle_hinge_start[i], model.particle_hinge_start[i + 1]):
            total += hinge_values[model.adjacency_hinge[a]]
    return total


@ti.func
def isometric_sum(model: ti.template(), first: ti.template(), second: ti.template(), i,
                  a, b):
    """sum_l (a k_il (first_l - first_i) + b d_il (second_l - second_i)) over particle i's
    neighbours l in increasing order, k = -Q and d = -beta Q the isometric bending's
    stiffness and damping (body/elements.isometric_matrix): a = b = 1 on positions and
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
def isometric_forces(model: ti.template(), state: ti.template(), forces: ti.template(),
                     work: ti.template(), stages: ti.template(), i, now: ti.template()):
    """particle_bend_force[i] = the isometric bending force on particle i (with the membranes,
    before any particle moves: it reads its neighbours' positions and velocities)."""
    state.particle_bend_force[i] = isometric_sum(model, state.particle_position,
                                                 state.particle_velocity, i, 1.0, 1.0)


@ti.func
def gather_elements(model: ti.template(), state: ti.template(), i):
    """The force of particle i's triangles and hinges (a body with triangles: gather_force
    calls it only then)."""
    total = gather_corners(model, state.face_force, state.hinge_force, i)
    if ti.static(model.isometric):
        total += state.particle_bend_force[i]
    return total


def element_loops(model) -> tuple:
    """The loops of the first force phase: every membrane triangle and every hinge's angle, or
    (isometric) every particle's bending force."""
    loops = ()
    if model.face_count:
        loops += (Loop(model.face_count, membrane_forces),)
    if model.isometric:
        loops += (Loop(model.particle_count, isometric_forces),)
    elif model.hinge_count:
        loops += (Loop(model.hinge_count, hinge_angles),)
    return loops


def bending_phases(model, with_moments: tuple = (), with_forces: tuple = ()) -> tuple:
    """The phases after the first: the triangles' moments, then the hinges' forces (each with
    the caller's loops that read the same inputs: with_moments read the hinges' angles and
    gradients, with_forces everything the moments' phase wrote)."""
    if not model.hinge_count or model.isometric:
        return ()
    return (Phase(Loop(model.face_count, face_moments), *with_moments),
            Phase(Loop(model.hinge_count, hinge_forces), *with_forces))
