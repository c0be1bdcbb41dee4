"""Per-particle strain for the strain colour map: how far the most stretched spring at each
particle is beyond its rest length — the quantity tearing (Stuyck 4.5) compares with its limit."""

import numpy as np
import taichi as ti

from ..inputs.validation import as_array, require
from ..runtime import backend
from .raster import ndarray_f32_1, ndarray_f32_2, ndarray_i32_1, ndarray_i32_2


@backend.kernel
def _max_spring_strain(position: ndarray_f32_2, springs: ndarray_i32_2, rest: ndarray_f32_1,
                       alive: ndarray_i32_1, strain: ndarray_f32_1):
    for i in range(strain.shape[0]):
        strain[i] = 0.0
    for s in range(springs.shape[0]):
        if alive[s] != 0 and rest[s] > 0:
            i, j = springs[s, 0], springs[s, 1]
            xi = ti.Vector([position[i, 0], position[i, 1], position[i, 2]])
            xj = ti.Vector([position[j, 0], position[j, 1], position[j, 2]])
            e = (xi - xj).norm() / rest[s] - 1.0
            ti.atomic_max(strain[i], e)     # a maximum does not depend on the order: deterministic
            ti.atomic_max(strain[j], e)


def vertex_strain(positions, spring_indices, rest_length, alive=None) -> np.ndarray:
    """(N,) float32: max over each particle's intact springs of |x_i - x_j| / rest - 1, floored
    at 0 (compression reads as unstretched). Springs of zero rest length are skipped."""
    x = as_array("positions", positions, np.float32, (None, 3))
    springs = as_array("spring_indices", spring_indices, np.int32, (None, 2))
    rest = as_array("rest_length", rest_length, np.float32, (len(springs),))
    alive = np.ones(len(springs), np.int32) if alive is None else \
        as_array("alive", alive, bool, (len(springs),)).astype(np.int32)
    if len(springs):
        require(springs.min() >= 0 and springs.max() < len(x), "spring_indices",
                (int(springs.min()), int(springs.max())), f"indices in [0, {len(x) - 1}]")
    strain = np.zeros(len(x), np.float32)
    if len(springs) and len(x):
        _max_spring_strain(x, springs, rest, alive, strain)
    return strain
