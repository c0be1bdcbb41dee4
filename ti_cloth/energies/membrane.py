"""A Fabric's membrane: constant-strain triangles (linear FEM) with the plane-stress
orthotropic Saint Venant-Kirchhoff law. Each triangle has a rest material frame (warp, weft)
in its plane; F = sum_c x_c (x) grad(lambda_c) is the deformation gradient from that frame
(3 x 2, lambda_c the barycentric coordinates, their gradients constant on the rest triangle),
the Green strain is E = 1/2 (F^T F - I), and the energy A/2 e^T C e with e = (E11, E22, 2 E12)
and C = Fabric.membrane (Bonet & Wood, "Nonlinear continuum mechanics for finite element
analysis", 2008, eq. 6.11 and 7.13 with plane-stress orthotropy; Volino, Magnenat-Thalmann &
Faure, "A simple approach to nonlinear tensile stiffness for accurate cloth simulation", ACM
TOG 28(4), 2009, sec. 3). Everything each solver needs of it, together:

- rest data from the host mesh: each triangle's frame, area and barycentric gradients
  (material_frames); the energy in float64 (membrane_energy);
- force: -A (F S) grad lambda_c per corner with S = C (e + beta de/dt), beta the Rayleigh
  damping time (membrane_forces);
- Hessian: exactly A (J^T C J + S (x) I) (Bonet & Wood eq. 7.13-7.15), J = de/dx with
  de(u) = (warp . dwarp, weft . dweft, warp . dweft + weft . dwarp) for (dwarp, dweft) the
  columns of dF; the Gauss-Newton part A J^T C J is positive semi-definite, the geometric
  part S (x) I is not under compression, so S is projected onto its non-negative eigenvalues
  (Teran et al. 2005; projected_stress); Rayleigh damping adds h beta A J^T C J: implicit
  Euler's linearisation, product and 3x3 diagonal (linearise_face, face_product,
  corner_diagonal), and its blocks between sets of corners moved as one (face_block: a coarse
  level's, integrators/coarse.py);
- projection: XPBD on the strain e with compliance (A C)^-1 (xpbd_membrane; faces.py), each
  update optionally over-relaxed (XPBD(membrane_relaxation=omega): successive
  over-relaxation of the Gauss-Seidel passes, the same converged step).

A Fabric whose compression is kappa < 1 resists shortening along its warp or weft by kappa of
its stiffness in tension: a yarn buckles rather than push (Fabric.compression; Marvelous
Designer's buckling ratio, Vellum's compression stiffness). The energy is A/2 u^T C u + the
shear's, with u = (phi(E11), phi(E22)) and

    phi(E) = E (E >= 0),   phi(E) = r E + (1 - r) b (exp(E / b) - 1) (E < 0),

r = sqrt(kappa) and b = BUCKLING: the stiffness a warp or weft had in tension fades to kappa of
it over a few b of compressive strain (phi' goes from 1 to r), so the stress is continuous
(Poisson coupling included) and Newton meets no kink. The stress is S = D C (u + beta D de/dt)
with D = diag(phi'(E11), phi'(E22)); every Hessian above uses D C D for C (moduli), leaving
out phi''(E) (C u)_i, which is <= 0 in compression (the projection drops it); XPBD projects
the constraints phi(E). Shear (C33) is never scaled: a woven sheet's shear is its yarns
turning at their crossings, not a yarn pushed.
"""

import numpy as np
import taichi as ti

from ..runtime.plan import DT, ITEM, STATE, Loop, Sweep
from .faces import face_columns, face_intact, multiplier_step, store_corners

BUCKLING = 1e-3     # b: the compressive strain over which a softened warp or weft gives way
# the slot of XPBD's run-time settings (integrators/xpbd.py) holding its membrane_relaxation
XPBD_MEMBRANE_RELAXATION = 2


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


def give_way(strain: np.ndarray, root: np.ndarray) -> np.ndarray:
    """phi of the module doc, in float64: r E + (1 - r) b (exp(E / b) - 1) where E < 0."""
    short = np.minimum(strain, 0.0)
    return np.where(strain < 0, root * short + (1 - root) * BUCKLING * np.expm1(short / BUCKLING),
                    strain)


