"""A Fabric's elements as XPBD constraints (Macklin, Mueller & Chentanez 2016), each a vector
of three: a triangle's Green strain e = (E11, E22, 2 E12) with compliance (A C)^-1, and its
three hinges' tangents dt = t - t_rest with compliance B^-1 (body/elements.py's energies
1/2 A e^T C e and 1/2 dt^T B dt are their elastic potentials). Converged, a step is the
backward Euler step of those energies except for the change of the constraints' gradients
within the step, which XPBD leaves out (Macklin et al. 2016, section 4): the rest state is
O(h) from the energies' (tests/test_fabric.py measures it).

For a constraint vector c with Jacobian J, stiffness K = alpha^-1 and the multipliers lambda,
XPBD's update (Macklin et al. 2016 eq. 18, with damping as their eq. 26) is
((1 + gamma) J W J^T + alpha~) dlambda = -c - alpha~ lambda - gamma J (x - x_n),
alpha~ = alpha / h^2; multiplied through by K~ = h^2 K it needs no inverse of K (B may be
near singular): ((1 + gamma) K~ J W J^T + I) dlambda = -K~ (c + gamma J (x - x_n)) - lambda,
a 3x3 solve per element. Rayleigh damping (damping matrix beta K) gives gamma = beta / h.
Then x += W J^T dlambda. A hinge missing from a triangle (a boundary edge) has c = 0 and no
gradient, so its row leaves the others' equations alone.

Triangles are visited colour by colour (Model.element_colourings: no two of a colour move a
common particle), a Gauss-Seidel sweep in a fixed order, deterministic.
"""

import taichi as ti

from .elements import face_columns, hinge_gradient, hinge_intact


@ti.func
def _moduli(c):
    """The 3x3 plane-stress matrix of a triangle's (C11, C12, C22, C33)."""
    return ti.Matrix([[c[0], c[1], 0.0], [c[1], c[2], 0.0], [0.0, 0.0, c[3]]])


@ti.func
def _multiplier_step(stiffness, coupling, residual, multiplier, gamma):
    """dlambda of ((1 + gamma) K~ JWJ + I) dlambda = -K~ residual - lambda."""
    system = (1.0 + gamma) * stiffness @ coupling + ti.Matrix.identity(float, 3)
    return system.inverse() @ (-(stiffness @ residual) - multiplier)


@ti.func
def xpbd_membrane(model: ti.template(), state: ti.template(), f, multiplier: ti.template(), dt,
                  tearable: ti.template()):
    """XPBD for triangle f's strain, its multipliers in multiplier[f]. The strain's gradient
    on corner c with grad lambda_c = (g0, g1) has rows g0 F1, g1 F2, g1 F1 + g0 F2 (F1, F2
    F's columns), so J W J^T needs only sums of w_c g_c g_c^T. A torn triangle is no
    constraint."""
    if _intact(state, f, tearable):
        _membrane(model, state, f, multiplier, dt)


@ti.func
def _intact(state: ti.template(), f, tearable: ti.template()):
    intact = True
    if ti.static(tearable):
        intact = state.face_alive[f] != 0
    return intact


@ti.func
def _membrane(model: ti.template(), state: ti.template(), f, multiplier: ti.template(), dt):
    corner = model.face_indices[f]
    g = model.face_gradient[f]
    warp, weft = face_columns(model, state.particle_position, f)
    dwarp, dweft = face_columns(model, state.particle_prev_position, f)
    dwarp, dweft = warp - dwarp, weft - dweft
    a, b, m = warp.dot(warp), weft.dot(weft), warp.dot(weft)
    grads = [ti.Vector([-g[0] - g[2], -g[1] - g[3]]), ti.Vector([g[0], g[1]]),
             ti.Vector([g[2], g[3]])]
    s00, s11, s01 = 0.0, 0.0, 0.0
    for c in ti.static(range(3)):
        w = model.particle_inv_mass[corner[c]]
        s00 += w * grads[c][0] * grads[c][0]
        s11 += w * grads[c][1] * grads[c][1]
        s01 += w * grads[c][0] * grads[c][1]
    coupling = ti.Matrix([[s00 * a, s01 * m, s01 * a + s00 * m],
                          [s01 * m, s11 * b, s11 * m + s01 * b],
                          [s01 * a + s00 * m, s11 * m + s01 * b, s11 * a + 2.0 * s01 * m + s00 * b]])
    strain = ti.Vector([0.5 * (a - 1.0), 0.5 * (b - 1.0), m])
    motion = ti.Vector([warp.dot(dwarp), weft.dot(dweft), warp.dot(dweft) + weft.dot(dwarp)])
    gamma = model.face_damping[f] / dt
    stiffness = (dt * dt * model.face_area[f]) * _moduli(model.face_moduli[f])
    step = _multiplier_step(stiffness, coupling, strain + gamma * motion, multiplier[f], gamma)
    multiplier[f] = multiplier[f] + step
    along_warp = step[0] * warp + step[2] * weft
    along_weft = step[2] * warp + step[1] * weft
    for c in ti.static(range(3)):
        x = state.particle_position[corner[c]]
        w = model.particle_inv_mass[corner[c]]
        state.particle_position[corner[c]] = x + w * (along_warp * grads[c][0]
                                                      + along_weft * grads[c][1])


