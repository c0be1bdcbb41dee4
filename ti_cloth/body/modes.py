"""The stiffness of a body's springs as the stability analyses see it: per-particle Gershgorin
bounds and the stiffest mode of the springs linearised about rest (numpy, on the host). Each
integrator turns these into its own largest stable step (Integrator.stable_step).

An altitude spring (Selle et al. 2008) linearised about rest is k G G^T with G = g (x) n, its
altitude's gradient over its four corners (energies/altitude.py altitude_frames): at rest
h = h0, so the curvature term k (h - h0) d^2h/dx^2 vanishes and this is exact there. A
Fabric's elements are sums of such rank-one terms at rest too (rest_rank_one); all of them
enter as rank_one_groups.
"""

from __future__ import annotations

import numpy as np

from ..energies.altitude import altitude_frames
from ..energies.bending import HALF_ANGLE_LIMIT, bending_matrices, dihedral_angles
from ..energies.isometric import is_flat, isometric_parts
from ..energies.membrane import deformation_gradients

LANCZOS_STEPS = 100
LANCZOS_TOLERANCE = 1e-7      # stop once the largest Ritz value grew by less than this, relative,
LANCZOS_WINDOW = 10           # over this many steps (it can stall near a close second eigenvalue)


def row_bounds(cloth, drag: float, pinned) -> tuple[np.ndarray, np.ndarray]:
    """Per-particle Gershgorin bounds (w^2 [1/s^2], damping rate g [1/s]) of the linearised
    spring system M^-1/2 K M^-1/2 about rest: row i sums k_s (1/m_i + 1/sqrt(m_i m_j)) over its
    springs (the off-diagonal term vanishes for a pinned j); the same with kd gives g, plus drag.
    Pinned particles get 0."""
    m = cloth.particle_mass
    inv = np.where(pinned, 0.0, 1.0 / np.where(m > 0, m, 1.0))
    i, j = cloth.spring_indices.T
    cross = np.sqrt(inv[i] * inv[j])
    omega2 = np.zeros(len(m))
    gamma = np.zeros(len(m))
    for a, b in ((i, j), (j, i)):
        np.add.at(omega2, a, cloth.spring_stiffness * (inv[a] + cross))
        np.add.at(gamma, a, cloth.spring_damping * (inv[a] + cross))
    for indices, stiff, damp in rank_one_groups(cloth):
        # Row of slot c of g g^T, scaled: |g_c| sqrt(inv_c) sum_l |g_l| sqrt(inv_l) (a bound:
        # slots of one particle add their vectors, whose norm is at most the sum of theirs).
        for vectors, out in ((stiff, omega2), (damp, gamma)):
            weight = np.linalg.norm(vectors, axis=2) * np.sqrt(inv[indices])
            total = weight.sum(axis=1)
            for corner in range(indices.shape[1]):
                np.add.at(out, indices[:, corner], weight[:, corner] * total)
    return omega2, np.where(pinned, 0.0, gamma + drag)


