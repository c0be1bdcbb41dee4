"""Simulation: the step loop, the divergence guard and diagnostics.

Each step runs the integrator, then the stages the simulation has, in STEP_ORDER (stages.py:
the order and what a stage is); a stage is made, compiled and launched only when the
simulation has it. The colliders and self-collision also have before_step(state, t) (t: the
step's start). The integrator's step and the stages' are written once, as phases
(runtime/plan.py): a launch per phase runs them (Integrator.step, Stage.after_step), and on
the CPU, when every stage has a `launched` object, many steps run in one launch (stepping.py;
tested against a launch per phase).
"""


import dataclasses
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from . import saved_state, stepping
from .body.topology import Cloth
from .contact.colliders.attachment import Attachment
from .contact.colliders.collision import ColliderSet
from .contact.colliders.shapes import Collider
from .contact.self_collision import (
    SelfCollision,
    SelfCollisionStage,
    SelfContacts,
    warn_if_thick,
)
from .energies.isometric import is_flat
from .errors import CrushedContact, SimulationDiverged, StaleSimulation, StateMismatch
from .inputs import limits
from .inputs.validation import as_array, in_range, integer, require
from .integrators import INTEGRATORS, make_integrator
from .model import Model
from .physics.forces import ForceSettings, energies
from .physics.handles import Handle, HandleSet, HandleTable
from .physics.sewing import Seams, Sewing
from .physics.strain_limit import StrainLimit, StrainLimiter
from .physics.tearing import RUNAWAY_STRAIN, Tearing, torn_triangles
from .physics.wind import WindField
from .runtime import backend, transfer
from .runtime.pool import POOL
from .stability import auto_dt, stable_dt
from .stages import STEP_ORDER, in_order
from .state import NO_BAD_STEP, State

PLANS = ("per stage", "many steps")   # Simulation.step's launch plans
# Simulation's options, in the order of the positional form kept for one release
OPTIONS = ("integrator", "dt", "gravity", "drag", "wind", "tearing", "handles", "colliders",
           "strain_limit", "position_limit", "self_collision", "sewing")


