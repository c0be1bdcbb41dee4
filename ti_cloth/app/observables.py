"""What a study can measure when cloth moves chaotically: the predictability horizon and the
observables that converge beyond it.

A cloth that buckles, folds or swings like a multiple pendulum amplifies any difference
between two runs exponentially: two converged references that differ in the last bits part
ways after a while (tests/test_chaos.py's chaotic string: rk4 f64 at 128 and 256 steps per
frame agree to 1e-9 of its size at 1 s and differ by 0.4 at 5 s; a perturbation of its start
by one rounding error grows to 0.2 by 5 s). No step, however small, gives a pointwise
reference there, so

- the study finds the horizon T*: the last sample time up to which the reference's own
  pointwise uncertainty (the change of its last halving, and the spread of references
  started from positions perturbed at the rounding level) stays within the reference
  tolerance, and measures pointwise errors up to T* only (`horizon`);
- beyond T* it measures observables: quantities of the whole cloth whose values converge
  when positions do not, or stay within the chaos of the motion. Chosen here: the total
  energy (the study's energy drift, a fraction of its scale: a first integral, or dissipated
  smoothly, it converges at every instant), and running means over the samples so far (the
  time averages a chaotic trajectory's statistics settle to, where its value at an instant
  does not) of the centre of mass and the bounding box (fractions of the cloth size) and of
  the mean and 99th percentile of the edges' strain |l - L| / L (`observables`). A run's
  observable error is the largest of their differences from the reference's. On the
  chaotic string, rk4 at 128 and 256 steps per frame differ by 0.42 of its size at 5.5 s,
  their running means by 0.011 and their energies by 7e-7 of its scale. The spread of the
  references started from perturbed positions is the level below which an observable's
  difference is the chaos of the motion, not error (`Reference.observable_spread`,
  study.py): a pinned 6 x 6 sheet flapping for 4 s has 8e-3 of it, and rk4 runs from 1/480
  to 1/1920 s all come within twice that.

Not chosen: momentum (for a pinned cloth it follows the centre of mass), the silhouette's
area (a raster of the projected triangles: its error floor is the raster's cell, and the
bounding box bounds it), and a drape's coefficient and fold count (defined at rest only,
where a settled drape's positions converge again and the pointwise errors of a study of
its last frames apply).
"""

from __future__ import annotations

import numpy as np

OBSERVABLES = ("centre x", "centre y", "centre z", "box low x", "box low y", "box low z",
               "box high x", "box high y", "box high z", "mean strain", "p99 strain")
ROUNDING = 2.0 ** -52      # a perturbation of the start at the rounding level (x cloth size)
STRAIN_PERCENTILE = 99


def edges(cloth) -> np.ndarray:
    """(E, 2) particle pairs whose strain the observables measure: a sheet's triangle edges,
    else (strings, hair, blocks) its springs of nonzero rest length."""
    if len(cloth.mesh.triangles):
        return cloth.mesh.edges()
    keep = np.asarray(cloth.spring_rest_length) > 0
    return np.asarray(cloth.spring_indices)[keep]


def observables(cloth, positions: np.ndarray, size: float) -> np.ndarray:
    """(samples, len(OBSERVABLES)): the running means over the samples so far of the centre
    of mass and the bounding box (fractions of `size` [m]) and of the edges' mean and 99th
    percentile strain, from the positions (samples, N, 3) [m] of every particle of `cloth`
    (the cloth at the resolution that produced them: the values compare across
    resolutions)."""
    mass = np.asarray(cloth.particle_mass, np.float64)
    centre = np.einsum("n,snk->sk", mass, positions) / mass.sum()
    low, high = positions.min(axis=1), positions.max(axis=1)
    pairs = edges(cloth)
    if len(pairs):
        rest = np.linalg.norm(cloth.rest_position[pairs[:, 0]]
                              - cloth.rest_position[pairs[:, 1]], axis=1)
        keep = rest > 0
        length = np.linalg.norm(positions[:, pairs[keep, 0]] - positions[:, pairs[keep, 1]],
                                axis=2)
        strain = np.abs(length / rest[keep] - 1.0)
        strains = np.stack([strain.mean(axis=1),
                            np.percentile(strain, STRAIN_PERCENTILE, axis=1)], axis=1)
    else:
        strains = np.zeros((len(positions), 2))
    values = np.concatenate([np.concatenate([centre, low, high], axis=1) / size, strains], axis=1)
    return np.cumsum(values, axis=0) / np.arange(1, len(values) + 1)[:, None]


def difference(a: np.ndarray, b: np.ndarray) -> float:
    """The largest difference between two observables' tables (observables), over samples
    and quantities: each a fraction of the cloth size or a strain."""
    return float(np.abs(a - b).max())


def horizon(times: np.ndarray, uncertainty: np.ndarray, level: float) -> int:
    """How many samples from the first have the reference's pointwise uncertainty (a fraction
    of the cloth size, per sample) within `level`: the samples up to the horizon T*."""
    beyond = np.flatnonzero(~(np.asarray(uncertainty) <= level))
    return int(beyond[0]) if len(beyond) else len(times)


def perturbed_start(sim, size: float, seed: int) -> None:
    """Move every free particle of `sim` by ROUNDING x size [m] along a random direction
    (seeded): a start that differs from the scene's by one rounding error per coordinate."""
    x = sim.positions()
    free = ~np.asarray(sim.pinned(), bool)
    rng = np.random.default_rng(seed)
    x[free] += size * ROUNDING * rng.normal(size=(int(free.sum()), 3))
    sim.set_positions(x)
