"""Extended position-based dynamics (Macklin, Mueller & Chentanez 2016): springs as compliant
constraints with compliance 1 / k, so the cloth has its material stiffness in N/m; a Fabric's
triangles as strain and bending constraints with compliance from its moduli
(energies/). Its passes solve a backward Euler step, or BDF2's (XPBD.scheme).

BDF2 (Curtiss & Hirschfelder 1952; for cloth, Choi & Ko, "Stable but responsive cloth", 2002)
on x' = v, v' = a(x, v):

    x_{n+1} - 4/3 x_n + 1/3 x_{n-1} = 2/3 h v_{n+1},
    v_{n+1} - 4/3 v_n + 1/3 v_{n-1} = 2/3 h a(x_{n+1}, v_{n+1}).

With h^ = 2/3 h, x^ = (4 x_n - x_{n-1}) / 3 and v^ = (4 v_n - v_{n-1}) / 3 that is
x_{n+1} = x^ + h^ v^ + h^2 a(x_{n+1}, v_{n+1}), v_{n+1} = (x_{n+1} - x^) / h^: a backward Euler
step of h^ from (x^, v^), which the passes solve as they solve backward Euler's (compliance
alpha / h^2, the damping's rates against x^). Second order, A- and L-stable: a mode of
frequency w keeps its amplitude to O((h w)^4) a step where backward Euler loses (h w)^2 / 2,
and the modes a step cannot follow die out (Hairer & Wanner, Solving ODEs II, ch. V). The
history (x_{n-1}, v_{n-1}) is kept per particle, with what the step left (x_{n+1}, v_{n+1}):
a particle that a later stage of the step moved (a collider, self-contact, a handle, a seam),
or that the user set, or the first step of a run, starts again from the past its external
loads alone give it, x_{n-1} = x_n - h v_n + h^2 a / 2, v_{n-1} = v_n - h a (a = M^-1 f_ext:
the start stays second order where the internal forces start at rest, as a cloth at its rest
shape does; a constant velocity behind made it first order, the error halving with h). An
old velocity against a contact's new one would throw the particle back: a landing at -1 m/s,
stopped, would leave at +1/3 m/s.
"""


import numpy as np
import taichi as ti

from ..body.material import SpringKind
from ..body.mesh import Mesh
from ..contact.colliders.collision import push_out
from ..contact.self_collision import project_listed
from ..energies import PROJECTIONS
from ..energies.faces import XPBD_BENDING_TOLERANCE
from ..energies.membrane import XPBD_MEMBRANE_RELAXATION
from ..energies.springs import damp
from ..energies.tethers import (
    TETHERS,
    XPBD_TETHER_STRAIN,
    expected_strain,
    tether_table,
    weakest_modulus,
)
from ..inputs import limits
from ..inputs.validation import count, finite_number, require
from ..physics import wind
from ..physics.forces import gather_force
from ..runtime import backend, transfer
from ..runtime.plan import DT, ITEM, NOW, STATE, Loop, Phase, Repeat, Setting, Sweep, substep
from ..state import store_particle
from . import fused
from .base import PASSES, Integrator, add_settings
from .pbd import velocity_from_positions


@ti.func
def xpbd_predict(model: ti.template(), state: ti.template(), forces: ti.template(), i,
                 now: ti.template()):
    """x~ = x_n + h (v_n + h M^-1 f_ext) for particle i, f_ext its external loads (kept in
    particle_force); x_n is kept in particle_prev_position."""
    state.particle_force[i] = gather_force(model, state, forces, i, False)
    x = state.particle_position[i]
    v = state.particle_velocity[i] + now.dt * model.particle_inv_mass[i] * state.particle_force[i]
    state.particle_prev_position[i] = x
    state.particle_position[i] = x + now.dt * v


SCHEMES = ("backward_euler", "bdf2")     # the step the passes solve (XPBD.scheme)
TABLES = 4        # tether tables a workspace keeps (XPBD.loaded_workspace)