def rank_one_groups(cloth) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The body's multi-particle terms linearised about rest as rank-one g g^T, in groups of
    (indices (R, k), stiffness vectors (R, k, 3), damping vectors (R, k, 3)): altitude springs
    (g = sqrt(k) g_c n, damping sqrt(kd) g_c n) and a Fabric's elements
    (rest_rank_one)."""
    groups = []
    if cloth.altitude_count:
        n, _, g = altitude_frames(cloth.rest_position, cloth.altitude_indices)
        vectors = g[:, :, None] * n[:, None, :]
        groups.append((cloth.altitude_indices,
                       np.sqrt(cloth.altitude_stiffness)[:, None, None] * vectors,
                       np.sqrt(cloth.altitude_damping)[:, None, None] * vectors))
    return groups + rest_rank_one(cloth)


def stiffest_mode(cloth, drag: float = 0.0, pinned=None, steps: int = LANCZOS_STEPS):
    """(w^2 [1/s^2], g [1/s]): the largest angular frequency^2 and damping rate of the
    springs linearised about rest.

    Lanczos on A = M^-1/2 K M^-1/2 (K_s = k n n^T per spring at rest, and the rank-one terms
    of rank_one_groups: k G G^T per altitude spring, a Fabric's elements; pins removed), started
    from a fixed random vector: w^2 is the largest Ritz value, which grows towards the largest
    eigenvalue from below (stopped after `steps` or once it grew by less than
    LANCZOS_TOLERANCE in LANCZOS_WINDOW steps). Within 1e-6 of a dense eigensolver on the
    tests' bodies, where the 100 power iterations used before stopped up to 1.6e-3 short
    (and faster than they were: docs/performance.md).

    g is the largest damping rate of any mode: the largest eigenvalue of M^-1/2 C M^-1/2 (C
    from kd, "axial" along n n^T, "relative" I), by Lanczos too, plus drag. The pair is
    conservative: a light particle on damped springs (a hair's ghost) can have a mode far more
    damped than the stiffest one, and explicit damping is unstable once h g > 2 whatever w is
    (the stiffest mode's own damping rate missed that: symplectic Euler diverged at half its
    predicted step). (0, 0) if nothing is free or there are no springs.
    """
    pinned = cloth.pinned if pinned is None else pinned
    free = ~np.asarray(pinned, bool)
    if not free.any() or cloth.spring_count + cloth.altitude_count + cloth.face_count == 0:
        return 0.0, 0.0
    scale = np.where(free, 1.0 / np.sqrt(np.where(cloth.particle_mass > 0, cloth.particle_mass, 1.0)), 0.0)
    i, j = cloth.spring_indices.T
    d = cloth.rest_position[i] - cloth.rest_position[j]
    length = np.linalg.norm(d, axis=1)
    n = d / np.where(length > 0, length, 1.0)[:, None]
    n[length == 0] = 0.0    # zero-length springs: no direction at rest (linear k I handled as 0)
    # Component-major (3, S) and (3, N) arrays: 1-D gathers and bincounts over contiguous
    # rows run faster than over the columns of (S, 3) ones (docs/performance.md).
    n_i, n_j = n.T * scale[i], n.T * scale[j]        # M^-1/2 folded into n
    # (k, R) corner indices and (k, 3, R) vectors with M^-1/2 folded in, per group
    groups = [(indices.T, [np.moveaxis(v * scale[indices][:, :, None], 0, -1) for v in (stiff, damp)])
              for indices, stiff, damp in rank_one_groups(cloth)]
    relative = cloth.damping == "relative"
    count = cloth.particle_count

    def product(x, coefficient, which, isotropic=False):
        """M^-1/2 K M^-1/2 x, x of shape (3, N), for K of `coefficient` n n^T per spring
        (isotropic: coefficient I) and g g^T of each rank-one term, g its stiffness vectors
        (which = 0) or damping vectors (1)."""
        if isotropic:
            f = [coefficient * (scale[i] * x[c][i] - scale[j] * x[c][j]) for c in range(3)]
            out = np.stack([np.bincount(i, scale[i] * f[c], count)
                            - np.bincount(j, scale[j] * f[c], count)
                            for c in range(3)]).astype(np.float64)
        else:
            t = coefficient * sum(n_i[c] * x[c][i] - n_j[c] * x[c][j] for c in range(3))
            out = np.stack([np.bincount(i, t * n_i[c], count) - np.bincount(j, t * n_j[c], count)
                            for c in range(3)]).astype(np.float64)   # (int without springs)
        for corners, vectors in groups:
            g = vectors[which]
            t = sum(g[k, c] * x[c][corners[k]] for k in range(len(corners)) for c in range(3))
            out += np.stack([sum(np.bincount(corners[k], t * g[k, c], count)
                                 for k in range(len(corners))) for c in range(3)])
        return out

    start = (np.random.default_rng(0).normal(size=(count, 3)) * free[:, None]).T.copy()
    omega2 = largest_ritz(lambda x: product(x, cloth.spring_stiffness, 0), start, steps)
    gamma = largest_ritz(lambda x: product(x, cloth.spring_damping, 1, relative), start, steps)
    return omega2, gamma + drag


def largest_ritz(apply, start: np.ndarray, steps: int) -> float:
    """The largest Ritz value of the symmetric operator `apply` after at most `steps` Lanczos
    steps from `start` (Golub & Van Loan 10.1). No reorthogonalisation: lost orthogonality
    only repeats converged Ritz values."""
    alpha, beta, history = [], [], []
    for a, b in lanczos(apply, start, steps):
        alpha.append(a)
        value = float(np.linalg.eigvalsh(tridiagonal(alpha, beta))[-1])
        history.append(value)
        stalled = (len(history) > LANCZOS_WINDOW
                   and value - history[-1 - LANCZOS_WINDOW] <= LANCZOS_TOLERANCE * value)
        if b <= 1e-12 * abs(value) or stalled:
            break
        beta.append(b)
    return value


def lanczos(apply, start: np.ndarray, steps: int):
    """Yields (alpha_k, beta_k) of the three-term Lanczos recurrence, k < steps: stops early
    when beta_k = 0 (an invariant subspace)."""
    previous, q, b = np.zeros_like(start), start / np.linalg.norm(start), 0.0
    for _ in range(steps):
        w = apply(q) - b * previous
        a = float(np.vdot(q, w))
        w -= a * q
        b = float(np.linalg.norm(w))
        yield a, b
        if b == 0.0:
            return
        previous, q = q, w / b


def tridiagonal(alpha: list, beta: list) -> np.ndarray:
    """The symmetric tridiagonal matrix of diagonal alpha and off-diagonal beta."""
    return np.diag(alpha) + np.diag(beta[:len(alpha) - 1], 1) + np.diag(beta[:len(alpha) - 1], -1)


def stiffest_bending(cloth) -> np.ndarray:
    """(F, 3, 3): face_bending, where a triangle has a BendingCurve with the rigidities of its
    stiffest tangents (BendingCurve.stiffest): the largest its Hessian can be."""
    if not cloth.curved:
        return cloth.face_bending
    stiffest = np.array([c.stiffest for c in cloth.bending_curves] + [np.zeros(3)])
    peak = bending_matrices(cloth.face_components, cloth.face_area, stiffest[cloth.face_curve])
    return np.where((cloth.face_curve >= 0)[:, None, None], peak, cloth.face_bending)


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
    an upper bound for either model). A triangle whose rigidity depends on curvature enters
    with B at each direction's stiffest tangent (stiffest_bending). Rayleigh damping is beta
    times the same: its vectors are sqrt(beta) g."""
    if not cloth.face_count:
        return []
    x = cloth.rest_position
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
    if cloth.hinge_count and is_flat(cloth) and not cloth.curved:
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
        theta, grad = dihedral_angles(x, cloth.hinge_indices, gradient=True)
        half = 0.5 * theta
        slope = np.where(np.abs(half) > HALF_ANGLE_LIMIT, 0.5 / np.cos(HALF_ANGLE_LIMIT) ** 2,
                         0.5 / np.cos(half) ** 2)
        hinge_vectors = np.concatenate([slope[:, None, None] * grad, np.zeros((1, 4, 3))])
        hinge_corners = np.concatenate([cloth.hinge_indices, np.zeros((1, 4), np.int64)])
        per_face = hinge_vectors[cloth.face_hinge]                      # (T, 3 hinges, 4, 3)
        values, vectors = np.linalg.eigh(stiffest_bending(cloth))
        weights = vectors * np.sqrt(np.maximum(values, 0.0))[:, None, :]   # V sqrt(lambda)
        bending = np.einsum("tim,tikx->tmikx", weights, per_face).reshape(-1, 3, 12, 3)
        corners = np.repeat(hinge_corners[cloth.face_hinge].reshape(-1, 12), 3, axis=0)
        bending = bending.reshape(-1, 12, 3)
        groups.append((corners, bending, np.repeat(beta, 3)[:, None, None] * bending))
    return groups
