"""Simulation: the step loop, scripted handles, the divergence guard and diagnostics."""


from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import taichi as ti

from . import backend, stepping
from . import tearing as tearing_module
from ._validate import as_array, finite_number, require
from .colliders import ColliderSet, resolve_collisions
from .errors import SimulationDiverged
from .forces import ForceSettings, energies
from .integrators import make_integrator
from .model import Model
from .stability import auto_dt, stable_dt
from .strain_limit import StrainLimit, StrainLimiter
from .state import NO_BAD_STEP, copy_positions
from .tearing import Tearing, torn_triangles
from .topology import Cloth
from .wind import WindField


@dataclass(frozen=True)
class Handle:
    """Particles moved along a scripted path (the lecture's "click a particle and pull it").

    particles: indices of the particles the handle holds; they become pinned (inverse mass 0).
    path: t [s] -> displacement [m] from their rest positions, shape (3,) (all move together)
        or (len(particles), 3).
    """

    particles: Sequence[int]
    path: Callable[[float], object]

    def __post_init__(self):
        object.__setattr__(self, "particles", as_array("Handle.particles", self.particles,
                                                       np.int64, (None,)))
        require(len(self.particles) > 0, "Handle.particles", [], "at least one particle index")
        require(callable(self.path), "Handle.path", self.path, "a callable t -> displacement")


@ti.kernel
def _move_handles(state: ti.template(), index: ti.types.ndarray(), target: ti.types.ndarray(),
                  dt: float):
    """Put held particles on their targets; velocity = displacement / dt so springs damp right."""
    for h in range(index.shape[0]):
        i = index[h]
        x_old = state.particle_position[i]
        x_new = ti.Vector([target[h, 0], target[h, 1], target[h, 2]])
        state.particle_prev_position[i] = x_old
        state.particle_position[i] = x_new
        state.particle_velocity[i] = (x_new - x_old) / dt


