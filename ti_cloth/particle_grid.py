"""A uniform grid of particles, rebuilt every step: the broad phase of contact between particles
and the triangles and edges they belong to (issue 18's self-collision).

Build (ParticleGrid.build): the bounding box of the positions (atomic min/max: exact in any
order, unlike a sum), cells of side >= `cell_size` over it, each particle's cell, the
count of particles per cell (integer atomics: exact), an exclusive prefix sum of the counts
(cell_start) and a fill of cell_particle in particle-index order, so a cell lists its particles
in increasing index and every query visits them in the same order on every run and thread count.
No hashing: a cell is a cell, so a query never sees a particle twice or a distant one. When the
box would need more than CELL_BUDGET cells per particle (a body blown apart), the cells grow until
it does not: queries stay correct, only slower.

Query: every particle within r <= cell_side of a point lies in the 3 x 3 x 3 block of cells
around the point's cell (cell_block, cell_range).
"""

import taichi as ti

from . import backend

CELL_BUDGET = 4     # grid cells per particle at most


@backend.kernel_argument
class ParticleGrid:
    """Cells of `particle_count` particles. After build(): cell_side [m] (>= the cell_size
    asked for), origin [m] and dims (cells per axis) in `frame` (origin xyz, side, dims xyz);
    cell_start (cells + 1,) and cell_particle (particle_count,): the particles of cell c are
    cell_particle[cell_start[c]:cell_start[c + 1]], in increasing index."""

    def __init__(self, particle_count: int):
        self.particle_count = n = particle_count
        self.cell_capacity = CELL_BUDGET * max(n, 1)
        real = backend.real()
        fields = backend.FieldGroup()
        self.lower = fields.vector(3, real, ())
        self.upper = fields.vector(3, real, ())
        self.side = fields.scalar(real, ())
        self.dims = fields.vector(3, ti.i32, ())
        self.particle_cell = fields.scalar(ti.i32, n)
        self.cell_start = fields.scalar(ti.i32, self.cell_capacity + 1)
        self.cell_fill = fields.scalar(ti.i32, self.cell_capacity)
        self.cell_particle = fields.scalar(ti.i32, n)
        fields.finalize(self)

    @staticmethod
    def structure(particle_count: int) -> tuple:
        return ("ParticleGrid", particle_count)

    def load(self, particle_count: int) -> None:
        """Nothing is kept between builds."""

    def build(self, positions, cell_size: float) -> None:
        """Sort the particles at `positions` (a vector field of particle_count rows) into cells
        of side >= cell_size [m] > 0."""
        _bounds(self, positions)
        _sort(self, positions, cell_size)

    def cells(self) -> int:
        """Cells in use after the last build."""
        d = self.dims[None]
        return int(d[0]) * int(d[1]) * int(d[2])


@ti.kernel
def _bounds(grid: ti.template(), positions: ti.template()):
    for _ in range(1):
        grid.lower[None] = positions[0]
        grid.upper[None] = positions[0]
    for i in range(grid.particle_count):
        ti.atomic_min(grid.lower[None], positions[i])
        ti.atomic_max(grid.upper[None], positions[i])


@ti.kernel
def _sort(grid: ti.template(), positions: ti.template(), cell_size: float):
    for _ in range(1):
        extent = grid.upper[None] - grid.lower[None]
        side = cell_size
        dims = ti.max(ti.cast(ti.floor(extent / side), ti.i32) + 1, 1)
        # Grow the cells until the box needs at most cell_capacity of them (float volume:
        # the product of int dims could overflow).
        while ti.cast(dims[0], ti.f64) * dims[1] * dims[2] > grid.cell_capacity:
            side *= 2.0
            dims = ti.max(ti.cast(ti.floor(extent / side), ti.i32) + 1, 1)
        grid.side[None] = side
        grid.dims[None] = dims
    cells = grid.dims[None][0] * grid.dims[None][1] * grid.dims[None][2]
    for c in range(cells + 1):
        grid.cell_start[c] = 0
    for i in range(grid.particle_count):
        c = cell_index(grid, cell_of(grid, positions[i]))
        grid.particle_cell[i] = c
        ti.atomic_add(grid.cell_start[c + 1], 1)
    for _ in range(1):                                   # exclusive prefix sum, serial
        for c in range(cells):
            grid.cell_start[c + 1] += grid.cell_start[c]
            grid.cell_fill[c] = grid.cell_start[c]
    for _ in range(1):                                   # fill in particle order, serial
        for i in range(grid.particle_count):
            c = grid.particle_cell[i]
            grid.cell_particle[grid.cell_fill[c]] = i
            grid.cell_fill[c] += 1


@ti.func
def cell_of(grid: ti.template(), x):
    """Integer cell coordinates of point x, clamped to the grid."""
    cell = ti.cast(ti.floor((x - grid.lower[None]) / grid.side[None]), ti.i32)
    return ti.math.clamp(cell, 0, grid.dims[None] - 1)


@ti.func
def cell_index(grid: ti.template(), cell):
    """Linear index of integer cell coordinates (x fastest)."""
    d = grid.dims[None]
    return cell[0] + d[0] * (cell[1] + d[1] * cell[2])


@ti.func
def cell_block(grid: ti.template(), x):
    """(lo, hi): the inclusive integer bounds of the 3 x 3 x 3 block of cells around x's cell,
    clipped to the grid: every particle within one cell side of x is in it."""
    cell = cell_of(grid, x)
    return ti.max(cell - 1, 0), ti.min(cell + 1, grid.dims[None] - 1)


@ti.func
def cell_range(grid: ti.template(), cell):
    """(begin, end) into cell_particle of the particles in the cell at integer coordinates."""
    c = cell_index(grid, cell)
    return grid.cell_start[c], grid.cell_start[c + 1]