def membrane_energy(cloth, positions: np.ndarray, alive: np.ndarray | None = None) -> float:
    """sum over triangles (those `alive`, (F,) bool, when given: not torn) of A/2 u^T C u +
    A/2 C33 (2 E12)^2 [J] (module doc; u = e without softened compression)."""
    if not cloth.face_count:
        return 0.0
    e = green_strains(positions, cloth.face_indices, cloth.face_gradient)
    c11, c12, c22, c33 = cloth.face_moduli.T
    root = np.sqrt(cloth.face_compression)
    u1, u2 = give_way(e[:, 0], root), give_way(e[:, 1], root)
    density = 0.5 * (c11 * u1 ** 2 + 2 * c12 * u1 * u2 + c22 * u2 ** 2 + c33 * e[:, 2] ** 2)
    if alive is not None:
        density = density * alive
    return float(np.sum(cloth.face_area * density))


@ti.func
def gauge(model: ti.template(), f, warp, weft):
    """(phi(E11), phi'(E11), phi(E22), phi'(E22)) of triangle f where F's columns are (warp,
    weft) (module doc): (E11, 1, E22, 1) for a sheet that resists compression as tension."""
    e11 = 0.5 * (warp.dot(warp) - 1.0)
    e22 = 0.5 * (weft.dot(weft) - 1.0)
    result = ti.Vector([e11, 1.0, e22, 1.0])
    if ti.static(model.softened):
        root = ti.sqrt(model.face_compression[f])
        for k in ti.static(range(2)):
            strain = result[2 * k]
            if strain < 0:
                fade = ti.exp(strain / BUCKLING)
                result[2 * k] = root * strain + (1.0 - root) * BUCKLING * (fade - 1.0)
                result[2 * k + 1] = root + (1.0 - root) * fade
    return result


@ti.func
def gauged_moduli(c, g):
    """D C D (module doc) of (C11, C12, C22, C33) and a gauge's D."""
    return ti.Vector([g[1] * g[1] * c[0], g[1] * g[3] * c[1], g[3] * g[3] * c[2], c[3]])


@ti.func
def moduli(model: ti.template(), f, warp, weft):
    """Triangle f's moduli for the Hessian where F's columns are (warp, weft): D C D (module
    doc), Fabric.membrane's C for a sheet that resists compression as tension."""
    c = model.face_moduli[f]
    if ti.static(model.softened):
        c = gauged_moduli(c, gauge(model, f, warp, weft))
    return c


@ti.func
def membrane_forces(model: ti.template(), state: ti.template(), forces: ti.template(), f):
    """face_force[3 f + c] = force of triangle f's membrane on its corner c:
    -A (F S) grad lambda_c, S = C (e + beta de/dt) with e = (E11, E22, 2 E12) the Green strain
    in the warp/weft frame (module doc; Bonet & Wood eq. 6.11, 7.13) and beta the Rayleigh
    damping time; softened, S = D C (u + beta D de/dt) on the warp and weft (module doc)."""
    warp, weft = face_columns(model, state.particle_position, f)
    warp_rate, weft_rate = face_columns(model, state.particle_velocity, f)
    beta = model.face_damping[f]
    shear = warp.dot(weft) + beta * (warp.dot(weft_rate) + weft.dot(warp_rate))
    c = model.face_moduli[f]
    s11, s22 = 0.0, 0.0
    if ti.static(model.softened):
        g = gauge(model, f, warp, weft)
        u1 = g[0] + beta * g[1] * warp.dot(warp_rate)
        u2 = g[2] + beta * g[3] * weft.dot(weft_rate)
        s11 = g[1] * (c[0] * u1 + c[1] * u2)
        s22 = g[3] * (c[1] * u1 + c[2] * u2)
    else:
        e11 = 0.5 * (warp.dot(warp) - 1.0) + beta * warp.dot(warp_rate)
        e22 = 0.5 * (weft.dot(weft) - 1.0) + beta * weft.dot(weft_rate)
        s11 = c[0] * e11 + c[1] * e22
        s22 = c[1] * e11 + c[2] * e22
    s12 = c[3] * shear
    area = model.face_area[f]
    if ti.static(forces.tearable):
        if state.face_alive[f] == 0:         # torn: no membrane
            area = 0.0
    store_corners(model, state.face_force, f, -area * (s11 * warp + s12 * weft),   # -A (F S)
                  -area * (s12 * warp + s22 * weft))


