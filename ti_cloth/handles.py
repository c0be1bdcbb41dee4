"""Scripted handles: particles moved along a path (the lecture's "click a particle and pull it",
headless). A handle's particles are pinned (inverse mass 0), so the integrators leave them alone;
after every step they are put where the path says, with the velocity of that move."""

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import taichi as ti

from . import backend, limits
from ._validate import as_array, require


@dataclass(frozen=True)
class Handle:
    """Particles moved along a scripted path.

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
def move_handles(state: ti.template(), index: ti.types.ndarray(), target: ti.types.ndarray(),
                 dt: float):
    """Put held particles on their targets; velocity = displacement / dt so springs damp right."""
    for h in range(index.shape[0]):
        i = index[h]
        x_old = state.particle_position[i]
        x_new = ti.Vector([target[h, 0], target[h, 1], target[h, 2]])
        state.particle_prev_position[i] = x_old
        state.particle_position[i] = x_new
        state.particle_velocity[i] = (x_new - x_old) / dt


class HandleSet:
    """The handles of one simulation: which particles they hold and where those rest.

    handles: Handle objects; rest_position: the body's rest positions [m], shape (N, 3).
    """

    def __init__(self, handles: Sequence[Handle], rest_position: np.ndarray):
        self.handles = tuple(handles)
        count = len(rest_position)
        for h in self.handles:
            require(isinstance(h, Handle), "handles", h, "Handle objects")
            bad = h.particles[(h.particles < 0) | (h.particles >= count)]
            require(len(bad) == 0, "Handle.particles", bad.tolist(),
                    f"particle indices in [0, {count - 1}]")
        self.index = np.concatenate([h.particles for h in self.handles]).astype(np.int32)
        self.rest_position = rest_position

    def pin(self, pinned: np.ndarray) -> np.ndarray:
        """`pinned` (N,) bool with every held particle added."""
        pinned = pinned.copy()
        pinned[self.index] = True
        return pinned

    def targets(self, t: float) -> np.ndarray:
        """Where the held particles belong at time t [m], shape (len(index), 3)."""
        targets = []
        for h in self.handles:
            offset = np.asarray(h.path(t))
            shape = (3,) if offset.shape == (3,) else (len(h.particles), 3)
            offset = as_array(f"Handle.path({t})", offset, np.float64, shape)
            targets.append(self.rest_position[h.particles] + offset)
        target = np.concatenate(targets)
        far = np.abs(target).max()
        require(far <= limits.COORDINATE.high, f"Handle.path({t})", far,
                f"displacements keeping particles at coordinates {limits.COORDINATE.text()}")
        return target

    def after_step(self, model, state, t: float, dt: float, step_index: int) -> None:
        """The handle stage of a step ending at time t (simulation.STEP_ORDER): the held
        particles to their targets, with the velocity of that move over dt [s]."""
        move_handles(state, self.index, self.targets(t).astype(backend.numpy_real()), dt)

    def place_at_start(self, model, state, dt: float) -> None:
        """Held particles at their t = 0 targets, at rest."""
        self.after_step(model, state, 0.0, dt, 0)
        state.particle_velocity.fill(0)