@ti.func
def _bdf2_predict(model: ti.template(), state: ti.template(), forces: ti.template(),
                  work: ti.template(), i, now: ti.template()):
    """x~ = x^ + h^ (v^ + h^ M^-1 f_ext) for particle i (module doc; now.dt is h^ = 2/3 h),
    its history taken and replaced by (x_n, v_n); x^ goes in particle_prev_position, where
    the passes' damping and the velocity read the step's origin."""
    hat = now.dt
    h = 1.5 * hat
    f = gather_force(model, state, forces, i, False)
    state.particle_force[i] = f
    a = model.particle_inv_mass[i] * f
    x = state.particle_position[i]
    v = state.particle_velocity[i]
    x_old, v_old = x - h * v + 0.5 * h * h * a, v - h * a     # no history (module doc)
    if now.start == 0 and (x == work.solved_position[i]).all() \
            and (v == work.solved_velocity[i]).all():
        x_old, v_old = work.history_position[i], work.history_velocity[i]
    work.history_position[i] = x
    work.history_velocity[i] = v
    origin = (4.0 * x - x_old) / 3.0
    state.particle_prev_position[i] = origin
    state.particle_position[i] = origin + hat * ((4.0 * v - v_old) / 3.0 + hat * a)


@ti.func
def _bdf2_velocity(state: ti.template(), work: ti.template(), i, now: ti.template(),
                   record: ti.template()):
    """v_{n+1} = (x_{n+1} - x^) / h^, x_n back in particle_prev_position (as backward Euler's
    step leaves it); with `record`, what the step left is noted (_bdf2_record)."""
    x = state.particle_position[i]
    store_particle(state, i, x, (x - state.particle_prev_position[i]) / now.dt, now.step)
    state.particle_prev_position[i] = work.history_position[i]
    if ti.static(record):
        _bdf2_record(state, work, i)


@ti.func
def _bdf2_record(state: ti.template(), work: ti.template(), i):
    """What the step left of particle i: the next step keeps its history only if it finds the
    particle there (module doc)."""
    work.solved_position[i] = state.particle_position[i]
    work.solved_velocity[i] = state.particle_velocity[i]


def contact_nodes(model, stage, pairs, colliders) -> tuple:
    """The end of a pass where self-collision joins the solve (SelfCollision.in_solve): the
    listed pairs in contact moved apart, in list order (a loop of one item), then every
    particle out of the colliders (`colliders`: a ColliderSet without animated meshes, placed
    for the step's end; or None)."""
    nodes = (Phase(Loop(1, project_listed, stage, pairs, model, STATE, ITEM)),)
    if colliders is not None:
        nodes += (Phase(Loop(model.particle_count, push_out, model, STATE, colliders, ITEM)),)
    return nodes