class Simulation:
    """Advance a Cloth in time with one integrator and fixed step dt.

    cloth: the body. integrator: a name from ti_cloth.INTEGRATORS or an Integrator instance.
    dt: step [s], > 0, or "auto": half the predicted stable step, at most 1/240 s
        (stability.auto_dt; ValueError if no stable step exists).
    gravity: [m/s^2], any vector. drag: uniform air drag [1/s], >= 0.
    tearing: None (off: the tear kernel is never compiled nor launched), a tear strain
        (float) or a Tearing.
    handles: scripted particles (Handle) and particles carried by a collider's surface
        (Attachment, a handle bound to the surface at t = 0); their particles are pinned
        while held (until a release time). dt="auto" treats particles let go as free.
    colliders: Plane, Sphere, Box, Capsule, MeshCollider, AnimatedMeshCollider objects
        (none: the collision kernels are never compiled nor launched).
    strain_limit: None (off: never compiled nor launched) or a StrainLimit (Provot 1995).
    position_limit: the divergence guard flags any |coordinate| beyond this [m].
    sewing: how a garment's seams close (a Sewing); default Sewing() when the cloth has
        seams (Cloth.seam_indices), none otherwise (never compiled nor launched).

    Each step runs the integrator, then the stages of STEP_ORDER this simulation has
    (stages.py); the wind is held at its value at the step start.
    """

    def __init__(self, cloth: Cloth, *positional, integrator="symplectic_euler",
                 dt: float = 1e-3, gravity=(0.0, -9.81, 0.0), drag: float = 0.0, wind=None,
                 tearing=None, handles: Sequence[Handle] = (), colliders=(), strain_limit=None,
                 position_limit: float = 1e6, self_collision: SelfCollision | None = None,
                 sewing: Sewing | None = None):
        options = {name: value for name, value in locals().items() if name in OPTIONS}
        if positional:
            options = _from_positional(positional, options)
        with transfer.batched():     # the model's and the stages' tables in one launch
            self._build(cloth, **options)

    def _build(self, cloth, integrator, dt, gravity, drag, wind, tearing, handles, colliders,
               strain_limit, position_limit, self_collision, sewing) -> None:
        require(isinstance(cloth, Cloth), "cloth", cloth, "a ti_cloth.Cloth")
        self._runtime = backend.generation()
        self.cloth = cloth
        self.integrator = make_integrator(integrator)
        if cloth.fabric:
            _check_fabric_integrator(self.integrator)
            require(tearing is None or strain_limit is None, "strain_limit", strain_limit,
                    "None when a body made of a Fabric can tear (tearing is set): the limit "
                    "relaxes triangle edges and would hold a torn crack shut")
        auto = isinstance(dt, str) and dt == "auto"
        self.dt = None if auto else in_range("dt", dt, limits.DT)
        gravity = as_array("gravity", gravity, np.float64, (3,))
        for axis in range(3):
            in_range(f"gravity[{axis}]", gravity[axis], limits.ACCELERATION)
        drag = in_range("drag", drag, limits.DRAG)
        if tearing is not None and not isinstance(tearing, Tearing):
            tearing = Tearing(tearing)
        require(tearing is None or getattr(self.integrator, "tethers", None) is None, "tearing",
                tearing, "None when xpbd has tethers (XPBD.tethers): a piece torn off would "
                "stay tied to its pin")
        self.tearing = tearing
        require(isinstance(handles, (list, tuple)), "handles", handles,
                "a list of Handle and Attachment objects (handles=[Handle(...)])")
        handles = tuple(handles)
        held = [h.handle(cloth.particle_position) if isinstance(h, Attachment) else h
                for h in handles]
        self.handles = (HandleSet(held, cloth.particle_position, cloth.pinned) if handles
                        else None)
        pinned = self.handles.pinned() if self.handles is not None else cloth.pinned
        position_limit = in_range("position_limit", position_limit, limits.GUARD)
        require(strain_limit is None or isinstance(strain_limit, StrainLimit), "strain_limit",
                strain_limit, "None or a StrainLimit")
        require(isinstance(colliders, (list, tuple)), "colliders", colliders,
                "a list of colliders (colliders=[Plane(...)])")
        colliders = tuple(c.for_cloth(cloth) if isinstance(c, Collider) else c
                          for c in colliders)     # a default thickness: the cloth's (shapes.py)
        require(sewing is None or isinstance(sewing, Sewing), "sewing", sewing,
                "None or a Sewing(speed=...)")
        require(sewing is None or len(cloth.seam_indices), "sewing", sewing,
                "None for a cloth without seams (Cloth(seams=...), a Garment's seam_pairs)")
        if len(cloth.seam_indices) and sewing is None:
            sewing = Sewing()
        # what decides the motion besides the integrator and dt (fingerprint)
        self._inputs = (cloth, tuple(gravity), drag, wind, tearing, handles, colliders,
                        strain_limit, position_limit, self_collision, sewing)
        # a flat sheet bends by the isometric model, its Q merged over the triangles, unless
        # triangles can tear out of it (then by the mid-edge tangents, whose hinges can go) or
        # its rigidity depends on curvature (a quadratic energy cannot carry a BendingCurve)
        isometric = is_flat(cloth) and tearing is None and not cloth.curved
        parts = {"model": (Model, (cloth, pinned, isometric)),
                 "state": (State, (cloth.particle_count, cloth.spring_count, position_limit,
                                   cloth.altitude_count, cloth.face_count, cloth.hinge_count))}
        if wind is not None:
            parts["wind"] = (WindField, (wind, cloth))
        if strain_limit is not None and (cloth.spring_count or cloth.face_count):
            parts["strain_limit"] = (StrainLimiter, (strain_limit, cloth.particle_count,
                                                       tearing is not None))
        if colliders:
            parts["colliders"] = (ColliderSet, (colliders, cloth))
        if sewing is not None:
            parts["sewing"] = (Seams, (sewing, cloth.seam_indices, cloth.particle_position))
        require(self_collision is None or isinstance(self_collision, SelfCollision),
                "self_collision", self_collision, "None or a SelfCollision(thickness=...)")
        if self_collision is not None:
            warn_if_thick(self_collision, cloth)
            require(not self_collision.in_solve or self.integrator.name == "xpbd",
                    "self_collision.in_solve", True, f"False with {self.integrator.name!r}: "
                    "the contacts join the passes of the xpbd integrator only")
            parts["self_collision"] = (SelfCollisionStage, (self_collision, cloth))
        if handles:
            parts["handle_table"] = (HandleTable, (len(self.handles.index),))
        self._lent = self._lend(parts)
        self.model, self.state = self._lent["model"], self._lent["state"]
        self.wind = self._lent.get("wind")
        self.strain_limiter = self._lent.get("strain_limit")
        self.colliders = self._lent.get("colliders")
        self.seams = self._lent.get("sewing")
        self.self_collision = self._lent.get("self_collision")
        if self.handles is not None:
            self.handles.table = self._lent["handle_table"]
        if self.self_collision is not None:
            self.self_collision.attach(self.colliders)
        # Kernels get the pool's equal copies, whose compiled kernels outlive this simulation;
        # the user's integrator gets the reports of the steps (Simulation.step).
        self.forces = POOL.keep(ForceSettings(gravity=tuple(gravity), drag=drag,
                                              tearable=tearing is not None, wind=self.wind))
        self._in_solve = self_collision is not None and self_collision.in_solve
        held = pinned if self.handles is None else self.handles.pinned(permanent=True)
        self.integrator.fit(cloth, drag, held)
        self._stepper = POOL.keep(self.integrator)
        if auto:
            self.dt = auto_dt(cloth, self.integrator, drag, held)
        self.state.reset(self.cloth.particle_position)
        # the pool's copy of the Tearing, its strain a constant of the kernels (pool.py)
        self._tearing = None if self.tearing is None else POOL.keep(self.tearing)
        # the stages this simulation has, by their STEP_ORDER names, in that order
        self._stages = in_order(dict(handles=self.handles, sewing=self.seams,
                                     strain_limit=self.strain_limiter, colliders=self.colliders,
                                     self_collision=self.self_collision, tearing=self._tearing))
        self.stages = ("integrator",) + tuple(self._stages)
        self._before = [stage for stage in (self.colliders, self.self_collision)
                        if stage is not None]
        self.step_count = 0
        self._diverged: SimulationDiverged | None = None
        self._place_handles_at_start()
        # Many steps per launch on the CPU when every stage runs in a team launch; with
        # self-collision (whose list is made on the host), each step's integrator and the
        # stages before self-collision in one team launch, the rest launch by launch (made
        # on first use, kept with the lent objects).
        head = {name: stage for name, stage in self._stages.items()
                if self.self_collision is None
                or STEP_ORDER.index(name) < STEP_ORDER.index("self_collision")}
        teamed = backend.config().arch == "cpu" and all(
            stage.launched is not None for stage in head.values())
        self._many_per_launch = teamed and len(head) == len(self._stages)
        self._team_head = head if teamed else None
        self._tail = [stage for name, stage in self._stages.items() if name not in head]

    def _lend(self, parts: dict) -> dict:
        """The objects this simulation passes to kernels, {name: cls(*args)}, lent by the pool
        (pool.py) as one set, so their kernels are compiled once per structure in a process;
        a set lent before is loaded with these args."""
        key = tuple((name, cls.structure(*args)) for name, (cls, args) in parts.items())
        size = limits.memory_needed(self.cloth.particle_count,
                                    limits.spring_equivalents(self.cloth))
        lent, reused = POOL.lend(key, lambda: {name: cls(*args) for name, (cls, args)
                                               in parts.items()}, self, size)
        if reused:
            for name, (cls, args) in parts.items():
                lent[name].load(*args)
        return lent

    def restart(self, dt: float | None = None) -> None:
        """Back to time 0: rest positions, at rest, every spring intact, handles and colliders
        at their start, the divergence flag cleared; `dt` [s] replaces the step if given.
        The compiled kernels are kept, so a sweep over dt compiles once."""
        self._check_runtime()
        if dt is not None:
            self.dt = in_range("dt", dt, limits.DT)
        with transfer.batched():
            self.state.reset(self.cloth.particle_position)
            self.step_count = 0
            self._diverged = None
            if self.colliders is not None and self.colliders.moving:
                self.colliders.place(0.0)
            self._place_handles_at_start()
            if self.self_collision is not None:
                self.self_collision.forget()

    def _place_handles_at_start(self) -> None:
        if self.handles is not None:
            self.handles.place_at_start(self.model, self.state, self.dt)

    def fingerprint(self) -> str:
        """Hex digest of everything that decides this simulation's motion (saved_state.py):
        a saved state is loaded only into a simulation with the same fingerprint. Of the
        integrator, its name and the options it was given away from their defaults
        (Integrator.changed_options)."""
        return saved_state.fingerprint(backend.config().precision, self.integrator.name,
                                       self.integrator.changed_options(), self.dt,
                                       *self._inputs)

    def save_state(self, path) -> Path:
        """Write everything this simulation needs to continue bit for bit from here to `path`
        (an npz, written atomically): positions, velocities, previous positions, forces of
        the last evaluation, spring alive flags and tear steps, the step count, what the
        integrator keeps of the steps before (XPBD's BDF2 history) and self-collision's
        candidate list. Handles, colliders and the wind follow from the time.
        Returns the path."""
        self._check_runtime()
        require(self._diverged is None, "simulation", "diverged",
                "a simulation that has not diverged (its state is not finite)")
        arrays = {f"state.{k}": v for k, v in self.state.saved().items()}
        arrays.update({f"integrator.{k}": v for k, v
                       in self.integrator.saved_history(self.model, self.state).items()})
        if self.self_collision is not None:    # "self_contact.": the key of saved states
            arrays.update({f"self_contact.{k}": v
                           for k, v in self.self_collision.saved().items()})
        return saved_state.write(path, self.fingerprint(),
                                 {"step_count": self.step_count, "dt": self.dt}, arrays)

    def load_state(self, path) -> None:
        """Continue from the state save_state wrote to `path`: the next step is the one after
        it, with the same bits as in the run that saved it. Raises errors.StateMismatch for a
        file of another state format or from a different simulation (fingerprint)."""
        self._check_runtime()
        header, arrays = saved_state.read(path, self.fingerprint())
        expected = {f"state.{k}": v for k, v in self.state.saved().items()}
        history = self.integrator.saved_history(self.model, self.state)
        expected.update({f"integrator.{k}": v for k, v in history.items()})
        saved_state.check_arrays(path, arrays, expected, float(self.state.limit))
        steps = header.get("step_count")
        if not (isinstance(steps, int) and not isinstance(steps, bool)
                and 0 <= steps <= limits.STEPS.high):
            raise StateMismatch(f"{path}: its step_count {steps!r} is not a step count "
                                f"{limits.STEPS.text()}")
        contact = _prefixed(arrays, "self_contact.")
        if self.self_collision is not None:
            self.self_collision.check_saved(path, contact, float(self.state.limit))
        self.state.restore(_prefixed(arrays, "state."))
        self.integrator.restore_history(self.model, self.state, _prefixed(arrays, "integrator."))
        if self.self_collision is not None:
            self.self_collision.restore(contact)
        self.step_count = int(header["step_count"])
        self._diverged = None
        if self.handles is not None:
            self.handles.hold_at(self.model, self.time, self.dt)
        if self.colliders is not None and self.colliders.moving:
            self.colliders.place(self.time, self.dt if self.step_count else None)

    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return self.step_count * self.dt

    def step(self, n: int = 1, *, plan: str | None = None) -> None:
        """Advance n steps of dt, each the stages of STEP_ORDER. Raises SimulationDiverged at
        the first step whose result is not finite; after that the simulation refuses to
        continue.

        plan: how the steps are launched (PLANS). None takes the default, decided by the
        arch and the simulation alone: on the CPU many steps per launch when every stage runs
        there (many_steps), a single step too (one kernel serves a simulation stepped one
        and many at a time: each plan compiles the whole step, docs/performance.md); with
        self-collision a launch per step of the integrator and the stages before it, then a
        launch per stage for the rest; on GPUs a launch per stage. "per stage" or "many
        steps" forces one (ValueError if this simulation has no many-steps plan: one with
        self-collision, or on a GPU). Every plan gives the same bits, on every rerun
        and thread count (exact IEEE arithmetic: runtime/backend.py)."""
        self._check_runtime()
        integer("n", n, 0, limits.STEPS.high - self.step_count)
        require(plan is None or plan in PLANS, "plan", plan, f"None or one of {PLANS}")
        require(plan != "many steps" or self._many_per_launch, "plan", plan,
                "'per stage' here: this simulation has a stage that runs only launch by launch "
                "(self-collision) or an arch that runs a "
                "launch per stage")
        if self._diverged is not None:
            raise self._diverged
        if plan is None:
            many = self._many_per_launch
        else:
            many = plan == "many steps"
        self._stepper.take_settings(self.integrator)   # its run-time options (pool.py's copy)
        try:
            if many:
                self._step_many(n)
            elif plan is None and self._team_head is not None:
                self._step_teamed(n)
            else:
                for _ in range(n):
                    self._step_once()
        except CrushedContact as err:
            self._diverged = SimulationDiverged(
                err.step, (err.step + 1) * self.dt, self.dt,
                stable_dt(self.cloth, self.integrator, self.forces.drag, self.model.pinned),
                self.integrator.name, str(err))
            raise self._diverged from err
        finally:
            self.integrator.copy_reports(self._stepper)
        bad = int(self.state.first_bad_step[None])
        if bad != NO_BAD_STEP:
            self._diverged = SimulationDiverged(
                bad, (bad + 1) * self.dt, self.dt,
                stable_dt(self.cloth, self.integrator, self.forces.drag, self.model.pinned),
                self.integrator.name, self._divergence_reason(bad))
            raise self._diverged

    def _divergence_reason(self, bad: int) -> str | None:
        """Why step `bad` was flagged when it was a tear avalanche; None for the default."""
        if self.tearing is None:
            return None
        springs = int(np.sum(self.spring_torn_step() == bad))
        faces = int(np.sum(self.face_torn_step() == bad))
        torn = (f"{springs} springs" if springs else "") + (" and " if springs and faces else "")
        torn += f"{faces} triangles" if faces else ""
        x = self.positions()
        if torn and np.isfinite(x).all() and np.abs(x).max() <= float(self.state.limit):
            return (f"{torn} tore in that step, stretched more than "
                    f"{RUNAWAY_STRAIN:g} rest lengths past the tear strain (a step this large "
                    "explodes and tearing hides it)")
        return None

    def _check_runtime(self) -> None:
        """Raise StaleSimulation if ti_cloth.init ran again after this simulation was built."""
        if self._runtime != backend.generation():
            raise StaleSimulation()

    def _step_many(self, n: int) -> None:
        """n steps in few launches (stepping.py), until one diverges; a step in which a
        handle lets go runs stage by stage."""
        while n > 0:
            ran = self.many_steps.run(self._stepper, self.model, self.state, self.forces,
                                      self.dt, self.step_count, n, self.handles)
            self.step_count += ran
            n -= ran
            if n == 0 or self.state.first_bad_step[None] != NO_BAD_STEP:
                return   # Simulation.step reads the flag again: a diverged step is reported
            self._step_once()
            n -= 1

    def _step_teamed(self, n: int) -> None:
        """n steps, each the integrator and the stages before self-collision in one team
        launch (stepping.py), then self-collision and the stages after it launch by launch:
        the order of STEP_ORDER, the same bits as _step_once. A step in which a handle lets
        go runs stage by stage."""
        for _ in range(n):
            for stage in self._tail:
                if stage in self._before:
                    stage.before_step(self.state, self.time)
            self._list_for_solve()
            if self.many_steps.run(self._stepper, self.model, self.state, self.forces, self.dt,
                                   self.step_count, 1, self.handles, run_length=n) == 0:
                self._step_once()
                continue
            self.step_count += 1
            for stage in self._tail:
                stage.after_step(self.model, self.state, self.time, self.dt,
                                 self.step_count - 1)

    def _step_once(self) -> None:
        """One step, launch by launch: the stages of STEP_ORDER this simulation has."""
        for stage in self._before:
            stage.before_step(self.state, self.time)
        self._list_for_solve()
        self._stepper.step(self.model, self.state, self.dt, self.forces, self.step_count)
        self.step_count += 1
        for stage in self._stages.values():
            stage.after_step(self.model, self.state, self.time, self.dt, self.step_count - 1)

    def _list_for_solve(self) -> None:
        """SelfCollision.in_solve: the list for this step's predicted path, and the force
        settings that carry it into the integrator's passes (new ones when the list grew:
        its kernels compile again)."""
        if not self._in_solve:
            return
        stage, colliders = self.self_collision, self.colliders
        stage.list_for_solve(self.model, self.state, self.dt, self.forces.gravity,
                             self.step_count)
        met = colliders if colliders is not None and not colliders.animated else None
        if met is not None and met.moving:       # where its stage puts it: the passes meet it
            met.place((self.step_count + 1) * self.dt, self.dt)   # its after_step time
        if self.forces.contact is None or self.forces.contact[1] is not stage.candidates:
            self.forces = POOL.keep(dataclasses.replace(
                self.forces, contact=(stage, stage.candidates, met)))

    @property
    def many_steps(self) -> stepping.ManySteps | None:
        """The plan that runs steps in few launches (step(n > 1), and every step of an
        integrator that is not fused); with self-collision, the one that runs each step's
        integrator and the stages before self-collision in one launch; None when steps go
        launch by launch."""
        if self._team_head is None:
            return None
        key = ("many_steps", self._team_head.get("tearing"), self.integrator.fused,
               tuple(self._team_head))
        if key not in self._lent:
            self._lent[key] = stepping.ManySteps(stepping.TeamStages(
                {name: stage.launched for name, stage in self._team_head.items()},
                self.integrator.fused))
        return self._lent[key]

    def stage(self, name: str):
        """The object that runs stage `name` of STEP_ORDER (stages.py) in this simulation's
        steps, None when it has no such stage; ValueError for a name not in STEP_ORDER."""
        require(name in STEP_ORDER[1:], "stage", name, f"one of {STEP_ORDER[1:]}")
        return self._stages.get(name)

    def positions(self) -> np.ndarray:
        """Particle positions [m], (N, 3) float64 copy."""
        self._check_runtime()
        return self.state.read(State.POSITION).astype(np.float64, copy=False)   # a fresh array

    def self_contacts(self, active: bool = True) -> SelfContacts:
        """Self-collision's pairs after the last step: those in contact in any of its passes, or
        (active=False) every candidate pair it watches. ValueError without self-collision."""
        self._check_runtime()
        require(self.self_collision is not None, "self_collision", None,
                "a SelfCollision for self_contacts()")
        return self.self_collision.pairs(active)

    def candidate_lists(self) -> dict[str, tuple[int, int]]:
        """How the animated colliders' candidate lists fare: {"particles": (overflowed,
        made), "edges": (...)} for the lists of the particles and (edge contact) of the
        cloth's edges. A list overflows when more than its room of a body's triangles are
        within reach of its element, which then traverses the body's hierarchy every step
        until its next list: the same answers at a traversal's cost (contact/colliders/
        candidate_lists.py). {} without an animated collider. Self-collision's list grows
        instead: self_contacts().grown."""
        self._check_runtime()
        if self.colliders is None or not self.colliders.animated:
            return {}
        lists = {"particles": self.colliders.bodies.lists.overflowed()}
        if self.colliders.edge_contact:
            lists["edges"] = self.colliders.edges.lists.overflowed()
        return lists

    def velocities(self) -> np.ndarray:
        """Particle velocities [m/s], (N, 3) float64 copy."""
        self._check_runtime()
        return self.state.read(State.VELOCITY).astype(np.float64, copy=False)   # a fresh array

    def set_positions(self, positions) -> None:
        """Overwrite positions [m] (N, 3); Verlet-type history restarts from the velocities."""
        self._check_runtime()
        x = as_array("positions", positions, np.float64, (self.cloth.particle_count, 3))
        self.state.write(State.POSITION, x)
        self.state.prev_valid = False

    def set_velocities(self, velocities) -> None:
        """Overwrite velocities [m/s] (N, 3); Verlet-type history restarts from them."""
        self._check_runtime()
        v = as_array("velocities", velocities, np.float64, (self.cloth.particle_count, 3))
        self.state.write(State.VELOCITY, v)
        self.state.prev_valid = False

    def spring_alive(self) -> np.ndarray:
        """(S,) bool: springs not torn."""
        self._check_runtime()
        return self.state.spring_alive.to_numpy()[: self.cloth.spring_count].astype(bool)

    def torn_springs(self) -> np.ndarray:
        """Indices of torn springs, in spring order."""
        return np.flatnonzero(~self.spring_alive())

    @property
    def torn_count(self) -> int:
        """How many springs have torn."""
        return len(self.torn_springs())

    def spring_torn_step(self) -> np.ndarray:
        """(S,) int: the index of the step in which each spring tore, -1 while it is intact
        (tear statistics: when and in what order the cloth came apart)."""
        self._check_runtime()
        return self.state.spring_torn_step.to_numpy()[: self.cloth.spring_count].astype(np.int64)

    def face_alive(self) -> np.ndarray:
        """(F,) bool: a Fabric's triangles not torn."""
        self._check_runtime()
        return self.state.face_alive.to_numpy()[: self.cloth.face_count].astype(bool)

    def face_torn_step(self) -> np.ndarray:
        """(F,) int: the step in which each Fabric triangle tore, -1 while it is intact."""
        self._check_runtime()
        return self.state.face_torn_step.to_numpy()[: self.cloth.face_count].astype(np.int64)

    def torn_triangles(self) -> np.ndarray:
        """Indices of mesh triangles that lost an edge spring or, a Fabric's, tore (for a
        renderer to drop)."""
        torn = np.zeros(self.cloth.mesh.triangle_count, bool)
        torn[torn_triangles(self.cloth.triangle_edge_spring, ~self.spring_alive())] = True
        face = self.cloth.triangle_face
        torn[face >= 0] |= ~self.face_alive()[face[face >= 0]]
        return np.flatnonzero(torn)

    def pinned(self) -> np.ndarray:
        """(N,) bool: particles the integrator does not move now (the cloth's pins and the
        particles of every handle still holding)."""
        return self.model.pinned.copy()

    def collider_shapes(self) -> tuple:
        """The colliders where their paths have them at the current time (Collider.placed)."""
        if self.colliders is None:
            return ()
        return tuple(c.placed(self.time) for c in self.colliders.colliders)

    def collider_distance(self, points) -> tuple[np.ndarray, np.ndarray]:
        """(distance [m] from each point (N, 3) [m] to the nearest collider surface as the
        collision stage measures it (negative inside; a shell mesh gives the unsigned
        distance, an animated mesh the exact distance, signed when it is closed), shape (N,);
        that collider's outward normal, shape (N, 3)) at the current time. Without
        colliders: infinite distances, zero normals."""
        points = as_array("points", points, np.float64, (None, 3))
        if self.colliders is None:
            return np.full(len(points), np.inf), np.zeros((len(points), 3))
        self._check_runtime()
        distance, normal = self.colliders.distance(points, self.time)
        nearest = np.argmin(distance, axis=1)
        rows = np.arange(len(points))
        return distance[rows, nearest], normal[rows, nearest]

    def energy(self) -> dict[str, float]:
        """{"kinetic", "gravity", "spring", "spring_stretch", "spring_shear", "spring_bend",
        "total"} [J]; torn springs and triangles hold no energy."""
        return energies(self.cloth, self.positions(), self.velocities(), self.forces.gravity,
                        self.spring_alive(), self.face_alive(), self.model.isometric)

    def stable_dt(self) -> float:
        """Predicted largest stable step [s] of this simulation's integrator."""
        return stable_dt(self.cloth, self.integrator, self.forces.drag, self.model.pinned)

    def __repr__(self) -> str:
        return (f"Simulation({self.cloth!r}, integrator={self.integrator!r}, dt={self.dt}, "
                f"time={self.time:.6g})")