def force_loops(model, forces) -> tuple:
    """The loop of the first force phase that evaluates every triangle's membrane
    (membrane_forces)."""
    if not model.face_count:
        return ()
    return (Loop(model.face_count, membrane_forces, model, STATE, forces, ITEM),)


@ti.func
def projected_stress(s11, s22, s12):
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
def face_product(model: ti.template(), ws: ti.template(), f, vectors: ti.template(),
                  stiff, geometric):
    """face_product[3 f + c] = (stiff A J^T C J + geometric A S (x) I) u on triangle f's corner
    c, u = vectors."""
    dwarp, dweft = face_columns(model, vectors, f)
    warp, weft, s = ws.face_warp[f], ws.face_weft[f], ws.face_stress[f]
    c = moduli(model, f, warp, weft)
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
def face_block(model: ti.template(), ws: ti.template(), f, alpha_i, beta_i, alpha_j, beta_j,
               stiff, geometric):
    """The 3x3 block of stiff A J^T C J + geometric A S (x) I (face_product's) coupling two
    sets of triangle f's corners that each move as one (a coarse level's aggregates:
    integrators/coarse.py): each set given by the sums of its corners' grad lambda components
    (alpha along the warp, beta along the weft: faces.corner_coefficients); the row set i,
    the column set j."""
    warp, weft, s = ws.face_warp[f], ws.face_weft[f], ws.face_stress[f]
    c = moduli(model, f, warp, weft)
    ww = c[0] * alpha_i * alpha_j + c[3] * beta_i * beta_j
    wf = c[1] * alpha_i * beta_j + c[3] * beta_i * alpha_j
    fw = c[3] * alpha_i * beta_j + c[1] * beta_i * alpha_j
    ff = c[3] * alpha_i * alpha_j + c[2] * beta_i * beta_j
    g = (s[0] * alpha_i * alpha_j + s[2] * (alpha_i * beta_j + beta_i * alpha_j)
         + s[1] * beta_i * beta_j)
    return model.face_area[f] * (
        stiff * (ww * warp.outer_product(warp) + wf * warp.outer_product(weft)
                 + fw * weft.outer_product(warp) + ff * weft.outer_product(weft))
        + geometric * g * ti.Matrix.identity(float, 3))


@ti.func
def corner_diagonal(warp, weft, s, c, g0, g1):
    """The diagonal of a corner's blocks (J^T C J, S (x) I) for grad lambda = (g0, g1)."""
    e11 = g0 * warp
    e22 = g1 * weft
    shear = g1 * warp + g0 * weft
    stiff = c[0] * e11 * e11 + 2.0 * c[1] * e11 * e22 + c[2] * e22 * e22 + c[3] * shear * shear
    return stiff, s[0] * g0 * g0 + 2.0 * s[2] * g0 * g1 + s[1] * g1 * g1


@ti.func
def linearise_face(model: ti.template(), state: ti.template(), forces: ti.template(),
                   ws: ti.template(), f, now: ti.template()):
    """Triangle f at x_n: F's columns, the projected elastic stress, its stiffness times v_n
    (face_product, for the right-hand side) and the diagonal of its blocks of A."""
    warp, weft = face_columns(model, state.particle_position, f)
    c = model.face_moduli[f]
    u = gauge(model, f, warp, weft)
    s = projected_stress(u[1] * (c[0] * u[0] + c[1] * u[2]), u[3] * (c[1] * u[0] + c[2] * u[2]),
                         c[3] * warp.dot(weft))
    if ti.static(model.softened):
        c = gauged_moduli(c, u)
    if ti.static(forces.tearable):
        if state.face_alive[f] == 0:         # torn: no stiffness (F = 0 zeroes J and S)
            warp, weft = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
            s = ti.Vector([0.0, 0.0, 0.0])
    ws.face_warp[f] = warp
    ws.face_weft[f] = weft
    ws.face_stress[f] = s
    face_product(model, ws, f, state.particle_velocity, 1.0, 1.0)
    h = now.dt
    stiff = h * h + h * model.face_damping[f]
    area = model.face_area[f]
    g = model.face_gradient[f]
    first_stiff, first_geometric = corner_diagonal(warp, weft, s, c, g[0], g[1])
    second_stiff, second_geometric = corner_diagonal(warp, weft, s, c, g[2], g[3])
    zero_stiff, zero_geometric = corner_diagonal(warp, weft, s, c, -g[0] - g[2], -g[1] - g[3])
    ws.face_diagonal[3 * f] = area * (stiff * zero_stiff + h * h * zero_geometric)
    ws.face_diagonal[3 * f + 1] = area * (stiff * first_stiff + h * h * first_geometric)
    ws.face_diagonal[3 * f + 2] = area * (stiff * second_stiff + h * h * second_geometric)


