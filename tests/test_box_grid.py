"""The broad phase of self-collision (box_grid.py): a query reports exactly the boxes that meet
it, each once, in a fixed order, on every run (thread counts: test_self_collision, which
compares a simulation's grid on one thread and two)."""

import numpy as np
import pytest
import taichi as ti

from ti_cloth.contact.broad_phase.box_grid import (
    BoxGrid,
    box_cell,
    box_cell_count,
    cell_box,
    cell_range,
    first_shared,
    meets,
)
from ti_cloth.runtime import backend


@ti.kernel
def _query(grid: ti.template(), kind: ti.i32, lo: ti.types.ndarray(), hi: ti.types.ndarray(),
           found: ti.types.ndarray()):
    """found[q, i] += 1 for every item i of `kind` the query box q reports."""
    for q in range(lo.shape[0]):
        qlo = ti.Vector([lo[q, 0], lo[q, 1], lo[q, 2]])
        qhi = ti.Vector([hi[q, 0], hi[q, 1], hi[q, 2]])
        first, last = cell_box(grid, qlo, qhi)
        for k in range(box_cell_count(first, last)):
            cell = box_cell(first, last, k)
            begin, end = cell_range(grid, kind, cell)
            for a in range(begin, end):
                if meets(grid, a, qlo, qhi):
                    if first_shared(grid, a, cell, first):
                        found[q, grid.cell_item[a]] += 1


def reported(lo, hi, query_lo, query_hi, cell, counts=None, kind=0):
    grid = BoxGrid(*(counts or [len(lo)]))
    grid.lo.from_numpy(lo.astype(backend.numpy_real()))
    grid.hi.from_numpy(hi.astype(backend.numpy_real()))
    grid.build(cell)
    found = np.zeros((len(query_lo), len(lo)), np.int32)
    _query(grid, kind, query_lo, query_hi, found)
    return grid, found


def scenes():
    """(item lo, item hi, query lo, query hi, cell side) of four clouds."""
    rng = np.random.default_rng(7)
    points = rng.uniform(-1.0, 1.0, size=(400, 3))                                  # degenerate
    sheet = np.c_[rng.uniform(0, 1, 300), np.zeros(300), rng.uniform(0, 1, 300)]
    size = rng.uniform(0.0, 0.05, size=(300, 3))
    apart = np.concatenate([rng.normal(scale=0.01, size=(150, 3)),
                            1e4 + rng.normal(scale=0.01, size=(150, 3))])            # 1e4 m apart
    flung = rng.uniform(0.0, 1.0, size=(200, 3))
    flung_hi = flung.copy()
    flung_hi[:60, 0] += 5.0                  # 60 boxes flung 5 m along x: over the entry budget
    return {"points": (points, points, points - 0.15, points + 0.15, 0.3),
            "flat sheet of boxes": (sheet, sheet + size, sheet - 0.04, sheet + 0.04, 0.08),
            "blown apart": (apart, apart, apart - 0.01, apart + 0.01, 0.02),
            "boxes flung across": (flung, flung_hi, flung - 0.15, flung + 0.15, 0.1)}


@pytest.mark.parametrize("name", list(scenes()))
def test_a_query_reports_exactly_the_boxes_that_meet_it_once(f64, name):
    lo, hi, query_lo, query_hi, cell = scenes()[name]
    grid, found = reported(lo, hi, query_lo, query_hi, cell)
    expected = ((lo[None] <= query_hi[:, None]) & (query_lo[:, None] <= hi[None])).all(axis=2)
    assert found.max() == 1, "no box reported twice"
    np.testing.assert_array_equal(found == 1, expected)
    assert expected.sum() > 2 * len(lo), "the queries meet boxes besides their own"
    assert grid.cells() <= 4 * len(lo) and grid.side[None] >= cell


def test_a_query_reports_only_the_kind_it_asks_for(f64):
    """Points (kind 0) and boxes of a sheet (kind 1) in one grid: a query of either kind
    reports exactly the brute-force boxes of that kind."""
    sheet, sheet_hi, query_lo, query_hi, cell = scenes()["flat sheet of boxes"]
    points = sheet[::2] + [0.01, 0.01, 0.0]                      # among the sheet's boxes
    lo, hi = np.concatenate([points, sheet]), np.concatenate([points, sheet_hi])
    meets = ((lo[None] <= query_hi[:, None]) & (query_lo[:, None] <= hi[None])).all(axis=2)
    for kind, mine in ((0, np.arange(len(lo)) < len(points)), (1, np.arange(len(lo)) >= len(points))):
        _, found = reported(lo, hi, query_lo, query_hi, cell, counts=[len(points), len(sheet)],
                            kind=kind)
        assert found.max() == 1
        np.testing.assert_array_equal(found == 1, meets & mine[None])
        assert (meets & mine[None]).sum() > len(query_lo)


def test_cells_list_their_boxes_in_increasing_index_and_rebuild_identically(f64):
    lo, hi, query_lo, query_hi, cell = scenes()["flat sheet of boxes"]
    grid, _ = reported(lo, hi, query_lo, query_hi, cell)
    start, order = grid.cell_start.to_numpy(), grid.cell_item.to_numpy()
    cells = grid.cells()
    assert start[cells] >= len(lo) and set(order[:start[cells]]) == set(range(len(lo)))
    for c in range(cells):
        assert (np.diff(order[start[c]:start[c + 1]]) > 0).all()
    again, _ = reported(lo, hi, query_lo, query_hi, cell)
    np.testing.assert_array_equal(again.cell_item.to_numpy(), order)
