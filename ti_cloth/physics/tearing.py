"""Tearable cloth (Stuyck 4.5): springs stretched too far are removed; so are a Fabric's
triangles with an edge stretched too far, and with them the bending of the hinges beside
them (the Fabric terms of energies/ read face_alive)."""


import warnings
from dataclasses import dataclass

import numpy as np
import taichi as ti

from ..inputs.validation import finite_number
from ..runtime import backend, plan
from ..runtime.plan import ITEM, NOW, STATE, Loop, Phase


@backend.kernel_argument
@dataclass(frozen=True, init=False)
class Tearing:
    """A spring tears when |x_i - x_j| > (1 + strain) * rest length (Stuyck 4.5).

    strain: tear strain, > 0 (0.5 = tears at 150 % of its rest length). Springs of zero rest
        length have no strain and never tear. (`stretch=` is its deprecated name.)
    """

    strain: float = 0.5

    def __init__(self, strain: float = 0.5, *, stretch: float | None = None):
        if stretch is not None:
            warnings.warn("Tearing(stretch=) is now Tearing(strain=)", DeprecationWarning,
                          stacklevel=2)
            strain = stretch
        object.__setattr__(self, "strain", finite_number("Tearing.strain", strain, 0.0,
                                                         strict=True))

    @property
    def stretch(self) -> float:
        """Deprecated name of `strain`."""
        warnings.warn("Tearing.stretch is now Tearing.strain", DeprecationWarning, stacklevel=2)
        return self.strain

    def phases(self, model, forces, work) -> tuple:
        """The tearing stage as phases (runtime/plan.py): every spring's and every Fabric
        triangle's test (tear_spring, tear_face);
        `work` is this Tearing (its strain a compile-time constant of the pooled copy a
        simulation passes: pool.py)."""
        loops = ()
        if model.spring_count:
            loops += (Loop(model.spring_count, tear_spring, model, STATE, work, ITEM, NOW),)
        if model.face_count:
            loops += (Loop(model.face_count, tear_face, model, STATE, work, ITEM, NOW),)
        return (Phase(*loops),)

    @property
    def launched(self):
        """The object a many-steps launch runs this stage's phases on: itself (stages.py)."""
        return self

    def after_step(self, model, state, t: float, dt: float, step_index: int) -> None:
        """The tearing stage of a step (stages.STEP_ORDER), a launch of its phases."""
        plan.run(self, model, state, None, self, dt, step_index, False)


# A spring found stretched more than RUNAWAY_STRAIN beyond its tear strain has not torn: the
# step has exploded. Under a stable step a spring's strain grows by far less than its rest
# length per step (the largest relative speed x dt), so it tears just past its tear strain
# (tearing demo: at most 0.03 past it at 0.5 and 0.95 x the stable step); tears avalanching out
# of an unstable step overshoot by many rest lengths (0.26 at 1.2 x, over 1 at 3 x). Tearing would
# otherwise hide the blow-up: the torn pieces fly apart, finite, for ever.
RUNAWAY_STRAIN = 0.5


@ti.func
def tear_spring(model: ti.template(), state: ti.template(), tearing: ti.template(), s,
                now: ti.template()):
    """Remove spring s if intact and longer than (1 + strain) x rest; record the step it tore.
    A tear more than RUNAWAY_STRAIN past the tear strain flags the step as diverged
    (state.first_bad_step)."""
    rest = model.spring_rest_length[s]
    if state.spring_alive[s] != 0 and rest > 0:
        i, j = model.spring_indices[s][0], model.spring_indices[s][1]
        length = (state.particle_position[i] - state.particle_position[j]).norm()
        if length > (1.0 + tearing.strain) * rest:
            state.spring_alive[s] = ti.i8(0)
            state.spring_torn_step[s] = now.step
            if length > (1.0 + tearing.strain + RUNAWAY_STRAIN) * rest:
                ti.atomic_min(state.first_bad_step[None], now.step)


@ti.func
def tear_face(model: ti.template(), state: ti.template(), tearing: ti.template(), f,
              now: ti.template()):
    """Remove a Fabric's triangle f if intact and one of its edges is longer than
    (1 + strain) x its rest length; record the step; flag a runaway as tear_spring does."""
    if state.face_alive[f] != 0:
        corner = model.face_indices[f]
        rest = model.face_edge_rest[f]
        worst = 0.0
        for i in ti.static(range(3)):
            length = (state.particle_position[corner[(i + 1) % 3]]
                      - state.particle_position[corner[(i + 2) % 3]]).norm()
            if rest[i] > 0:
                worst = ti.max(worst, length / rest[i] - 1.0)
        if worst > tearing.strain:
            state.face_alive[f] = ti.i8(0)
            state.face_torn_step[f] = now.step
            if worst > tearing.strain + RUNAWAY_STRAIN:
                ti.atomic_min(state.first_bad_step[None], now.step)


def torn_triangles(triangle_edge_spring: np.ndarray, torn: np.ndarray) -> np.ndarray:
    """Indices of triangles with at least one torn edge spring (a renderer drops them).

    torn: boolean mask over springs.
    """
    edge = triangle_edge_spring
    padded = np.append(np.asarray(torn, bool), False)      # edge -1 (no spring) reads False
    hit = padded[np.where(edge >= 0, edge, len(padded) - 1)]
    return np.flatnonzero(hit.any(axis=1))
