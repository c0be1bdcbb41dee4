"""Largest stable step of the explicit integrators, from the stiffest mode of the cloth."""

from __future__ import annotations

import math

import numpy as np

from .integrators import make_integrator

RK4_IMAGINARY = 2.0 * math.sqrt(2.0)   # |1 + z + z^2/2 + z^3/6 + z^4/24| <= 1 on z = iy, |y| <= this
RK4_RADIUS = 2.61                      # a left half-disc of this radius lies in RK4's region (min 2.6156)
POWER_ITERATIONS = 100
POWER_TOLERANCE = 1e-6        # stop once the Rayleigh quotient grows by less than this, relative
AUTO_MAX_DT = 1.0 / 240.0     # "auto" steps: at most half the predicted stable step and at most this [s]


def _row_bounds(cloth, drag: float, pinned) -> tuple[np.ndarray, np.ndarray]:
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


def stable_dt(cloth, integrator="symplectic_euler", drag: float = 0.0, pinned=None) -> float:
    """Largest stable step [s] predicted for `integrator` on `cloth` (inf: no limit; 0: no
    stable step exists, e.g. explicit Euler on undamped springs).

    From the linear analysis of each update matrix on a mode of angular frequency w and damping
    rate g: symplectic Euler and Verlet h < (sqrt(g^2 + 4 w^2) - g) / w^2 (= 2 / w undamped);
    rk4 h |lambda| within its stability region: 2 sqrt(2) / w undamped (its reach up the
    imaginary axis), else RK4_RADIUS / |lambda| with |lambda| the mode's largest eigenvalue
    modulus; all three on the stiffest mode (stiffest_mode). Explicit Euler h < g / w^2 (the
    smaller root (g - sqrt(g^2 - 4 w^2)) / w^2 for an overdamped mode): its worst mode is the
    least damped relative to its stiffness, not the stiffest, so it takes the smallest ratio
    over per-particle Gershgorin bounds (conservative). Position-based integrators and
    implicit Euler have no limit.
    """
    integrator = make_integrator(integrator)
    if not integrator.step_limited:
        return math.inf
    pinned = cloth.pinned if pinned is None else np.asarray(pinned, bool)
    if integrator.name == "explicit_euler":
        omega2, gamma = _row_bounds(cloth, drag, pinned)
        stiff = omega2 > 0
        if not stiff.any():
            return math.inf
        w2, g = omega2[stiff], gamma[stiff]
        return float(np.min((g - np.sqrt(np.maximum(g * g - 4.0 * w2, 0.0))) / w2))
    w2, g = stiffest_mode(cloth, drag, pinned)
    if w2 <= 0:
        return math.inf
    if integrator.name == "rk4":
        largest = max(math.sqrt(w2), 0.5 * g + math.sqrt(max(0.25 * g * g - w2, 0.0)))
        return (RK4_RADIUS if g > 0 else RK4_IMAGINARY) / largest
    return (math.sqrt(g * g + 4.0 * w2) - g) / w2


def auto_dt(cloth, integrator="symplectic_euler", drag: float = 0.0, pinned=None) -> float:
    """The step dt="auto" picks [s]: min(stable_dt / 2, AUTO_MAX_DT). Raises ValueError when
    no stable step exists (explicit Euler on undamped springs)."""
    stable = stable_dt(cloth, integrator, drag, pinned)
    if stable == 0:
        raise ValueError(f"dt='auto': no stable step exists for {make_integrator(integrator).name} "
                         "with these springs (undamped springs make explicit Euler unstable at any "
                         "step); add spring damping (kd) or choose another integrator")
    return min(0.5 * stable, AUTO_MAX_DT)


def auto_substeps(cloth, integrator, frame_dt: float, drag: float = 0.0, pinned=None) -> int:
    """Steps per frame of substeps="auto": the fewest with dt = frame_dt / substeps <= auto_dt."""
    return max(1, math.ceil(frame_dt / auto_dt(cloth, integrator, drag, pinned) - 1e-9))
