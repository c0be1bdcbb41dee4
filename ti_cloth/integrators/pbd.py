"""The lecture's cloth: Verlet prediction under external forces, then spring relaxation."""


from collections.abc import Mapping

import taichi as ti

from ..body.material import SpringKind
from ..energies.altitude import relax_altitude
from ..energies.springs import relax
from ..inputs import limits
from ..inputs.validation import count, finite_number, require
from ..physics import wind
from ..physics.forces import gather_force
from ..runtime import backend
from ..runtime.plan import ITEM, NOW, STATE, Loop, Phase, Repeat, Setting, Sweep
from ..state import store_particle
from . import fused
from .base import PASSES, Integrator, add_settings
from .verlet import verlet_update


@backend.kernel_argument
class SweepOrder:
    """A model's spring and altitude-spring colourings, as one kernel argument (pbd's
    phases sweep them), and the run-time settings (the passes: Integrator.runtime_options)."""

    def __init__(self, model):
        self.colours = model.spring_colouring()
        self.altitude_colours = model.altitude_colouring()
        fields = backend.FieldGroup()
        add_settings(self, fields)
        fields.finalize(self)


@ti.func
def velocity_from_positions(state: ti.template(), i, now: ti.template()):
    """v_{n+1} = (x_{n+1} - x_n) / h for particle i, with x_n in particle_prev_position."""
    x = state.particle_position[i]
    store_particle(state, i, x, (x - state.particle_prev_position[i]) / now.dt, now.step)


@ti.func
def _predict(model: ti.template(), state: ti.template(), forces: ti.template(), i,
             now: ti.template(), integrator: ti.template()):
    """Verlet prediction of particle i under its external forces (kept in particle_force)."""
    f = gather_force(model, state, forces, i, False)
    state.particle_force[i] = f
    verlet_update(state, i, model.particle_inv_mass[i] * f, now.dt, integrator.damping,
                  now.start, now.step)


@ti.func
def _relax_spring(model: ti.template(), state: ti.template(), forces: ti.template(),
                  work: ti.template(), t, integrator: ti.template()):
    relax(model, state, work.colours, t, ti.Vector(integrator.kind_stiffness), forces.tearable,
          0.0, False)


@ti.func
def _relax_altitude(model: ti.template(), state: ti.template(), work: ti.template(), t,
                    integrator: ti.template()):
    relax_altitude(model, state, work.altitude_colours.order[t],
                   integrator.stiffness["altitude"])


STIFFNESS_KEYS = tuple(k.name.lower() for k in SpringKind) + ("altitude",)


class PBD(Integrator):
    """Position-based dynamics as in the lecture: springs are constraints.

    Each step: (1) Verlet-predict every particle under gravity and drag only (with the lecture's
    damping factor), (2) `iterations` Gauss-Seidel passes of mass-weighted spring relaxation,
    (3) velocity = (x_{n+1} - x_n) / h. Spring constants k and kd are not used: with
    stiffness 1 a spring is projected fully to its rest length each pass, so the cloth's
    apparent stiffness grows with iterations and shrinks with h (use xpbd for a material
    stiffness in N/m).

    iterations: relaxation passes per step, >= 1 (the lecture uses 1-2).
    damping: lecture factor d in [0, 1), as Verlet.
    stiffness: fraction of the correction applied per pass, per kind, {"stretch": 1.0, ...};
        "altitude" for the altitude springs (each a corner projected to its rest height over
        the opposite face of a tetrahedron: energies/altitude.py relax_altitude).
    Order 1 (velocity from positions); no step-size stability limit: positions are projected,
    never extrapolated by stiff forces.
    """

    name = "pbd"
    runs_fabric = False   # a Fabric's elements need constraints (and Hessians): not yet
    order = 1
    position_based = True
    step_limited = False
    records_history = True
    runtime_options = ("iterations",)

    def __init__(self, *, iterations: int = 2, damping: float = 0.0, stiffness=None):
        self.iterations = count("PBD.iterations", iterations, limits.ITERATIONS)
        self.damping = finite_number("PBD.damping", damping, 0.0)
        require(self.damping < 1.0, "PBD.damping", damping, "a number in [0, 1)")
        require(stiffness is None or isinstance(stiffness, Mapping), "PBD.stiffness", stiffness,
                "None or a table {stretch = 1.0, shear = ..., bend = ...}")
        stiffness = dict(stiffness or {})
        unknown = set(stiffness) - set(STIFFNESS_KEYS)
        require(not unknown, "PBD.stiffness keys", sorted(unknown),
                ", ".join(repr(k) for k in STIFFNESS_KEYS))
        self.stiffness = {k: 1.0 for k in STIFFNESS_KEYS} | {
            name: finite_number(f"PBD.stiffness[{name!r}]", value, 0.0) for name, value in stiffness.items()}
        for name, value in self.stiffness.items():
            require(value <= 1.0, f"PBD.stiffness[{name!r}]", value, "a fraction in [0, 1]")
        self.kind_stiffness = tuple(self.stiffness[k.name.lower()] for k in SpringKind)

    def options(self):
        return {"iterations": self.iterations, "damping": self.damping, "stiffness": self.stiffness}

    def settings_values(self):
        return (float(self.iterations),)

    def workspace(self, model, state):
        return self.buffers(state, lambda: SweepOrder(model))

    def step_work(self, model):
        return (self.iterations + 2) * fused.spring_work(model)

    def phases(self, model, forces, work):
        """Predict under the external loads (and the wind), `iterations` relaxation passes
        colour by colour (work: the SweepOrder), velocities from positions."""
        passes = ()
        if model.spring_count:
            passes += (Sweep(work.colours, _relax_spring, model, STATE, forces, work, ITEM, self),)
        if model.altitude_count:
            passes += (Sweep(work.altitude_colours, _relax_altitude, model, STATE, work, ITEM,
                             self),)
        return (wind.phases(model, forces)
                + (Phase(Loop(model.particle_count, _predict, model, STATE, forces, ITEM, NOW,
                              self)),)
                + ((Repeat(Setting(work, PASSES), *passes),) if passes else ())
                + (Phase(Loop(model.particle_count, velocity_from_positions, STATE, ITEM, NOW)),))
