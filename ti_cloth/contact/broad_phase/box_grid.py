"""A uniform grid of boxes, rebuilt when self-collision lists its pairs: the broad phase between
the swept boxes of particles, triangles and edges (issue 18).

Items come in kinds (self-collision: particles, then edges), numbered one after the other;
each kind has cells of its own over the same grid, so one build and one set of compiled
kernels serve both, and a query visits only the kind it asks for.

Build (BoxGrid.build, after the owner has written each item's box into `lo` / `hi`): the
bounding box of all boxes (each block of BLOCK items reduced by one thread, then the blocks in
order: a max and a min are exact), cells of side >= `cell_size` over it, each item entered in
every cell its box meets (integer counts per cell, an exclusive prefix sum, then a serial fill
in item order), so a cell lists its items in increasing index and every query visits them in
the same order on every run and thread count. Each entry holds a copy of its item's box, so
that a query scans a cell's boxes front to back instead of reading them item by item (the
broad phase of self-collision was most of a pile's step: docs/performance.md), and the
first cell of that box, so that an item met in several cells is told apart without
computing its cells again (the cape's count of a list 10 % cheaper). No hashing: a
cell is a cell. When the box would need more than CELL_BUDGET cells per item, or the entries
more than ENTRY_BUDGET per item (a body blown apart, a particle flung far in one step), the
cells grow until they do not: queries stay exact, only slower.

Query (cell_box, box_cell_count, box_cell, cell_range, meets, first_shared): the items of a
kind whose boxes meet a query box are in that kind's cells the query box meets; an item met in
several of them is reported from the first cell the two share (the componentwise max of their
first cells), so exactly once.
"""

import numpy as np
import taichi as ti

from ...runtime import backend

CELL_BUDGET = 4     # grid cells per item at most
ENTRY_BUDGET = 8    # cell entries per item at most
BLOCK = 256         # items one thread reduces