@ti.func
def _hinge_on_face(model: ti.template(), positions: ti.template(), f, e):
    """Hinge e of triangle f: (t, grad t on f's corners 0, 1, 2, grad t on the hinge's other
    corner, that corner's particle)."""
    face = model.face_indices[f]
    corner = model.hinge_indices[e]
    t, ga, gb, gc, gd = hinge_gradient(model, positions, e)
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
def _moved(state: ti.template(), p):
    """x_p - x_p^n: particle p's motion in the step so far."""
    return state.particle_position[p] - state.particle_prev_position[p]


@ti.func
def _hinge_term(model: ti.template(), state: ti.template(), f, i: ti.template(),
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
    t, g0, g1, g2, other_grad, other = _hinge_on_face(model, state.particle_position, f, e)
    if other_grad.norm_sqr() == 0:      # no angle (physics/elements.hinge_angles)
        t = model.hinge_rest_tangent[e]
    g0, g1, g2, other_grad = valid * g0, valid * g1, valid * g2, valid * other_grad
    motion = (g0.dot(_moved(state, face[0])) + g1.dot(_moved(state, face[1]))
              + g2.dot(_moved(state, face[2])) + other_grad.dot(_moved(state, other)))
    return valid * (t - model.hinge_rest_tangent[e]), g0, g1, g2, other_grad, other, motion


@ti.func
def xpbd_bending(model: ti.template(), state: ti.template(), f, multiplier: ti.template(), dt,
                 tearable: ti.template()):
    """XPBD for triangle f's bending, its multipliers in multiplier[f]: the constraint is the
    tangents of the hinges across its three edges (0 and no gradient across a boundary or,
    tearing, beside a torn triangle)."""
    if _intact(state, f, tearable):
        _bending(model, state, f, multiplier, dt, tearable)


@ti.func
def _bending(model: ti.template(), state: ti.template(), f, multiplier: ti.template(), dt,
             tearable: ti.template()):
    face = model.face_indices[f]
    hinge = model.face_hinge[f]
    t0, g00, g10, g20, o0, p0, m0 = _hinge_term(model, state, f, 0, tearable)
    t1, g01, g11, g21, o1, p1, m1 = _hinge_term(model, state, f, 1, tearable)
    t2, g02, g12, g22, o2, p2, m2 = _hinge_term(model, state, f, 2, tearable)
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
    b = model.face_bending[f]                  # symmetric: 00, 11, 22, 01, 02, 12
    bending = ti.Matrix([[b[0], b[3], b[4]], [b[3], b[1], b[5]], [b[4], b[5], b[2]]])
    gamma = model.face_damping[f] / dt
    residual = ti.Vector([t0, t1, t2]) + gamma * ti.Vector([m0, m1, m2])
    step = _multiplier_step((dt * dt) * bending, coupling, residual, multiplier[f], gamma)
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


@ti.func
def xpbd_isometric(model: ti.template(), state: ti.template(), f, multiplier: ti.template(), dt):
    """XPBD for triangle f's isometric bending (a flat rest sheet: body/elements.isometric_matrix),
    its multipliers in multiplier[f] (3 x 3: a hinge's row, an axis's column): the constraint
    is w_i = sum_s J_is x_s over its stencil s (Model.face_stencil_weight), linear and the same
    on each axis, with compliance B'^-1. Its gradients do not change within the step, so,
    converged, this is the backward Euler step of the energy (what XPBD leaves out of the
    other elements is zero here)."""
    stencil = model.face_stencil[f]
    weight = model.face_stencil_weight[f]
    coupling = ti.Matrix.zero(float, 3, 3)
    value = ti.Matrix.zero(float, 3, 3)
    motion = ti.Matrix.zero(float, 3, 3)
    for s in ti.static(range(6)):
        p = stencil[s]
        w = model.particle_inv_mass[p]
        x = state.particle_position[p]
        moved = _moved(state, p)
        for i in ti.static(range(3)):
            for j in ti.static(range(3)):
                coupling[i, j] += w * weight[6 * i + s] * weight[6 * j + s]
            for a in ti.static(range(3)):
                value[i, a] += weight[6 * i + s] * x[a]
                motion[i, a] += weight[6 * i + s] * moved[a]
    b = model.face_isometric[f]                # symmetric: 00, 11, 22, 01, 02, 12
    bending = ti.Matrix([[b[0], b[3], b[4]], [b[3], b[1], b[5]], [b[4], b[5], b[2]]])
    gamma = model.face_damping[f] / dt
    m = multiplier[f]
    held = ti.Matrix([[m[0], m[1], m[2]], [m[3], m[4], m[5]], [m[6], m[7], m[8]]])
    step = _multiplier_step((dt * dt) * bending, coupling, value + gamma * motion, held, gamma)
    for i in ti.static(range(3)):
        for a in ti.static(range(3)):
            m[3 * i + a] += step[i, a]
    multiplier[f] = m
    for s in ti.static(range(6)):
        p = stencil[s]
        move = ti.Vector([0.0, 0.0, 0.0])
        for i in ti.static(range(3)):
            move += weight[6 * i + s] * ti.Vector([step[i, 0], step[i, 1], step[i, 2]])
        state.particle_position[p] = state.particle_position[p] + model.particle_inv_mass[p] * move