def _check_fabric_integrator(integrator) -> None:
    """A Fabric's elements run on the integrators with runs_fabric: refuse the rest by name
    rather than ignore the elements."""
    able = sorted(name for name, cls in INTEGRATORS.items() if cls.runs_fabric)
    require(integrator.runs_fabric, "integrator", integrator.name,
            f"one of {able} for a body made of a Fabric (pbd's stiffness is a fraction of "
            "a correction per iteration, not a modulus: xpbd is pbd with the Fabric's "
            "moduli as compliances)")


def _from_positional(positional: tuple, options: dict) -> dict:
    """The options with `positional` (the pre-keyword-only form, in OPTIONS order) filled in,
    with a DeprecationWarning; TypeError for too many or for an option given twice."""
    warnings.warn("Simulation's options are keyword-only (Simulation(cloth, integrator=..., "
                  "dt=...)); passing them by position stops working in the next release",
                  DeprecationWarning, stacklevel=3)
    if len(positional) > len(OPTIONS):
        raise TypeError(f"Simulation takes at most {len(OPTIONS)} options after the cloth, got "
                        f"{len(positional)}")
    defaults = Simulation.__init__.__kwdefaults__
    for name, value in zip(OPTIONS, positional):
        if options[name] is not defaults[name]:
            raise TypeError(f"Simulation got two values for option {name!r}")
        options[name] = value
    return options


def _prefixed(arrays: dict, prefix: str) -> dict:
    """The entries of `arrays` whose keys start with `prefix`, without it."""
    return {k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)}
