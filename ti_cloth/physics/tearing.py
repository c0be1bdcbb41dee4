"""Tearable cloth (Stuyck 4.5): springs stretched too far are removed."""


import warnings
from dataclasses import dataclass

import numpy as np
import taichi as ti

from ..runtime import backend
from ..runtime.validation import finite_number


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

    def after_step(self, model, state, t: float, dt: float, step_index: int) -> None:
        """The tearing stage of a step (simulation.STEP_ORDER)."""
        tear_springs(model, state, self.strain, step_index)


# A spring found stretched more than RUNAWAY_STRAIN beyond its tear strain has not torn: the
# step has exploded. Under a stable step a spring's strain grows by far less than its rest
# length per step (the largest relative speed x dt), so it tears just past its tear strain
# (tearing demo: at most 0.03 past it at 0.5 and 0.95 x the stable step); tears avalanching out
# of an unstable step overshoot by many rest lengths (0.26 at 1.2 x, over 1 at 3 x). Tearing would
# otherwise hide the blow-up: the torn pieces fly apart, finite, for ever.
RUNAWAY_STRAIN = 0.5


@backend.kernel
def tear_springs(model: ti.template(), state: ti.template(), strain: float, step: ti.i32):
    """Remove every intact spring longer than (1 + strain) x rest; record the step it tore."""
    tear_overstretched(model, state, strain, step, 0, model.spring_count)


@ti.func
def tear_overstretched(model: ti.template(), state: ti.template(), strain, step, begin, end):
    """tear_springs' loop over springs begin .. end - 1, for kernels that run whole steps
    (integrators/fused.py). A tear more than RUNAWAY_STRAIN past the tear strain flags the
    step as diverged (state.first_bad_step)."""
    for s in range(begin, end):
        rest = model.spring_rest_length[s]
        if state.spring_alive[s] != 0 and rest > 0:
            i, j = model.spring_indices[s][0], model.spring_indices[s][1]
            length = (state.particle_position[i] - state.particle_position[j]).norm()
            if length > (1.0 + strain) * rest:
                state.spring_alive[s] = ti.i8(0)
                state.spring_torn_step[s] = step
                if length > (1.0 + strain + RUNAWAY_STRAIN) * rest:
                    ti.atomic_min(state.first_bad_step[None], step)


def torn_triangles(triangle_edge_spring: np.ndarray, torn: np.ndarray) -> np.ndarray:
    """Indices of triangles with at least one torn edge spring (a renderer drops them).

    torn: boolean mask over springs.
    """
    edge = triangle_edge_spring
    hit = np.where(edge >= 0, torn[np.maximum(edge, 0)], False)
    return np.flatnonzero(hit.any(axis=1))