@backend.kernel_argument
class _Multipliers:
    """One Lagrange multiplier per spring (in colour order) and per altitude spring [N s^2],
    three per triangle for its strain and three for its bending (a Fabric's mid-edge bending),
    reset every step; each triangle's passes of its bending swept so far in the step and
    needed (energies/faces.py passes_needed); for the isometric bending of a flat sheet, each
    particle's displacement by it in the step (energies/isometric.py); the model's
    colourings (read by the phases); with
    `history` (BDF2), each particle's (x_{n-1}, v_{n-1}) and what the last step left of it
    (module doc); with `tethered`, each particle's anchors and rest lengths
    (energies/tethers.py), made for the pins `tethered_for` (their bytes) of the body
    `tables_for` (held: no id reused), and the last tables made for it, by pins (`tables`:
    XPBD.loaded_workspace).
    """

    HISTORY = ("history_position", "history_velocity", "solved_position", "solved_velocity")

    def __init__(self, model, history: bool, tethered: bool):
        fields = backend.FieldGroup()
        self.value = fields.scalar(backend.real(), max(model.spring_count, 1))
        self.altitude = fields.scalar(backend.real(), max(model.altitude_count, 1))
        self.membrane = fields.vector(3, backend.real(), max(model.face_count, 1))
        hinged = max(model.face_count, 1) if model.hinge_count and not model.isometric else 1
        self.bending = fields.vector(3, backend.real(), hinged)
        self.bending_swept = fields.scalar(ti.i32, hinged)
        self.bending_needed = fields.scalar(ti.i32, hinged)
        self.bend_shift = fields.vector(3, backend.real(),
                                        model.particle_count if model.isometric else 1)
        for name in self.HISTORY if history else ():
            setattr(self, name, fields.vector(3, backend.real(), model.particle_count))
        self.tethered, self.tethered_for = tethered, None
        self.tables, self.tables_for = {}, None   # the last tables made, by pins; their body
        if tethered:
            self.tether_anchor = fields.vector(TETHERS, ti.i32, model.particle_count)
            self.tether_length = fields.vector(TETHERS, backend.real(), model.particle_count)
        add_settings(self, fields)      # the passes (Integrator.runtime_options)
        fields.finalize(self)
        self.colours = model.spring_colouring()
        self.altitude_colours = model.altitude_colouring()
        if model.face_count:
            self.membrane_colours, self.bending_colours = model.element_colourings()


def _tether_table(model) -> tuple:
    """(anchors, rest lengths, expected strain) of energies/tethers.py for the model's body
    and its pins now. The strain (tethers="auto") from its mass over its rest area and its
    weakest stretch modulus (a Fabric's Young's modulus in its weakest direction, shear
    included: weakest_modulus; a Material's stretch springs' k), or a string's over its rest
    length and k l."""
    cloth = model.cloth
    stretch = cloth.spring_kind == SpringKind.STRETCH
    k, rest = cloth.spring_stiffness[stretch], cloth.spring_rest_length[stretch]
    anchors, lengths = tether_table(cloth.rest_position, cloth.mesh.triangles,
                                    cloth.spring_indices[stretch], cloth.seam_indices,
                                    model.pinned, cloth.particle_position)
    if len(cloth.mesh.triangles):
        extent = float(Mesh(cloth.rest_position, cloth.mesh.triangles).triangle_areas().sum())
        moduli = weakest_modulus(cloth.face_moduli) if cloth.face_count else k
    else:
        extent, moduli = float(rest.sum()), k * rest
    strain = expected_strain(float(cloth.particle_mass.sum()), extent,
                             float(np.min(moduli, initial=np.inf)), float(lengths.max()))
    return anchors, lengths, strain


