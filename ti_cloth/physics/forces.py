"""Forces as Taichi functions (gravity, Hookean springs, spring damping, air drag, Selle et al.
2008's altitude springs) and the energies they derive from, evaluated on the host in float64.

Each spring's force is computed once per evaluation, from its first end's side, into
State.spring_force (a loop over springs); every particle then gathers + or - the forces of its
own springs in a fixed order (Model adjacency: second-end springs first, then first-end ones).
No float atomics, so a run is deterministic; each spring's formula is evaluated once, not once
per end; Newton's third law holds exactly. Altitude springs (four particles each) are evaluated
the same way: once each, into one force per corner, which each corner gathers in a fixed order.

The pieces are ti.funcs, the bodies of the phases integrators write their steps with
(runtime/plan.py): a loop over springs, then one over particles.
"""


import warnings
from dataclasses import dataclass

import numpy as np
import taichi as ti

from ..body.material import SpringKind
from ..energies import SLOTS, TERMS
from ..energies.altitude import altitude_energy
from ..energies.bending import bending_energy, bending_phases
from ..energies.isometric import isometric_energy
from ..energies.membrane import membrane_energy
from ..energies.springs import spring_energies
from ..runtime import backend, plan
from ..runtime.plan import ITEM, STATE, Loop, Phase
from . import wind


@backend.kernel_argument
@dataclass(frozen=True)
class ForceSettings:
    """External loads and switches of one simulation, compile-time constants of its kernels
    (passed as a template argument, compiled per instance).

    gravity: acceleration [m/s^2], any direction.
    drag: uniform air drag [1/s]: f_i = -drag * m_i * v_i (mass-proportional, so the same
        deceleration everywhere and independent of resolution). 0 compiles it out.
    tearable: springs carry an alive flag that force loops must test (compile-time switch; on
        when the simulation has Tearing).
    wind: a wind.WindField (per-triangle aerodynamics) or None (its kernel is never compiled).
    contact: (self-collision stage, its candidate PairList, the ColliderSet met in the passes
        or None: one with animated meshes is met after them) when the contacts join the
        integrator's passes (SelfCollision.in_solve: xpbd), else None; a bigger list is
        another setting (its kernels compile again, once).
    """

    gravity: tuple[float, float, float] = (0.0, -9.81, 0.0)
    drag: float = 0.0
    tearable: bool = False
    wind: object = None
    contact: tuple | None = None

    def __post_init__(self):
        object.__setattr__(self, "gravity", tuple(float(g) for g in self.gravity))
        object.__setattr__(self, "drag", float(self.drag))

    @property
    def has_wind(self) -> bool:
        return self.wind is not None

    @property
    def tearing(self) -> bool:
        """Deprecated name of `tearable`."""
        warnings.warn("ForceSettings.tearing is now ForceSettings.tearable", DeprecationWarning,
                      stacklevel=2)
        return self.tearable


def force_loops(model, forces) -> tuple:
    """The loops of a force evaluation's first phase: each term's of energies.TERMS that the
    model has (every spring, altitude spring and triangle membrane, and every hinge's angle or
    every particle's isometric bending), in that order."""
    return sum((term.force_loops(model, forces) for term in TERMS), ())


def spring_phases(model, forces) -> tuple:
    """The phases that evaluate every term the model has (force_loops, then the mid-edge
    bending's moments and forces), none for a body without them."""
    loops = force_loops(model, forces)
    return ((Phase(*loops),) if loops else ()) + bending_phases(model)


@ti.func
def gather_force(model: ti.template(), state: ti.template(), forces: ti.template(), i,
                 springs: ti.template()):
    """Total force on particle i: m g (Stuyck eq. 4.3) - drag m v + its terms' forces, as
    spring_phases left them (springs=False: external loads only) + the wind's
    share."""
    f = model.particle_mass[i] * ti.Vector(forces.gravity)
    if ti.static(forces.drag > 0):
        f -= forces.drag * model.particle_mass[i] * state.particle_velocity[i]
    if ti.static(springs):
        for slots in ti.static(SLOTS):        # the terms' forces, in a fixed order
            f = slots.gather(model, state, i, f)
    if ti.static(forces.has_wind):
        f += forces.wind.particle_wind_force[i]
    return f


@ti.func
def total_force(model: ti.template(), state: ti.template(), forces: ti.template(), i):
    """particle_force[i] = the total force on particle i (springs evaluated)."""
    state.particle_force[i] = gather_force(model, state, forces, i, True)


@ti.func
def external_force(model: ti.template(), state: ti.template(), forces: ti.template(), i):
    """particle_force[i] = the external loads on particle i (gravity, drag, wind)."""
    state.particle_force[i] = gather_force(model, state, forces, i, False)


@backend.kernel_argument
class _Evaluation:
    """The force evaluation of compute_forces, as phases (plan.py)."""

    def phases(self, model, forces, work):
        """The wind, every spring, every particle's total."""
        return (wind.phases(model, forces) + spring_phases(model, forces)
                + (Phase(Loop(model.particle_count, total_force, model, STATE, forces, ITEM)),))

    def external(self, model, forces, work):
        """The wind, every particle's external loads."""
        return wind.phases(model, forces) + (Phase(Loop(model.particle_count, external_force,
                                                        model, STATE, forces, ITEM)),)


EVALUATION = _Evaluation()


def compute_forces(model, state, forces: ForceSettings, springs: bool = True,
                   time: float = 0.0) -> None:
    """particle_force at the current state and time [s] (the wind's): with springs, or
    (springs=False) the external loads only."""
    plan.run(EVALUATION, model, state, forces, state, 0.0, 0, False,
             "phases" if springs else "external", time=time)


def energies(cloth, positions: np.ndarray, velocities: np.ndarray, gravity,
             alive: np.ndarray | None = None, face_alive: np.ndarray | None = None,
             isometric: bool = False) -> dict[str, float]:
    """Kinetic, gravitational and spring energy [J], in float64 on the host.

    kinetic = sum 1/2 m |v|^2; gravity = -sum m g . x (Stuyck 4.3.1, zero at the origin);
    spring = sum 1/2 k (|x_i - x_j| - L)^2 (Stuyck eq. 4.4) over intact springs, plus
    sum 1/2 k (h - h0)^2 over altitude springs, plus a Fabric's membrane and bending energies
    (energies/; of the triangles face_alive keeps, when given; bending by the isometric
    model with `isometric`, as Model.isometric); also per kind as spring_stretch, spring_shear,
    spring_bend, spring_altitude, membrane and bending; total = kinetic + gravity + spring.
    """
    m = cloth.particle_mass
    kinetic = 0.5 * float(np.sum(m * np.sum(velocities * velocities, axis=1)))
    potential = -float(np.sum(m * (positions @ np.asarray(gravity, np.float64))))
    per_spring = spring_energies(cloth, positions, alive)
    by_kind = np.bincount(cloth.spring_kind, weights=per_spring, minlength=len(SpringKind))
    altitude = altitude_energy(cloth, positions)
    membrane = membrane_energy(cloth, positions, face_alive)
    bending = (isometric_energy if isometric else bending_energy)(cloth, positions, face_alive)
    result = {"kinetic": kinetic, "gravity": potential,
              "spring": float(by_kind.sum()) + altitude + membrane + bending}
    result.update({f"spring_{k.name.lower()}": float(by_kind[k]) for k in SpringKind})
    result["spring_altitude"] = altitude
    result["membrane"] = membrane
    result["bending"] = bending
    result["total"] = kinetic + potential + result["spring"]
    return result
