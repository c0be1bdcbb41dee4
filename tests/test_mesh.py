"""Mesh builders and OBJ input/output (numpy only; no Taichi runtime needed)."""

import numpy as np
import pytest

import ti_cloth as tc
from ti_cloth.body.mesh import unique_rows


def test_grid_layout_and_counts():
    rows, cols, width, height = 4, 6, 2.5, 1.5
    mesh = tc.grid_mesh(rows, cols, size=(width, height), plane="xz", origin=(1.0, 2.0, 3.0))
    assert mesh.vertex_count == rows * cols
    assert mesh.triangle_count == 2 * (rows - 1) * (cols - 1)
    v = mesh.vertices
    np.testing.assert_allclose(v[0], [1.0, 2.0, 3.0])
    np.testing.assert_allclose(v[cols - 1], [1.0 + width, 2.0, 3.0])        # columns along x
    np.testing.assert_allclose(v[(rows - 1) * cols], [1.0, 2.0, 3.0 + height])  # rows along z
    np.testing.assert_allclose(v[:, 1], 2.0)
    np.testing.assert_allclose(mesh.triangle_areas().sum(), width * height)
    assert len(mesh.boundary_edges()) == 2 * (rows - 1) + 2 * (cols - 1)
    assert len(mesh.boundary_vertices()) == 2 * rows + 2 * cols - 4
    assert len(mesh.edges()) == rows * (cols - 1) + cols * (rows - 1) + (rows - 1) * (cols - 1)


def test_a_disc_mesh_covers_its_polygon_with_triangles_facing_up():
    """disc_mesh: 1 + 3 r (r + 1) vertices on rings of 6 k at radius k R / r, 6 r^2 triangles
    wound upwards that tile the outer ring's polygon (their areas sum to it) and share every
    interior edge with exactly one other (a manifold disc: a boundary of 6 r edges)."""
    radius, rings, centre = 0.15, 5, np.array([0.1, 0.3, -0.2])
    mesh = tc.disc_mesh(radius, rings, centre=centre)
    assert mesh.vertex_count == 1 + 3 * rings * (rings + 1)
    assert mesh.triangle_count == 6 * rings ** 2
    offset = mesh.vertices - centre
    np.testing.assert_allclose(offset[:, 1], 0.0)
    ring_of = np.concatenate([[0]] + [np.full(6 * k, k) for k in range(1, rings + 1)])
    np.testing.assert_allclose(np.hypot(offset[:, 0], offset[:, 2]), ring_of * radius / rings,
                               atol=1e-15)
    a, b, c = (mesh.vertices[mesh.triangles[:, k]] for k in range(3))
    assert (np.cross(b - a, c - a)[:, 1] > 0).all()
    polygon = 0.5 * 6 * rings * radius ** 2 * np.sin(2 * np.pi / (6 * rings))
    np.testing.assert_allclose(mesh.triangle_areas().sum(), polygon, rtol=1e-12)
    assert len(mesh.boundary_edges()) == 6 * rings


def test_load_obj_splits_quads_and_save_round_trips(tmp_path):
    obj = tmp_path / "quad.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nf 1 2 3 4\nf 2 5 3\n")
    mesh = tc.load_mesh(obj)
    assert mesh.vertex_count == 5 and mesh.triangle_count == 3
    np.testing.assert_allclose(mesh.triangle_areas().sum(), 1.0 + 0.5)
    out = tmp_path / "out.obj"
    tc.save_mesh(out, mesh)
    again = tc.load_mesh(out)
    np.testing.assert_array_equal(again.triangles, mesh.triangles)
    np.testing.assert_allclose(again.vertices, mesh.vertices)
    assert not list(tmp_path.glob(".*tmp*")), "temporary file left behind"


def test_load_mesh_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.obj"):
        tc.load_mesh(tmp_path / "missing.obj")


@pytest.mark.parametrize("vertices, triangles, field", [
    (np.zeros((0, 3)), np.zeros((0, 3), int), "vertices"),
    (np.zeros((3, 2)), [[0, 1, 2]], "vertices.shape"),
    ([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]], [[0, 1, 2]], "vertices[2, 1]"),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]], "triangles"),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1]], "triangles.shape"),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 1]], "triangles[[0]]"),
])
def test_mesh_rejects_bad_input(vertices, triangles, field):
    with pytest.raises(ValueError, match=__import__("re").escape(field)):
        tc.Mesh(vertices, triangles)


@pytest.mark.parametrize("kwargs, field", [
    (dict(rows=1, cols=4), "rows"), (dict(rows=3, cols=2.5), "cols"),
    (dict(rows=3, cols=3, size=(1.0, -1.0)), "size"), (dict(rows=3, cols=3, plane="xx"), "plane"),
])
def test_grid_mesh_rejects_bad_input(kwargs, field):
    with pytest.raises(ValueError, match=field):
        tc.grid_mesh(**kwargs)


def test_import_does_not_start_taichi():
    import os
    import subprocess
    import sys

    # Taichi says "Starting on arch=..." when a runtime starts; a control run shows it does
    # (with Taichi's banner switch unset: a CLI test run in this worker before sets it)
    env = {k: v for k, v in os.environ.items() if k != "ENABLE_TAICHI_HEADER_PRINT"}
    code = "import ti_cloth, ti_cloth.render"
    quiet = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,
                           text=True, env=env)
    started = subprocess.run([sys.executable, "-c", code + "; ti_cloth.init()"], check=True,
                             capture_output=True, text=True, env=env)
    assert "Starting on arch" in started.stdout + started.stderr
    assert "Starting on arch" not in quiet.stdout + quiet.stderr


@pytest.mark.parametrize("columns, high", [(2, 50), (3, 50), (2, 2**40)])
def test_unique_rows_is_numpys_row_unique(columns, high):
    """The int64 encoding gives exactly np.unique(axis=0): rows, first indices, inverse and
    counts; 2**40 in two columns overflows the code and takes the fallback."""
    rows = np.random.default_rng(columns).integers(0, high, (3999, columns))
    rows[1::3] = rows[::3]                           # repeats
    for options in ({}, dict(return_index=True, return_inverse=True, return_counts=True)):
        ours, numpys = unique_rows(rows, **options), np.unique(rows, axis=0, **options)
        for a, b in zip(ours if options else [ours], numpys if options else [numpys]):
            np.testing.assert_array_equal(np.ravel(a), np.ravel(b))