class XPBD(Integrator):
    """XPBD: predict under external forces (gravity, drag, wind), then `iterations`
    Gauss-Seidel passes over the springs in colour order, each updating the spring's Lagrange
    multiplier (energies/springs.py xpbd_update), then v = (x_{n+1} - x_n) / h.

    Unlike pbd, the result does not depend on the iteration count once converged: it is the
    backward Euler step of the same Hookean springs (compliance 1/k) the force-based
    integrators use, with axial damping kd; for a Fabric, nearly that of its membrane and
    bending energies with their Rayleigh damping (a pass sweeps the triangles' strains, then
    their bending; what XPBD leaves out there: energies/faces.py). On a body with relative
    damping (Stuyck eq. 4.7) the constraints are undamped and one pass of implicit relative
    damping on the new velocities follows (energies/springs.py damp: each spring's backward
    Euler step in turn, stable at any h); positions keep their solve, as in position-based
    damping (Mueller et al. 2007), and the next prediction starts from the damped
    velocities. Unconverged (few iterations, stiff springs, large h), the cloth is softer
    than its material. The terms it sweeps, and their order: energies.PROJECTIONS.

    A flat sheet's isometric bending, quadratic with a constant matrix, is a point
    Gauss-Seidel over its particles in every pass (energies/isometric.py: it converges at any
    step). A Fabric's mid-edge bending (a curved rest shape, a garment, a BendingCurve) is
    swept in the passes it needs, triangle by triangle: its constraints
    are compliant against the membrane's at the steps cloth takes, so each pass settles most
    of what is left of them, and after the passes its stiffness at the step asks
    (energies/faces.py passes_needed: about r^k <= bending_tolerance, r = a / (1 + a), a the
    triangle's tr(h^2 B JWJ)) a triangle is left to the next step (docs/integrators.md,
    "XPBD's bending passes"); a stiff bending (a leather, a large step) is swept in every
    pass, as before. So the converged step above is the one of bending_tolerance=0: with a
    tolerance, what the membrane's later passes change in a bending waits a step (on a
    denim sheet 0.2-0.3 % of what 10 passes miss).

    iterations: Gauss-Seidel passes per step, >= 1. The cost is passes per simulated second:
        a pass settles more the smaller the step (M / h^2 against the stiffness), so few
        passes at a smaller step can beat many at a larger one (issue 53's 32² denim sheet,
        tethered: 2 passes at 1/480 s 9.2 mm from the elastic sheet, 7 at 1/240 s 10.0 mm,
        for 0.6 of the cost; docs/integrators.md, "Fewer passes at a smaller step").
    bending_tolerance: the part of a triangle's mid-edge bending residual its passes may
        leave, in [0, 1); 0 sweeps every triangle's bending in every pass.
    membrane_relaxation: omega, each update of a Fabric's membrane scaled by it (successive
        over-relaxation), in (0, 2); 1 (the default) is plain Gauss-Seidel. The converged step
        is the same; unconverged passes come nearer it (issue 53's 32² denim sheet at
        1/240 s, 10 passes: 70 mm from the converged step at omega = 1, 28 mm at 1.5, 23 mm
        at 1.7: a garment less stiff than its passes made it), but the nonlinear passes stand
        less than the linear theory's 2 (that sheet diverged at 1.9), and where contacts push
        back every step (self-collision, an animated body) a large omega may fight them
        (docs/integrators.md, "Over-relaxing the membrane's passes").
    tethers: None (the default), or the strain s >= 0 a particle may stretch from each of its
        nearest pins (long-range attachments, Kim et al. 2012: energies/tethers.py): at the end
        of every pass a particle farther than (1 + s) x its rest geodesic distance from one of
        its TETHERS nearest pinned particles is moved back onto that sphere. The passes carry a
        pin's hold one ring of triangles a pass, so a stiff fabric's unconverged passes leave
        it hanging long and rubbery; the tethers take that back at once (issue 53's 32² denim
        sheet, BDF2 step at 1/240 s, 10 passes over-relaxed: 41 mm from the elastic sheet
        without, 8.5 mm with s = 0.001; at 64², 156 and 18 mm). A cloth that stretches more
        than s between a pin and a particle is held short there: s is a model choice, the
        strain the fabric is not expected to pass (docs/integrators.md, "Tethers"); "auto"
        takes it from the body: the strain at a pin of a strip as long as its longest tether,
        swung down from level (energies/tethers.expected_strain: 0.20 % on issue 53's denim,
        17 % on an interlock knit), read back as `tether_strain` after a step. Anchors are the
        particles pinned at the step (a table for each set of pins: loaded_workspace); paths
        run along the triangles' edges (a string's, its stretch springs).
    scheme: the step the passes solve: "backward_euler" (XPBD as published, the default) or
        "bdf2" (module doc: second order, the same passes on a step of 2/3 h from an origin
        the last step's history extrapolates; each particle keeps two more positions and
        velocities, and a saved state holds them). Backward Euler damps a mode of frequency
        w by about (h w)^2 / 2 a step, which is the stiff, slow "cardboard" look of cloth at
        a garment's steps; BDF2 keeps the modes the step resolves (docs/integrators.md,
        "XPBD's BDF2 step").
    Order 1, 2 with scheme="bdf2" (the passes converged). No step-size stability limit.
    """

    name = "xpbd"
    order = 1
    position_based = True
    step_limited = False
    runtime_options = ("iterations", "bending_tolerance", "membrane_relaxation", "tethers")
    # the study and the advisor weigh BDF2's step beside the default (study.DEFAULT_SOLVES),
    # and that step tethered at the strain the body expects (energies/tethers.expected_strain)
    presets = {"bdf2": {"scheme": "bdf2"}, "tethered": {"scheme": "bdf2", "tethers": "auto"}}
    preset_noun = "step"

    def __init__(self, *, iterations: int = 10, bending_tolerance: float = 0.1,
                 membrane_relaxation: float = 1.0, scheme: str = "backward_euler",
                 tethers: float | str | None = None):
        self.iterations = count("XPBD.iterations", iterations, limits.ITERATIONS)
        self.bending_tolerance = finite_number("XPBD.bending_tolerance", bending_tolerance, 0.0)
        require(self.bending_tolerance < 1.0, "XPBD.bending_tolerance", bending_tolerance,
                "a fraction in [0, 1) (0: every pass)")
        self.membrane_relaxation = finite_number("XPBD.membrane_relaxation",
                                                 membrane_relaxation, 0.0, strict=True)
        require(self.membrane_relaxation < 2.0, "XPBD.membrane_relaxation", membrane_relaxation,
                "in (0, 2) (1: Gauss-Seidel; over-relaxed above 1)")
        require(scheme in SCHEMES, "XPBD.scheme", scheme,
                f"one of {', '.join(map(repr, SCHEMES))}")
        self.scheme = scheme
        if tethers is not None and tethers != "auto":
            allowed = 'None (no tethers), "auto" or a strain in [0, 1]'
            require(not isinstance(tethers, str), "XPBD.tethers", tethers, allowed)
            tethers = finite_number("XPBD.tethers", tethers, 0.0)
            require(tethers <= 1.0, "XPBD.tethers", tethers, allowed)
        self.tethers = tethers
        self.tether_strain = None if tethers == "auto" else tethers   # "auto": the body's (below)
        self.order = 2 if scheme == "bdf2" else 1
        self.records_history = scheme == "bdf2"    # the start of a run has no history

    def options(self):
        return {"iterations": self.iterations, "bending_tolerance": self.bending_tolerance,
                "membrane_relaxation": self.membrane_relaxation, "scheme": self.scheme,
                "tethers": self.tethers}

    def compiled_options(self):
        """Whether there are tethers is compiled; their strain is read at run time."""
        return super().compiled_options() | {"tethered": self.tethers is not None}

    def settings_values(self):
        """The slots PASSES, energies/faces.XPBD_BENDING_TOLERANCE,
        energies/membrane.XPBD_MEMBRANE_RELAXATION and energies/tethers.XPBD_TETHER_STRAIN."""
        values = [0.0] * (max(XPBD_BENDING_TOLERANCE, XPBD_MEMBRANE_RELAXATION,
                              XPBD_TETHER_STRAIN) + 1)
        values[PASSES] = float(self.iterations)
        values[XPBD_BENDING_TOLERANCE] = self.bending_tolerance
        values[XPBD_MEMBRANE_RELAXATION] = self.membrane_relaxation
        values[XPBD_TETHER_STRAIN] = self.tether_strain or 0.0
        return tuple(values)

    def workspace(self, model, state):
        return self.buffers(state, lambda: _Multipliers(model, self.scheme == "bdf2",
                                                        self.tethers is not None))

    def buffer_key(self):
        return (type(self), self.scheme, self.tethers is not None)

    def loaded_workspace(self, model, state):
        """The workspace with its settings and, with tethers, their table for this body and
        its pins now (energies/tethers.py): a function of them alone, so every run of a
        simulation steps alike. The last TABLES tables are kept (a handle's hold and release,
        a restart: uploaded again, not made); another set of pins makes one (a particle
        grabbed in the viewer: 0.2-0.6 s on a garment, Dijkstra in Python)."""
        work = self.workspace(model, state)
        if work.tethered:
            if work.tables_for is not model.cloth:     # another body: the pool's next simulation
                work.tables_for, work.tables, work.tethered_for = model.cloth, {}, None
            pins = model.pinned.tobytes()
            if work.tethered_for != pins:
                made = work.tables.pop(pins, None) or _tether_table(model)
                work.tables[pins] = made                       # the newest last
                if len(work.tables) > TABLES:
                    del work.tables[next(iter(work.tables))]
                transfer.upload(((work.tether_anchor, made[0]), (work.tether_length, made[1])))
                work.tethered_for = pins
            self.tether_strain = (work.tables[work.tethered_for][2] if self.tethers == "auto"
                                  else self.tethers)
        self.load_settings(work)
        return work

    def copy_reports(self, stepper) -> None:
        """The strain the tethers hold (`tether_strain`: "auto"'s as the body gave it)."""
        self.tether_strain = stepper.tether_strain

    def saved_history(self, model, state) -> dict:
        """BDF2's per-particle history (module doc), for a saved state."""
        if self.scheme != "bdf2":
            return {}
        work = self.workspace(model, state)
        return {name: getattr(work, name).to_numpy() for name in _Multipliers.HISTORY}

    def restore_history(self, model, state, arrays: dict) -> None:
        """Load what saved_history returned."""
        if self.scheme == "bdf2":
            work = self.workspace(model, state)
            for name in _Multipliers.HISTORY:
                getattr(work, name).from_numpy(arrays[name])

    def step_work(self, model):
        return (self.iterations + 2) * fused.spring_work(model)

    def phases(self, model, forces, work):
        """Predict under the external loads (and the wind) with the multipliers cleared,
        `iterations` passes colour by colour (work: the _Multipliers), each ending with the
        self-contacts and the colliders where they join the solve (forces.contact), velocities
        from positions, and on a relative-damped body one pass of implicit damping; with BDF2,
        on a step of 2/3 h from its origin."""
        clear, passes = (), ()
        for term in PROJECTIONS:         # energies.PROJECTIONS, in that order
            clears, sweeps = term.xpbd_nodes(model, forces, work)
            clear, passes = clear + clears, passes + sweeps
        if forces.contact is not None and passes:     # SelfCollision.in_solve
            passes += contact_nodes(model, *forces.contact)
        damping = ()
        if model.spring_count and model.relative_damping:
            damping = (Sweep(work.colours, damp, model, STATE, work.colours, ITEM, DT,
                             forces.tearable),)
        n = model.particle_count
        if self.scheme == "backward_euler":
            predict = Loop(n, xpbd_predict, model, STATE, forces, ITEM, NOW)
            velocity = Loop(n, velocity_from_positions, STATE, ITEM, NOW)
        else:
            predict = Loop(n, _bdf2_predict, model, STATE, forces, work, ITEM, NOW)
            velocity = Loop(n, _bdf2_velocity, STATE, work, ITEM, NOW, not damping)
        step = (wind.phases(model, forces) + (Phase(predict, *clear),)
                + ((Repeat(Setting(work, PASSES), *passes),) if passes else ())
                + (Phase(velocity),) + damping)
        if self.scheme == "backward_euler":
            return step
        # BDF2: the same phases on a step of 2/3 h from its origin (module doc), then what the
        # step left noted (after the damping, which changes the velocities)
        record = (Phase(Loop(n, _bdf2_record, STATE, work, ITEM)),) if damping else ()
        return substep(2.0 / 3.0, step) + record
