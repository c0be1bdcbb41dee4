"""What a Fabric's triangle terms share (membrane.py, bending.py, isometric.py): a triangle's
deformation gradient from its rest material frame, its per-corner slots and every particle's
gather of them in the Model's fixed order (no float atomics: the same bits in every plan),
and XPBD's update of a vector constraint.

XPBD (Macklin, Mueller & Chentanez 2016) for a constraint vector c of three with Jacobian J,
stiffness K = alpha^-1 and multipliers lambda (their eq. 18, damping as their eq. 26):
((1 + gamma) J W J^T + alpha~) dlambda = -c - alpha~ lambda - gamma J (x - x_n),
alpha~ = alpha / h^2; multiplied through by K~ = h^2 K it needs no inverse of K (B may be near
singular): ((1 + gamma) K~ J W J^T + I) dlambda = -K~ (c + gamma J (x - x_n)) - lambda, a 3x3
solve per element (multiplier_step). Rayleigh damping (damping matrix beta K) gives
gamma = beta / h. Then x += W J^T dlambda. Converged, a step is the backward Euler step of the
energies except for the change of the constraints' gradients within the step, which XPBD
leaves out (Macklin et al. 2016, section 4): the rest state is O(h) from the energies'
(tests/test_fabric.py measures it). Triangles are visited colour by colour
(Model.element_colourings: no two of a colour move a common particle), a Gauss-Seidel sweep in
a fixed order, deterministic.

A triangle's bending (bending.py, isometric.py) is swept only in the passes it needs
(passes_needed): with a = tr((1 + gamma) K~ JWJ) its stiffness ratio at the step, a pass leaves
it about a / (1 + a) of what its neighbours' moves change, and a bending compliant against the
step (a denim's at 1/240 s: a below 1) is settled in 2-5 passes, 3 in the median, where the
membrane needs all of them. Each triangle counts its own passes (its slots in XPBD's
workspace: no sums, the same bits in every plan).
"""

import taichi as ti

# the slot of XPBD's run-time settings (integrators/xpbd.py) holding its bending_tolerance
XPBD_BENDING_TOLERANCE = 1
EVERY_PASS = 1 << 30      # passes_needed where the tolerance is 0 or a pass settles nothing


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
def corner_coefficients(model: ti.template(), f):
    """(alpha, beta): grad lambda_c's components (warp, weft) for triangle f's corners c, the
    coefficients of x_c in F's columns (face_columns) and of a corner's share (store_corners)."""
    g = model.face_gradient[f]
    return (ti.Vector([-g[0] - g[2], g[0], g[2]]), ti.Vector([-g[1] - g[3], g[1], g[3]]))


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
def gather(model: ti.template(), state: ti.template(), i, f):
    """f with the forces of particle i's triangles and hinges (the membrane's and the mid-edge
    bending's corner slots, then the isometric bending's per-particle force), compiled only
    for a body with triangles."""
    if ti.static(model.face_count > 0):
        total = gather_corners(model, state.face_force, state.hinge_force, i)
        if ti.static(model.isometric):
            total += state.particle_bend_force[i]
        f += total
    return f


@ti.func
def element_products(model: ti.template(), ws: ti.template(), i):
    """Particle i's rows of the elements' products (stiffness times v_n after the
    linearisation, the blocks of A times p after product_phases); the isometric bending's
    (a constant Q) are isometric.py's."""
    return gather_corners(model, ws.face_product, ws.hinge_product, i)


@ti.func
def element_diagonal(model: ti.template(), ws: ti.template(), i, dt):
    """The elements' share of particle i's 3x3 diagonal of A (preconditioner); the isometric
    bending's Q_ii = sum of -Q_il over its neighbours (rows sum to 0), the same on each axis."""
    total = gather_corners(model, ws.face_diagonal, ws.hinge_diagonal, i)
    if ti.static(model.isometric):
        weight = 0.0
        for c in range(model.particle_bend_start[i], model.particle_bend_start[i + 1]):
            weight += dt * dt * model.bend_stiffness[c] + dt * model.bend_damping[c]
        total += weight * ti.Vector([1.0, 1.0, 1.0])
    return total