@ti.func
def moduli_matrix(c):
    """The 3x3 plane-stress matrix of a triangle's (C11, C12, C22, C33)."""
    return ti.Matrix([[c[0], c[1], 0.0], [c[1], c[2], 0.0], [0.0, 0.0, c[3]]])


@ti.func
def xpbd_membrane(model: ti.template(), state: ti.template(), f, multiplier: ti.template(), dt,
                  tearable: ti.template(), relaxation):
    """XPBD for triangle f's strain (softened: phi of its warp and weft strains, module doc),
    its multipliers in multiplier[f], the update scaled by `relaxation` (omega: 1 is
    Gauss-Seidel; SOR converges to the same step for 0 < omega < 2 on the linearised step,
    Ostrowski-Reich, and gets there in fewer passes). The strain's gradient
    on corner c with grad lambda_c = (g0, g1) has rows g0 F1, g1 F2, g1 F1 + g0 F2 (F1, F2
    F's columns), so J W J^T needs only sums of w_c g_c g_c^T. A torn triangle is no
    constraint."""
    if face_intact(state, f, tearable):
        membrane_constraint(model, state, f, multiplier, dt, relaxation)


@ti.func
def membrane_constraint(model: ti.template(), state: ti.template(), f, multiplier: ti.template(),
                        dt, relaxation):
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
    scale = ti.Vector([1.0, 1.0, 1.0])
    if ti.static(model.softened):         # the constraints phi(E): gradients D grad E
        g = gauge(model, f, warp, weft)
        scale = ti.Vector([g[1], g[3], 1.0])
        strain = ti.Vector([g[0], g[2], m])
        motion = scale * motion
        coupling = coupling * scale.outer_product(scale)
    gamma = model.face_damping[f] / dt
    stiffness = (dt * dt * model.face_area[f]) * moduli_matrix(model.face_moduli[f])
    step = relaxation * multiplier_step(stiffness, coupling, strain + gamma * motion,
                                        multiplier[f], gamma)
    multiplier[f] = multiplier[f] + step
    if ti.static(model.softened):
        step = scale * step
    along_warp = step[0] * warp + step[2] * weft
    along_weft = step[2] * warp + step[1] * weft
    for c in ti.static(range(3)):
        x = state.particle_position[corner[c]]
        w = model.particle_inv_mass[corner[c]]
        state.particle_position[corner[c]] = x + w * (along_warp * grads[c][0]
                                                      + along_weft * grads[c][1])


@ti.func
def clear_multipliers(work: ti.template(), f):
    work.membrane[f] = ti.Vector([0.0, 0.0, 0.0])


@ti.func
def xpbd_at(model: ti.template(), state: ti.template(), forces: ti.template(),
            work: ti.template(), t, dt):
    """XPBD for the triangle at position t of its colouring."""
    xpbd_membrane(model, state, work.membrane_colours.order[t], work.membrane, dt,
                  forces.tearable, ti.cast(work.settings[XPBD_MEMBRANE_RELAXATION], float))


def xpbd_nodes(model, forces, work) -> tuple:
    """(loops clearing the multipliers, sweeps) of XPBD over the triangles' strains
    (xpbd.py's workspace `work`), none for a model without them."""
    if not model.face_count:
        return (), ()
    return ((Loop(model.face_count, clear_multipliers, work, ITEM),),
            (Sweep(work.membrane_colours, xpbd_at, model, STATE, forces, work, ITEM,
                   DT).with_big_body(),))
