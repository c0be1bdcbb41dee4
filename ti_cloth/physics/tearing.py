"""Tearable cloth (Stuyck 4.5): springs stretched too far are removed."""


import warnings
from dataclasses import dataclass

import numpy as np
import taichi as ti

from ..runtime import backend, plan
from ..runtime.plan import Loop, Phase
from ..runtime.validation import finite_number


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
        """The tearing stage as phases (runtime/plan.py): every spring's test (tear_spring);
        `work` is this Tearing (its strain a compile-time constant of the pooled copy a
        simulation passes: pool.py)."""
        return (Phase(Loop(model.spring_count, tear_spring)),)

    def after_step(self, model, state, t: float, dt: float, step_index: int) -> None:
        """The tearing stage of a step (simulation.STEP_ORDER), a launch of its phases."""
        plan.run(self, model, state, None, self, dt, step_index, False)


# A spring found stretched more than RUNAWAY_STRAIN beyond its tear strain has not torn: the
# step has exploded. Under a stable step a spring's strain grows by far less than its rest
# length per step (the largest relative speed x dt), so it tears just past its tear strain
# (tearing demo: at most 0.03 past it at 0.5 and 0.95 x the stable step); tears avalanching out
# of an unstable step overshoot by many rest lengths (0.26 at 1.2 x, over 1 at 3 x). Tearing would
# otherwise hide the blow-up: the torn pieces fly apart, finite, for ever.
RUNAWAY_STRAIN = 0.5


@ti.func
def tear_spring(model: ti.template(), state: ti.template(), forces: ti.template(),
                tearing: ti.template(), stages: ti.template(), s, now: ti.template()):
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


def torn_triangles(triangle_edge_spring: np.ndarray, torn: np.ndarray) -> np.ndarray:
    """Indices of triangles with at least one torn edge spring (a renderer drops them).

    torn: boolean mask over springs.
    """
    edge = triangle_edge_spring
    padded = np.append(np.asarray(torn, bool), False)      # edge -1 (no spring) reads False
    hit = padded[np.where(edge >= 0, edge, len(padded) - 1)]
    return np.flatnonzero(hit.any(axis=1))