@ti.func
def implicit_start(model: ti.template(), state: ti.template(), forces: ti.template(),
                   ws: ti.template(), i, dt, kv, diagonal):
    """(kv, diagonal) with particle i's rows of the triangle terms' stiffness times v_n and
    their share of A's 3x3 diagonal (a body with triangles; implicit Euler)."""
    if ti.static(model.face_count > 0):
        kv += element_products(model, ws, i)
        diagonal += element_diagonal(model, ws, i, dt)
    return kv, diagonal


@ti.func
def implicit_product(model: ti.template(), ws: ti.template(), i, dt, ap):
    """ap with particle i's rows of the triangle terms' blocks times the direction."""
    if ti.static(model.face_count > 0):
        ap += element_products(model, ws, i)
    return ap


@ti.func
def multiplier_step(stiffness, coupling, residual, multiplier, gamma):
    """dlambda of ((1 + gamma) K~ JWJ + I) dlambda = -K~ residual - lambda."""
    system = (1.0 + gamma) * stiffness @ coupling + ti.Matrix.identity(float, 3)
    return system.inverse() @ (-(stiffness @ residual) - multiplier)


@ti.func
def stiffness_ratio(stiffness, coupling, gamma):
    """a = tr((1 + gamma) K~ JWJ): an upper bound of the largest eigenvalue of what the
    update weighs against I (K~ and JWJ are positive semi-definite), 0 for no stiffness."""
    ratio = 0.0
    for i in ti.static(range(3)):
        for j in ti.static(range(3)):
            ratio += stiffness[i, j] * coupling[j, i]
    return (1.0 + gamma) * ratio


@ti.func
def passes_needed(ratio, tolerance):
    """The passes after which a bending of stiffness ratio a (stiffness_ratio) has at most
    `tolerance` of its residual left, taking a pass to leave r = a / (1 + a) of it: the
    smallest k with r^k <= tolerance, at least 1. Where the tolerance is 0, or r rounds to 1,
    every pass (EVERY_PASS). What the membrane's later passes change in a triangle's bending
    is taken in the next step's passes."""
    r = ratio / (1.0 + ratio)
    needed = EVERY_PASS
    if tolerance > 0.0 and r < 1.0:
        needed = 1
        if r > tolerance:      # clamped before the cast: r within 1e-16 of 1 asks ~1e16
            passes = ti.min(ti.ceil(ti.log(tolerance) / ti.log(r)), float(EVERY_PASS))
            needed = ti.cast(passes, ti.i32)
    return needed


@ti.func
def clear_passes(work: ti.template(), f):
    """No pass of triangle f's bending yet this step (it is swept in the first)."""
    work.bending_swept[f] = 0
    work.bending_needed[f] = 1


@ti.func
def needs_pass(work: ti.template(), f):
    """Whether triangle f's bending has had fewer passes than it needs."""
    return work.bending_swept[f] < work.bending_needed[f]


@ti.func
def count_pass(work: ti.template(), f, ratio):
    """One more pass of triangle f's bending, whose stiffness ratio was `ratio`; after its
    first, the passes it needs at the tolerance in XPBD's settings (taken once a step: its
    two logarithms in every pass made a step that skipped nothing up to 1.2x dearer)."""
    if work.bending_swept[f] == 0:
        tolerance = ti.cast(work.settings[XPBD_BENDING_TOLERANCE], float)
        work.bending_needed[f] = passes_needed(ratio, tolerance)
    work.bending_swept[f] = work.bending_swept[f] + 1


@ti.func
def face_intact(state: ti.template(), f, tearable: ti.template()):
    intact = True
    if ti.static(tearable):
        intact = state.face_alive[f] != 0
    return intact


@ti.func
def motion_in_step(state: ti.template(), p):
    """x_p - x_p^n: particle p's motion in the step so far."""
    return state.particle_position[p] - state.particle_prev_position[p]
