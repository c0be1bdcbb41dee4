"""Forces as Taichi kernels (gravity, Hookean springs, spring damping, air drag) and the
energies they derive from, evaluated on the host in float64.

Every particle gathers the forces of its own springs in a fixed order (Model adjacency), so
accumulation is deterministic and needs no float atomics. The spring force on i is computed
from i's side; j's loop computes the exact negation, so Newton's third law holds to rounding.
"""


from dataclasses import dataclass

import numpy as np
import taichi as ti

from .material import SpringKind
from .wind import accumulate_wind


@dataclass(frozen=True)
class ForceSettings:
    """External loads and switches of one simulation.

    gravity: acceleration [m/s^2], any direction.
    drag: uniform air drag [1/s]: f_i = -drag * m_i * v_i (mass-proportional, so the same
        deceleration everywhere and independent of resolution). 0 compiles it out.
    tearing: springs carry an alive flag that force loops must test (compile-time switch).
    wind: a wind.WindField (per-triangle aerodynamics) or None (its kernel is never compiled).
    """

    gravity: tuple[float, float, float] = (0.0, -9.81, 0.0)
    drag: float = 0.0
    tearing: bool = False
    wind: object = None


@ti.func
def spring_force(xi, xj, vi, vj, rest, k, kd, relative: ti.template()):
    """Force of one spring on particle i (the force on j is its negation).

    Elastic part: Stuyck eq. 4.5, f_i = -k (|x_ij| - L) x_ij / |x_ij|.
    Damping: relative = Stuyck eq. 4.7, -kd (v_i - v_j); axial = -kd ((v_i - v_j) . n) n.
    A spring of zero current length has no direction: its elastic and axial parts are zero.
    """
    xij = xi - xj
    vij = vi - vj
    length = xij.norm()
    f = ti.Vector([0.0, 0.0, 0.0])
    if length > 0:
        n = xij / length
        c = length - rest
        f = -k * c * n
        if ti.static(not relative):
            f -= kd * vij.dot(n) * n
    if ti.static(relative):
        f -= kd * vij
    return f


@ti.kernel
def accumulate_forces(model: ti.template(), state: ti.template(), gravity: ti.math.vec3,
                      drag: float, has_drag: ti.template(), springs: ti.template(),
                      tearing: ti.template()):
    """particle_force = m g (Stuyck eq. 4.3) - drag m v + sum of spring forces (eq. 4.5, 4.7).

    Compile-time switches: has_drag, springs (False for position-based prediction), tearing.
    """
    for i in range(model.particle_count):
        xi = state.particle_position[i]
        vi = state.particle_velocity[i]
        f = model.particle_mass[i] * gravity
        if ti.static(has_drag):
            f -= drag * model.particle_mass[i] * vi
        if ti.static(springs):
            for a in range(model.particle_spring_start[i], model.particle_spring_start[i + 1]):
                s = model.adjacency_spring[a]
                j = model.adjacency_other[a]
                alive = True
                if ti.static(tearing):
                    alive = state.spring_alive[s] != 0
                if alive:
                    f += spring_force(xi, state.particle_position[j], vi, state.particle_velocity[j],
                                      model.spring_rest_length[s], model.spring_stiffness[s],
                                      model.spring_damping[s], model.relative_damping)
        state.particle_force[i] = f


def compute_forces(model, state, forces: ForceSettings, springs: bool = True) -> None:
    """Launch accumulate_forces with the scene's switches, then the wind kernel if any."""
    accumulate_forces(model, state, ti.math.vec3(*forces.gravity), forces.drag, forces.drag > 0,
                      springs and model.spring_count > 0, forces.tearing)
    if forces.wind is not None:
        accumulate_wind(model, state, forces.wind, forces.tearing)


def energies(cloth, positions: np.ndarray, velocities: np.ndarray, gravity,
             alive: np.ndarray | None = None) -> dict[str, float]:
    """Kinetic, gravitational and spring energy [J], in float64 on the host.

    kinetic = sum 1/2 m |v|^2; gravity = -sum m g . x (Stuyck 4.3.1, zero at the origin);
    spring = sum 1/2 k (|x_i - x_j| - L)^2 (Stuyck eq. 4.4) over intact springs, also per kind
    as spring_stretch, spring_shear, spring_bend; total = kinetic + gravity + spring.
    """
    m = cloth.particle_mass
    kinetic = 0.5 * float(np.sum(m * np.sum(velocities * velocities, axis=1)))
    potential = -float(np.sum(m * (positions @ np.asarray(gravity, np.float64))))
    i, j = cloth.spring_indices.T
    stretch = np.linalg.norm(positions[i] - positions[j], axis=1) - cloth.spring_rest_length
    per_spring = 0.5 * cloth.spring_stiffness * stretch ** 2
    if alive is not None:
        per_spring = per_spring * alive
    by_kind = np.bincount(cloth.spring_kind, weights=per_spring, minlength=len(SpringKind))
    result = {"kinetic": kinetic, "gravity": potential, "spring": float(by_kind.sum())}
    result.update({f"spring_{k.name.lower()}": float(by_kind[k]) for k in SpringKind})
    result["total"] = kinetic + potential + result["spring"]
    return result