class Simulation:
    """Advance a Cloth in time with one integrator and fixed step dt.

    cloth: the body. integrator: a name from ti_cloth.INTEGRATORS or an Integrator instance.
    dt: step [s], > 0, or "auto": half the predicted stable step, at most 1/240 s
        (stability.auto_dt; ValueError if no stable step exists).
    gravity: [m/s^2], any vector. drag: uniform air drag [1/s], >= 0.
    tearing: None (off: the tear kernel is never compiled nor launched), a tear strain
        (float) or a Tearing.
    handles: scripted particles (Handle); their particles are pinned.
    colliders: Plane, Sphere, Box, Capsule objects (none: the collision kernels are never
        compiled nor launched).
    strain_limit: None (off: never compiled nor launched) or a StrainLimit (Provot 1995).
    position_limit: the divergence guard flags any |coordinate| beyond this [m].

    Each step: the integrator (wind held at its value at the step start), then strain limiting,
    then collisions (so nothing ends inside a collider), then handles, then tearing.
    """

    def __init__(self, cloth: Cloth, integrator="symplectic_euler", dt: float = 1e-3,
                 gravity=(0.0, -9.81, 0.0), drag: float = 0.0, wind=None, tearing=None,
                 handles: Sequence[Handle] = (), colliders=(), strain_limit=None,
                 position_limit: float = 1e6):
        require(isinstance(cloth, Cloth), "cloth", cloth, "a ti_cloth.Cloth")
        self.cloth = cloth
        self.integrator = make_integrator(integrator)
        auto = isinstance(dt, str) and dt == "auto"
        self.dt = None if auto else finite_number("dt", dt, 0.0, strict=True, unit="s")
        gravity = as_array("gravity", gravity, np.float64, (3,))
        drag = finite_number("drag", drag, 0.0, unit="1/s")
        if tearing is not None and not isinstance(tearing, Tearing):
            tearing = Tearing(stretch=tearing)
        self.tearing = tearing
        self.handles = tuple(handles)
        for h in self.handles:
            require(isinstance(h, Handle), "handles", h, "Handle objects")
            bad = h.particles[(h.particles < 0) | (h.particles >= cloth.particle_count)]
            require(len(bad) == 0, "Handle.particles", bad.tolist(),
                    f"particle indices in [0, {cloth.particle_count - 1}]")
        self.wind = WindField(wind, cloth) if wind is not None else None
        self.forces = ForceSettings(gravity=tuple(gravity), drag=drag, tearing=tearing is not None,
                                    wind=self.wind)

        pinned = cloth.pinned.copy()
        if self.handles:
            self._handle_index = np.concatenate([h.particles for h in self.handles]).astype(np.int32)
            pinned[self._handle_index] = True
        self.model = Model(cloth, pinned=pinned)
        if auto:
            self.dt = auto_dt(cloth, self.integrator, drag, pinned)
        self.state = self.model.state()
        self.state.position_limit[None] = finite_number("position_limit", position_limit, 0.0,
                                                        strict=True, unit="m")
        require(strain_limit is None or isinstance(strain_limit, StrainLimit), "strain_limit",
                strain_limit, "None or a StrainLimit")
        self.strain_limiter = (StrainLimiter(strain_limit, cloth.particle_count)
                               if strain_limit is not None and cloth.spring_count else None)
        colliders = tuple(colliders)
        self.colliders = ColliderSet(colliders, cloth.particle_count) if colliders else None
        self.step_count = 0
        self._diverged: SimulationDiverged | None = None
        self._place_handles_at_start()
        # Many steps per launch on the CPU when nothing but tearing acts between steps; made
        # on the first step(n > 1), so a simulation stepped one at a time allocates nothing.
        self._many_per_launch = (self.integrator.fused and backend.config().arch == "cpu"
                                 and self.wind is None and not self.handles
                                 and self.colliders is None and self.strain_limiter is None)
        self._many_steps_plan = None

    def restart(self, dt: float | None = None) -> None:
        """Back to time 0: rest positions, at rest, every spring intact, handles and colliders
        at their start, the divergence flag cleared; `dt` [s] replaces the step if given.
        The compiled kernels are kept, so a sweep over dt compiles once."""
        if dt is not None:
            self.dt = finite_number("dt", dt, 0.0, strict=True, unit="s")
        self.state.reset(self.model.particle_rest_position)
        self.step_count = 0
        self._diverged = None
        if self.colliders is not None:
            self.colliders.place(0.0)
        self._place_handles_at_start()

    def _place_handles_at_start(self) -> None:
        if self.handles:
            self._apply_handles(0.0)
            self.state.particle_velocity.fill(0)

    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return self.step_count * self.dt

    def step(self, n: int = 1) -> None:
        """Advance n steps of dt. Raises SimulationDiverged at the first step whose result is
        not finite; after that the simulation refuses to continue."""
        require(isinstance(n, (int, np.integer)) and n >= 0, "n", n, "an int >= 0")
        if self._diverged is not None:
            raise self._diverged
        if self._many_per_launch and n > 1:
            self.step_count += self._many_steps.run(
                self.integrator, self.model, self.state, self.forces, self.dt, self.step_count, n,
                self.tearing.stretch if self.tearing is not None else 0.0)
            n = 0
        for _ in range(n):
            if self.colliders is not None:
                copy_positions(self.state, self.colliders.step_start)
            if self.wind is not None:
                self.wind.update(self.time)
            self.integrator.step(self.model, self.state, self.dt, self.forces, self.step_count)
            self.step_count += 1
            if self.strain_limiter is not None:
                self.strain_limiter.apply(self.model, self.state, self.dt, self.forces.tearing)
            if self.colliders is not None:
                if self.colliders.moving:
                    self.colliders.place(self.time, self.dt)
                resolve_collisions(self.model, self.state, self.colliders, self.dt)
            if self.handles:
                self._apply_handles(self.time)
            if self.tearing is not None:
                tearing_module.tear_springs(self.model, self.state, self.tearing.stretch,
                                            self.step_count - 1)
        bad = int(self.state.first_bad_step[None])
        if bad != NO_BAD_STEP:
            self._diverged = SimulationDiverged(
                bad, (bad + 1) * self.dt, self.dt,
                stable_dt(self.cloth, self.integrator, self.forces.drag, self.model.pinned),
                self.integrator.name)
            raise self._diverged

    @property
    def _many_steps(self) -> stepping.ManySteps | None:
        """The plan that runs step(n > 1) in few launches, or None when steps go one by one."""
        if self._many_per_launch and self._many_steps_plan is None:
            self._many_steps_plan = stepping.ManySteps(self.model)
        return self._many_steps_plan

    def _apply_handles(self, t: float) -> None:
        targets = []
        for h in self.handles:
            offset = np.broadcast_to(np.asarray(h.path(t), np.float64), (len(h.particles), 3))
            targets.append(self.cloth.particle_position[h.particles] + offset)
        target = np.concatenate(targets)
        require(bool(np.isfinite(target).all()), f"Handle.path({t})", target, "finite displacements")
        _move_handles(self.state, self._handle_index, target.astype(backend.numpy_real()), self.dt)

    def positions(self) -> np.ndarray:
        """Particle positions [m], (N, 3) float64 copy."""
        return self.state.particle_position.to_numpy().astype(np.float64)

    def velocities(self) -> np.ndarray:
        """Particle velocities [m/s], (N, 3) float64 copy."""
        return self.state.particle_velocity.to_numpy().astype(np.float64)

    def set_positions(self, positions) -> None:
        """Overwrite positions [m] (N, 3); Verlet-type history restarts from the velocities."""
        x = as_array("positions", positions, np.float64, (self.cloth.particle_count, 3))
        self.state.particle_position.from_numpy(x.astype(backend.numpy_real()))
        self.state.prev_valid = False

    def set_velocities(self, velocities) -> None:
        """Overwrite velocities [m/s] (N, 3); Verlet-type history restarts from them."""
        v = as_array("velocities", velocities, np.float64, (self.cloth.particle_count, 3))
        self.state.particle_velocity.from_numpy(v.astype(backend.numpy_real()))
        self.state.prev_valid = False

    def spring_alive(self) -> np.ndarray:
        """(S,) bool: springs not torn."""
        return self.state.spring_alive.to_numpy()[: self.cloth.spring_count].astype(bool)

    def torn_springs(self) -> np.ndarray:
        """Indices of torn springs, in spring order."""
        return np.flatnonzero(~self.spring_alive())

    @property
    def torn_count(self) -> int:
        """How many springs have torn."""
        return len(self.torn_springs())

    def torn_triangles(self) -> np.ndarray:
        """Indices of triangles that lost an edge spring (for a renderer to drop)."""
        return torn_triangles(self.cloth.triangle_edge_spring, ~self.spring_alive())

    def energy(self) -> dict[str, float]:
        """{"kinetic", "gravity", "spring", "spring_stretch", "spring_shear", "spring_bend",
        "total"} [J]; torn springs hold no energy."""
        return energies(self.cloth, self.positions(), self.velocities(), self.forces.gravity,
                        self.spring_alive())

    def stable_dt(self) -> float:
        """Predicted largest stable step [s] of this simulation's integrator."""
        return stable_dt(self.cloth, self.integrator, self.forces.drag, self.model.pinned)

    def __repr__(self) -> str:
        return (f"Simulation({self.cloth!r}, integrator={self.integrator!r}, dt={self.dt}, "
                f"time={self.time:.6g})")
