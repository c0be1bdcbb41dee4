"""The broad phase of self-collision (particle_grid.py): the particles a query visits are exactly
the brute-force neighbours, each once, in a fixed order, on every run."""

import numpy as np
import pytest
import taichi as ti

from ti_cloth import backend
from ti_cloth.particle_grid import ParticleGrid, cell_block, cell_range


@ti.kernel
def _mark_neighbours(grid: ti.template(), positions: ti.template(), radius: float,
                     found: ti.types.ndarray()):
    """found[i, j] += 1 for every j the 3 x 3 x 3 block around x_i holds with |x_j - x_i| <= r."""
    for i in range(grid.particle_count):
        lo, hi = cell_block(grid, positions[i])
        for cz in range(lo[2], hi[2] + 1):
            for cy in range(lo[1], hi[1] + 1):
                for cx in range(lo[0], hi[0] + 1):
                    begin, end = cell_range(grid, ti.Vector([cx, cy, cz]))
                    for a in range(begin, end):
                        j = grid.cell_particle[a]
                        if (positions[j] - positions[i]).norm() <= radius:
                            found[i, j] += 1


def neighbours(points, radius):
    positions = ti.Vector.field(3, backend.real(), len(points))
    positions.from_numpy(points.astype(backend.numpy_real()))
    grid = ParticleGrid(len(points))
    grid.build(positions, radius)
    found = np.zeros((len(points), len(points)), np.int32)
    _mark_neighbours(grid, positions, radius, found)
    return grid, found


def clouds():
    rng = np.random.default_rng(7)
    uniform = rng.uniform(-1.0, 1.0, size=(400, 3))
    sheet = np.c_[rng.uniform(0, 1, 300), np.zeros(300), rng.uniform(0, 1, 300)]     # flat
    apart = np.concatenate([rng.normal(scale=0.01, size=(150, 3)),
                            1e4 + rng.normal(scale=0.01, size=(150, 3))])            # 1e4 m apart
    return {"uniform": (uniform, 0.3), "flat sheet": (sheet, 0.08), "blown apart": (apart, 0.01)}


@pytest.mark.parametrize("name", list(clouds()))
def test_a_query_visits_exactly_the_brute_force_neighbours_once(f64, name):
    points, radius = clouds()[name]
    grid, found = neighbours(points, radius)
    expected = np.linalg.norm(points[:, None] - points[None], axis=2) <= radius
    assert found.max() == 1, "no particle visited twice"
    np.testing.assert_array_equal(found == 1, expected)
    assert expected.sum() > 2 * len(points), "the clouds have neighbours besides themselves"
    assert grid.cells() <= 4 * len(points) and grid.side[None] >= radius


def test_cells_list_their_particles_once_in_increasing_index_and_rebuild_identically(f64):
    points, radius = clouds()["uniform"]
    grid, _ = neighbours(points, radius)
    start, order = grid.cell_start.to_numpy(), grid.cell_particle.to_numpy()
    cells = grid.cells()
    assert start[cells] == len(points) and sorted(order) == list(range(len(points)))
    for c in range(cells):
        assert (np.diff(order[start[c]:start[c + 1]]) > 0).all()
    again, _ = neighbours(points, radius)
    np.testing.assert_array_equal(again.cell_particle.to_numpy(), order)


def test_one_thread_and_two_sort_the_same():
    import ti_cloth as tc
    points, radius = clouds()["uniform"]
    results = []
    try:
        for threads in (1, 2):
            tc.init(arch="cpu", precision="f64", threads=threads)
            grid, found = neighbours(points, radius)
            results.append((grid.cell_start.to_numpy(), grid.cell_particle.to_numpy(), found))
    finally:
        tc.init(arch="cpu", precision="f64")
    for one, two in zip(*results):
        np.testing.assert_array_equal(one, two)
