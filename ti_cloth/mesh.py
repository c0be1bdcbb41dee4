"""Triangle meshes on the host (numpy): the grid builder, OBJ input/output and edge queries.

Nothing here touches Taichi, so every function is testable without a runtime.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._validate import as_array, require

PLANES = {"xy": (0, 1), "xz": (0, 2), "yz": (1, 2), "zx": (2, 0), "yx": (1, 0), "zy": (2, 1)}


class Mesh:
    """A triangle mesh: the reference (rest) configuration of a body.

    vertices: rest positions [m], shape (vertex_count, 3), float64.
    triangles: vertex indices, shape (triangle_count, 3), int64; may be empty only when
        the mesh describes particles without a surface (strings, explicit spring networks).
    grid_shape: (rows, cols) when the vertices form a regular grid laid out row-major
        (vertex = row * cols + col); grid meshes get the spring pattern of Stuyck fig. 4.2.
    """

    def __init__(self, vertices, triangles, grid_shape: tuple[int, int] | None = None):
        self.vertices = as_array("vertices", vertices, np.float64, (None, 3))
        self.triangles = as_array("triangles", triangles, np.int64, (None, 3))
        n = len(self.vertices)
        require(n > 0, "vertices", n, "at least 1 vertex (the mesh is empty)")
        if len(self.triangles):
            bad = np.flatnonzero((self.triangles < 0).any(axis=1) | (self.triangles >= n).any(axis=1))
            require(len(bad) == 0, "triangles", self.triangles[bad[:1]].tolist(),
                    f"vertex indices in [0, {n - 1}] (triangle {bad[:1].tolist()})")
            t = self.triangles
            repeated = np.flatnonzero((t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 0] == t[:, 2]))
            require(len(repeated) == 0, f"triangles[{repeated[:1].tolist()}]",
                    t[repeated[:1]].tolist(), "three distinct vertices per triangle")
        if grid_shape is not None:
            rows, cols = grid_shape
            require(rows * cols == n, "grid_shape", grid_shape, f"rows * cols == vertex_count ({n})")
        self.grid_shape = grid_shape

    @property
    def vertex_count(self) -> int:
        return len(self.vertices)

    @property
    def triangle_count(self) -> int:
        return len(self.triangles)

    def edges(self) -> np.ndarray:
        """Unique undirected edges (i < j), shape (edge_count, 2), sorted lexicographically."""
        return np.unique(triangle_edges(self.triangles), axis=0).reshape(-1, 2)

    def boundary_edges(self) -> np.ndarray:
        """Edges used by exactly one triangle (i < j), shape (B, 2)."""
        edges, counts = np.unique(triangle_edges(self.triangles), axis=0, return_counts=True)
        return edges[counts == 1].reshape(-1, 2)

    def boundary_vertices(self) -> np.ndarray:
        """Sorted indices of the vertices on a boundary edge."""
        return np.unique(self.boundary_edges())

    def triangle_areas(self) -> np.ndarray:
        """Rest area of each triangle [m^2], shape (triangle_count,)."""
        p = self.vertices[self.triangles]
        return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)

    def __repr__(self) -> str:
        grid = f", grid_shape={self.grid_shape}" if self.grid_shape else ""
        return f"Mesh(vertex_count={self.vertex_count}, triangle_count={self.triangle_count}{grid})"


def triangle_edges(triangles: np.ndarray) -> np.ndarray:
    """The edges (t0,t1), (t1,t2), (t2,t0) of every triangle as sorted pairs, shape (3T, 2)."""
    e = triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    return np.sort(e, axis=1)


def grid_mesh(rows: int, cols: int, size: tuple[float, float] = (1.0, 1.0), plane: str = "xy",
              origin=(0.0, 0.0, 0.0)) -> Mesh:
    """A regular grid of rows x cols particles, each quad split into two triangles.

    size: (width, height) [m]; columns run along the plane's first axis over `width`,
        rows along its second axis over `height`.
    plane: two axis letters, e.g. "xy" (a hanging sheet with y up) or "xz" (a horizontal sheet).
    origin: position of vertex 0 (row 0, col 0) [m].

    Vertex (r, c) has index r * cols + c. Every quad is cut along the same diagonal, from
    (r, c) to (r + 1, c + 1), so interior particles all touch six triangles of equal area.
    """
    for name, value in (("rows", rows), ("cols", cols)):
        require(isinstance(value, (int, np.integer)) and value >= 2, name, value, "an int >= 2")
    size = as_array("size", size, np.float64, (2,))
    require(bool(np.all(size > 0)), "size", size.tolist(), "two lengths > 0 m")
    require(plane in PLANES, "plane", plane, f"one of {sorted(PLANES)}")
    origin = as_array("origin", origin, np.float64, (3,))

    a, b = PLANES[plane]
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    vertices = np.tile(origin, (rows * cols, 1))
    vertices[:, a] += c.ravel() * size[0] / (cols - 1)
    vertices[:, b] += r.ravel() * size[1] / (rows - 1)

    q = (r[:-1, :-1] * cols + c[:-1, :-1]).ravel()  # lower-left corner of each quad
    lower = np.stack([q, q + 1, q + cols + 1], axis=1)
    upper = np.stack([q, q + cols + 1, q + cols], axis=1)
    triangles = np.stack([lower, upper], axis=1).reshape(-1, 3)
    return Mesh(vertices, triangles, grid_shape=(rows, cols))


def load_mesh(path) -> Mesh:
    """Read a surface mesh (OBJ, PLY, STL, ... anything meshio reads); quads are split in two."""
    import meshio

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"mesh file not found: {path}")
    data = meshio.read(path)
    triangles = []
    for block in data.cells:
        if block.type == "triangle":
            triangles.append(block.data)
        elif block.type == "quad":
            quads = block.data
            triangles += [quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]
    if not triangles:
        raise ValueError(f"{path}: no triangle or quad faces found (cell types: "
                         f"{[b.type for b in data.cells]})")
    return Mesh(data.points, np.concatenate(triangles))


def save_mesh(path, mesh: Mesh, vertices=None) -> None:
    """Write `mesh` (or its triangles with other `vertices`, e.g. simulated positions) to `path`.

    The file is written under a temporary name and renamed, so a reader never sees half a file.
    """
    import meshio

    path = Path(path)
    points = mesh.vertices if vertices is None else as_array("vertices", vertices, np.float64,
                                                             (mesh.vertex_count, 3))
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    meshio.write_points_cells(tmp, points, [("triangle", mesh.triangles)])
    tmp.replace(path)