@backend.kernel_argument
class BoxGrid:
    """Cells of axis-aligned boxes, `counts` items of each kind (kind k's items are numbered
    from sum(counts[:k])). The owner writes box i into lo[i], hi[i]; after build(): side [m]
    (>= the cell_size asked for), lower [m] (the grid's corner) and dims (cells per axis);
    cell_start and cell_item: the items of kind k whose boxes meet cell c are
    cell_item[cell_start[k C + c]:cell_start[k C + c + 1]] (C cells), in increasing index;
    entry_lo and entry_hi: the box of each entry's item, entry_first the first cell of it."""

    def __init__(self, *counts: int):
        self.kind_count = len(counts)
        self.kind_end = tuple(int(v) for v in np.cumsum(counts))
        self.item_count = n = sum(counts)
        self.cell_capacity = CELL_BUDGET * max(n, 1)
        self.entry_capacity = ENTRY_BUDGET * max(n, 1)
        self.block_count = -(-max(n, 1) // BLOCK)
        real = backend.real()
        fields = backend.FieldGroup()
        self.lo = fields.vector(3, real, max(n, 1))
        self.hi = fields.vector(3, real, max(n, 1))
        self.block_bounds = fields.vector(3, real, 2 * self.block_count)
        self.lower = fields.vector(3, real, ())
        self.upper = fields.vector(3, real, ())
        self.side = fields.scalar(real, ())
        self.dims = fields.vector(3, ti.i32, ())
        self.entries = fields.scalar(ti.i32, ())
        self.cell_start = fields.scalar(ti.i32, self.kind_count * self.cell_capacity + 1)
        self.cell_fill = fields.scalar(ti.i32, self.kind_count * self.cell_capacity)
        self.cell_item = fields.scalar(ti.i32, self.entry_capacity)
        self.entry_lo = fields.vector(3, real, self.entry_capacity)
        self.entry_hi = fields.vector(3, real, self.entry_capacity)
        self.entry_first = fields.vector(3, ti.i32, self.entry_capacity)
        fields.finalize(self)

    def build(self, cell_size: float) -> None:
        """Enter the boxes now in lo / hi into cells of side >= cell_size [m] > 0."""
        _bounds(self)
        side = cell_size
        while not (_layout(self, side) and _count(self) <= self.entry_capacity):
            side *= 2.0
        _fill(self)

    def cells(self) -> int:
        """Cells in use after the last build."""
        d = self.dims[None]
        return int(d[0]) * int(d[1]) * int(d[2])


@backend.kernel
def _bounds(grid: ti.template()):
    for b in range(grid.block_count):
        begin = b * BLOCK
        lo, hi = grid.lo[begin], grid.hi[begin]
        for i in range(begin + 1, ti.min(begin + BLOCK, grid.item_count)):
            lo, hi = ti.min(lo, grid.lo[i]), ti.max(hi, grid.hi[i])
        grid.block_bounds[2 * b] = lo
        grid.block_bounds[2 * b + 1] = hi
    for _ in range(1):
        grid.lower[None] = grid.block_bounds[0]
        grid.upper[None] = grid.block_bounds[1]
        for b in range(1, grid.block_count):
            grid.lower[None] = ti.min(grid.lower[None], grid.block_bounds[2 * b])
            grid.upper[None] = ti.max(grid.upper[None], grid.block_bounds[2 * b + 1])


@backend.kernel
def _layout(grid: ti.template(), side: float) -> ti.i32:
    """Cells of `side` over the bounds: 1 if they fit in cell_capacity (float volume: the
    product of int dims could overflow), else 0."""
    extent = grid.upper[None] - grid.lower[None]
    dims = ti.max(ti.cast(ti.floor(extent / side), ti.i32) + 1, 1)
    grid.side[None] = side
    grid.dims[None] = dims
    return ti.select(ti.cast(dims[0], ti.f64) * dims[1] * dims[2] <= grid.cell_capacity, 1, 0)


@backend.kernel
def _count(grid: ti.template()) -> ti.i32:
    """cell_start[k C + c + 1] = how many boxes of kind k meet cell c (integer atomics:
    exact); the entries."""
    d = grid.dims[None]
    cells = d[0] * d[1] * d[2]
    for c in range(grid.kind_count * cells + 1):
        grid.cell_start[c] = 0
    grid.entries[None] = 0
    for i in range(grid.item_count):
        base = _kind(grid, i) * cells + 1
        first, last = cell_box(grid, grid.lo[i], grid.hi[i])
        for k in range(box_cell_count(first, last)):
            ti.atomic_add(grid.cell_start[base + cell_index(grid, box_cell(first, last, k))], 1)
        ti.atomic_add(grid.entries[None], box_cell_count(first, last))
    return grid.entries[None]


@ti.func
def _kind(grid: ti.template(), i):
    kind = 0
    for k in ti.static(range(grid.kind_count - 1)):
        if i >= grid.kind_end[k]:
            kind = k + 1
    return kind


@backend.kernel
def _fill(grid: ti.template()):
    """Exclusive prefix sum of the counts, then each item entered in its cells in item order
    (serial: a cell lists its items in increasing index), with its box."""
    d = grid.dims[None]
    cells = d[0] * d[1] * d[2]
    for _ in range(1):
        for c in range(grid.kind_count * cells):
            grid.cell_start[c + 1] += grid.cell_start[c]
            grid.cell_fill[c] = grid.cell_start[c]
        for i in range(grid.item_count):
            base = _kind(grid, i) * cells
            first, last = cell_box(grid, grid.lo[i], grid.hi[i])
            for k in range(box_cell_count(first, last)):
                c = base + cell_index(grid, box_cell(first, last, k))
                a = grid.cell_fill[c]
                grid.cell_item[a] = i
                grid.entry_lo[a] = grid.lo[i]
                grid.entry_hi[a] = grid.hi[i]
                grid.entry_first[a] = first
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
def cell_box(grid: ti.template(), lo, hi):
    """(first, last): the inclusive integer bounds of the cells that meet the box [lo, hi],
    clipped to the grid."""
    return cell_of(grid, lo), cell_of(grid, hi)


@ti.func
def box_cell_count(first, last):
    """How many cells the inclusive integer bounds (first, last) of cell_box span."""
    extent = last - first + 1
    return extent[0] * extent[1] * extent[2]


@ti.func
def box_cell(first, last, k):
    """The k-th cell (x fastest) of the inclusive integer bounds (first, last)."""
    extent = last - first + 1
    return first + ti.Vector([k % extent[0], (k // extent[0]) % extent[1],
                              k // (extent[0] * extent[1])])


@ti.func
def cell_range(grid: ti.template(), kind, cell):
    """(begin, end) into cell_item of the items of `kind` in the cell at integer coordinates."""
    d = grid.dims[None]
    c = kind * d[0] * d[1] * d[2] + cell_index(grid, cell)
    return grid.cell_start[c], grid.cell_start[c + 1]


@ti.func
def meets(grid: ti.template(), a, lo, hi):
    """Whether entry a's box (cell_item[a]'s) meets the query box [lo, hi]."""
    return (grid.entry_lo[a] <= hi).all() and (lo <= grid.entry_hi[a]).all()


@ti.func
def first_shared(grid: ti.template(), a, cell, first):
    """Whether `cell` is the first cell that entry a's item shares with a query whose cells
    start at `first` (their boxes meeting): the query reports it from there alone."""
    return (ti.max(grid.entry_first[a], first) == cell).all()
