"""The stiffness of a body's springs as the stability analyses see it: per-particle Gershgorin
bounds and the stiffest mode of the springs linearised about rest (numpy, on the host). Each
integrator turns these into its own largest stable step (Integrator.stable_step)."""

from __future__ import annotations

import numpy as np

POWER_ITERATIONS = 100
POWER_TOLERANCE = 1e-6        # stop once the Rayleigh quotient grows by less than this, relative


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
    return omega2, np.where(pinned, 0.0, gamma + drag)


def stiffest_mode(cloth, drag: float = 0.0, pinned=None, iterations: int = POWER_ITERATIONS):
    """(w^2 [1/s^2], g [1/s]) of the stiffest mode of the springs linearised about rest.

    Power iteration on A = M^-1/2 K M^-1/2 (K_s = k n n^T per spring at rest, pins removed),
    started from a fixed random vector; w^2 is the Rayleigh quotient, which grows towards the
    largest eigenvalue from below (stopped after POWER_ITERATIONS or once it grows by less than
    POWER_TOLERANCE; within 1 % of a dense eigensolver on the tests' three bodies). g is the mode's damping rate: the
    Rayleigh quotient of M^-1/2 C M^-1/2 (C from kd, "axial" along n n^T, "relative" I) on
    the same vector, plus drag. (0, 0) if nothing is free or there are no springs.
    """
    pinned = cloth.pinned if pinned is None else pinned
    free = ~np.asarray(pinned, bool)
    if not free.any() or cloth.spring_count == 0:
        return 0.0, 0.0
    scale = np.where(free, 1.0 / np.sqrt(np.where(cloth.particle_mass > 0, cloth.particle_mass, 1.0)), 0.0)
    i, j = cloth.spring_indices.T
    d = cloth.particle_position[i] - cloth.particle_position[j]
    length = np.linalg.norm(d, axis=1)
    n = d / np.where(length > 0, length, 1.0)[:, None]
    n[length == 0] = 0.0    # zero-length springs: no direction at rest (linear k I handled as 0)
    relative = cloth.damping == "relative"

    count = cloth.particle_count

    def product(x, coefficient, isotropic=False):
        y = x * scale[:, None]
        diff = y[i] - y[j]
        f = coefficient[:, None] * (diff if isotropic else np.sum(diff * n, axis=1)[:, None] * n)
        out = np.stack([np.bincount(i, f[:, c], count) - np.bincount(j, f[:, c], count)
                        for c in range(3)], axis=1)
        return out * scale[:, None]

    x = np.random.default_rng(0).normal(size=(count, 3)) * free[:, None]
    omega2 = 0.0
    for _ in range(iterations):
        x /= np.linalg.norm(x)
        y = product(x, cloth.spring_stiffness)
        previous, omega2 = omega2, float(np.sum(x * y))
        if not np.any(y) or omega2 - previous <= POWER_TOLERANCE * omega2:
            break
        x = y
    x /= np.linalg.norm(x)
    gamma = float(np.sum(x * product(x, cloth.spring_damping, relative))) + drag
    return omega2, gamma
