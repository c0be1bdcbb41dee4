"""Largest stable step of the explicit integrators, from the stiffest mode of the cloth."""

from __future__ import annotations

import math

import numpy as np

from .integrators import make_integrator

RK4_IMAGINARY = 2.0 * math.sqrt(2.0)   # |1 + z + z^2/2 + z^3/6 + z^4/24| <= 1 on z = iy, |y| <= this
RK4_RADIUS = 2.61                      # a left half-disc of this radius lies in RK4's region (min 2.6156)


def stiffest_mode(cloth, drag: float = 0.0, pinned=None) -> tuple[np.ndarray, np.ndarray]:
    """Per-particle Gershgorin bounds (w^2 [1/s^2], damping rate g [1/s]) of the linearised
    spring system M^-1/2 K M^-1/2 about rest: row i sums k_s (1/m_i + 1/sqrt(m_i m_j)) over its
    springs (the off-diagonal term vanishes for a pinned j); the same with kd gives g, plus drag.
    Pinned particles get 0."""
    pinned = cloth.pinned if pinned is None else pinned
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


def stable_dt(cloth, integrator="symplectic_euler", drag: float = 0.0, pinned=None) -> float:
    """Largest stable step [s] predicted for `integrator` on `cloth` (inf: no limit; 0: no
    stable step exists, e.g. explicit Euler on undamped springs).

    Per mode of angular frequency w and damping rate g (linear analysis of the update matrix):
    explicit Euler h < g / w^2, tightened for an overdamped mode (g > 2w) to the smaller root
    (g - sqrt(g^2 - 4 w^2)) / w^2 so the update does not overshoot (g / w^2 is the midpoint of
    the two roots, so one expression covers both cases); symplectic Euler and Verlet
    h < (sqrt(g^2 + 4 w^2) - g) / w^2 (= 2 / w undamped); rk4 h |lambda| within its stability
    region: 2 sqrt(2) / w undamped (its reach up the imaginary axis), else RK4_RADIUS / |lambda|
    with |lambda| the mode's largest eigenvalue modulus; position-based integrators and
    implicit Euler have no limit. The Gershgorin bound overestimates w, so the prediction errs on the safe side.
    """
    integrator = make_integrator(integrator)
    if not integrator.step_limited:
        return math.inf
    omega2, gamma = stiffest_mode(cloth, drag, pinned)
    stiff = omega2 > 0
    if not stiff.any():
        return math.inf
    w2, g = omega2[stiff], gamma[stiff]
    if integrator.name == "explicit_euler":
        return float(np.min((g - np.sqrt(np.maximum(g * g - 4.0 * w2, 0.0))) / w2))
    if integrator.name == "rk4":
        largest = np.maximum(np.sqrt(w2), 0.5 * g + np.sqrt(np.maximum(0.25 * g * g - w2, 0.0)))
        reach = np.where(g > 0, RK4_RADIUS, RK4_IMAGINARY)
        return float(np.min(reach / largest))
    return float(np.min((np.sqrt(g * g + 4.0 * w2) - g) / w2))
