"""Triangle meshes on the host (numpy): the grid builder, OBJ input/output and edge queries.

Nothing here touches Taichi, so every function is testable without a runtime.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ..inputs import limits
from ..inputs.files import atomic_path
from ..inputs.validation import as_array, count, in_range, require

PLANES = {"xy": (0, 1), "xz": (0, 2), "yz": (1, 2), "zx": (2, 0), "yx": (1, 0), "zy": (2, 1)}


class Mesh:
    """A triangle mesh: the reference (rest) configuration of a body.

    vertices: rest positions [m], shape (vertex_count, 3), float64.
    triangles: vertex indices, shape (triangle_count, 3), int64; may be empty only when
        the mesh describes particles without a surface (strings, explicit spring networks).
    grid_shape: (rows, cols) when the vertices form a regular grid laid out row-major
        (vertex = row * cols + col); grid meshes get the spring pattern of Stuyck fig. 4.2.
    tetrahedra: vertex indices, shape (tet_count, 4), of a volume mesh (Stuyck 4.6.2); its
        surface is then given as `triangles` (see surface_triangles). Empty for surfaces.
    uvs: texture coordinates, shape (vertex_count, 2), one per vertex, or None: a Fabric's
        warp may follow them (Cloth(warp="uv")).
    """

    def __init__(self, vertices, triangles, grid_shape: tuple[int, int] | None = None,
                 tetrahedra=(), uvs=None):
        self.vertices = as_array("vertices", vertices, np.float64, (None, 3))
        self.triangles = as_array("triangles", triangles, np.int64, (None, 3))
        self.tetrahedra = as_array("tetrahedra", tetrahedra, np.int64, (None, 4))
        n = len(self.vertices)
        self.uvs = None if uvs is None else as_array("uvs", uvs, np.float64, (n, 2))
        require(n > 0, "vertices", n, "at least 1 vertex (the mesh is empty)")
        far = np.argwhere(np.abs(self.vertices) > limits.COORDINATE.high)
        require(len(far) == 0, f"vertices[{', '.join(map(str, far[0])) if len(far) else ''}]",
                self.vertices[tuple(far[0])] if len(far) else None,
                f"a coordinate {limits.COORDINATE.text()}")
        for name, cells in (("triangles", self.triangles), ("tetrahedra", self.tetrahedra)):
            if len(cells):
                bad = np.flatnonzero((cells < 0).any(axis=1) | (cells >= n).any(axis=1))
                require(len(bad) == 0, f"{name}[{bad[:1].tolist()}]", cells[bad[:1]].tolist(),
                        f"vertex indices in [0, {n - 1}]")
                ordered = np.sort(cells, axis=1)
                repeated = np.flatnonzero((ordered[:, 1:] == ordered[:, :-1]).any(axis=1))
                require(len(repeated) == 0, f"{name}[{repeated[:1].tolist()}]",
                        cells[repeated[:1]].tolist(), f"{cells.shape[1]} distinct vertices per cell")
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
        return unique_rows(triangle_edges(self.triangles)).reshape(-1, 2)

    def boundary_edges(self) -> np.ndarray:
        """Edges used by exactly one triangle (i < j), shape (B, 2)."""
        edges, counts = unique_rows(triangle_edges(self.triangles), return_counts=True)
        return edges[counts == 1].reshape(-1, 2)

    def boundary_vertices(self) -> np.ndarray:
        """Sorted indices of the vertices on a boundary edge."""
        return np.unique(self.boundary_edges())

    def named_vertices(self) -> dict[str, np.ndarray]:
        """Vertex sets by name, as scene files and `hem=` take them: "boundary", and for a grid
        its edges and corners ("bottom" = row 0, "left" = column 0, "top_right", ...)."""
        names = {"boundary": self.boundary_vertices()}
        if self.grid_shape is not None:
            rows, cols = self.grid_shape
            index = np.arange(rows * cols).reshape(rows, cols)
            names |= {"bottom_left": index[:1, 0], "bottom_right": index[:1, -1],
                      "top_left": index[-1:, 0], "top_right": index[-1:, -1],
                      "bottom": index[0], "top": index[-1], "left": index[:, 0],
                      "right": index[:, -1]}
        return names

    def triangle_areas(self) -> np.ndarray:
        """Rest area of each triangle [m^2], shape (triangle_count,)."""
        p = self.vertices[self.triangles]
        return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)

    def tetrahedron_volumes(self) -> np.ndarray:
        """Signed rest volume of each tetrahedron [m^3] (positive when (b-a, c-a, d-a) is
        right-handed), shape (tet_count,)."""
        return signed_volumes(self.vertices, self.tetrahedra)

    def __repr__(self) -> str:
        grid = f", grid_shape={self.grid_shape}" if self.grid_shape else ""
        tets = f", tet_count={len(self.tetrahedra)}" if len(self.tetrahedra) else ""
        uvs = ", uvs" if self.uvs is not None else ""
        return (f"Mesh(vertex_count={self.vertex_count}, "
                f"triangle_count={self.triangle_count}{grid}{tets}{uvs})")


def unique_rows(rows: np.ndarray, **options):
    """np.unique(rows, axis=0, **options) for non-negative integer rows, as fast as a 1-D
    unique: each row is encoded as one int64 in mixed radix (lexicographic order kept), and
    decoded back (np.unique over rows sorts void records, far slower: docs/performance.md).
    Falls back to the row unique when the codes could
    overflow int64."""
    rows = np.asarray(rows, np.int64)
    radix = int(rows.max()) + 1 if rows.size else 1
    if radix ** rows.shape[1] >= 2**63:
        return np.unique(rows, axis=0, **options)
    code = np.zeros(len(rows), np.int64)
    for column in range(rows.shape[1]):
        code = code * radix + rows[:, column]
    found = np.unique(code, **options)
    codes, rest = (found[0], found[1:]) if isinstance(found, tuple) else (found, ())
    unique = np.empty((len(codes), rows.shape[1]), np.int64)
    for column in reversed(range(rows.shape[1])):
        codes, unique[:, column] = np.divmod(codes, radix)
    return (unique, *rest) if rest else unique


def signed_volumes(vertices: np.ndarray, tetrahedra: np.ndarray) -> np.ndarray:
    """Signed volume [m^3] of each tetrahedron (a, b, c, d): (b-a) . ((c-a) x (d-a)) / 6."""
    p = vertices[tetrahedra]
    edges = p[:, 1:] - p[:, :1]
    return np.einsum("ij,ij->i", edges[:, 0], np.cross(edges[:, 1], edges[:, 2])) / 6.0


def surface_triangles(vertices: np.ndarray, tetrahedra: np.ndarray) -> np.ndarray:
    """The faces used by exactly one tetrahedron, wound so their normals point outwards."""
    faces = tetrahedra[:, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]].reshape(-1, 3)
    opposite = tetrahedra.ravel()
    _, first, counts = unique_rows(np.sort(faces, axis=1), return_index=True, return_counts=True)
    outer = np.sort(first[counts == 1])
    faces, inner = faces[outer], vertices[opposite[outer]]
    p = vertices[faces]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    flip = np.einsum("ij,ij->i", normal, inner - p[:, 0]) > 0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    return faces


def tet_grid_mesh(cells=(4, 4, 4), size=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0)) -> Mesh:
    """A box of cells[0] x cells[1] x cells[2] cubes [m], each cut into the six tetrahedra
    around its diagonal from the lowest to the highest corner (Kuhn's subdivision: faces of
    neighbouring cubes are cut the same way, so the tetrahedra fit together). The triangles
    are the outer surface. Vertex (i, j, k) has index (i * (ny + 1) + j) * (nz + 1) + k."""
    cells = as_array("cells", cells, np.int64, (3,))
    for axis in range(3):
        count(f"cells[{axis}]", int(cells[axis]), limits.CELLS)
    vertices = int(np.prod(cells + 1))
    limits.check_memory("cells", cells.tolist(), vertices, 7 * vertices)   # 7 edges per vertex
    size = as_array("size", size, np.float64, (3,))
    for axis in range(3):
        in_range(f"size[{axis}]", size[axis], limits.LENGTH)
    origin = as_array("origin", origin, np.float64, (3,))
    nx, ny, nz = (int(c) for c in cells)
    axes = [s * (np.arange(c + 1) / c) for s, c in zip(size, cells)]   # exact at refinements
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3) + origin
    index = np.arange(len(grid)).reshape(nx + 1, ny + 1, nz + 1)
    corners = np.stack([index[i:i + nx, j:j + ny, k:k + nz].ravel()
                        for i in (0, 1) for j in (0, 1) for k in (0, 1)], axis=1)  # corner = 4i+2j+k
    paths = [(4, 6), (4, 5), (2, 6), (2, 3), (1, 5), (1, 3)]   # monotone paths from corner 0 to 7
    tets = np.concatenate([corners[:, [0, a, b, 7]] for a, b in paths])
    negative = signed_volumes(grid, tets) < 0
    tets[negative] = tets[negative][:, [0, 2, 1, 3]]
    return Mesh(grid, surface_triangles(grid, tets), tetrahedra=tets)


def box_mesh(lo=(-0.5, -0.5, -0.5), hi=(0.5, 0.5, 0.5)) -> Mesh:
    """The surface of the axis-aligned box between corners `lo` and `hi` [m]: 12 triangles
    wound outwards, each face with 4 vertices of its own (24 in all), so a renderer shades
    the faces flat. Boxes combined (combine_meshes) make tables, shelves, steps."""
    lo = as_array("lo", lo, np.float64, (3,))
    hi = as_array("hi", hi, np.float64, (3,))
    require(bool((hi > lo).all()), "hi", tuple(hi), f"greater than lo {tuple(lo)} on every axis")
    vertices, triangles = [], []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        for side, face in ((-1, lo[axis]), (1, hi[axis])):
            corners = np.zeros((4, 3))
            corners[:, axis] = face
            corners[:, u] = (lo[u], hi[u], hi[u], lo[u])
            corners[:, v] = (lo[v], lo[v], hi[v], hi[v])
            base = len(vertices) * 4
            quad = [[0, 1, 2], [0, 2, 3]] if side > 0 else [[0, 2, 1], [0, 3, 2]]
            vertices.append(corners)
            triangles += [[base + i for i in t] for t in quad]
    return Mesh(np.concatenate(vertices), triangles)


def sphere_mesh(radius: float = 1.0, centre=(0.0, 0.0, 0.0), subdivisions: int = 3) -> Mesh:
    """An icosphere of `radius` [m] around `centre` [m]: the icosahedron with each triangle cut
    in four `subdivisions` times, its vertices pushed onto the sphere (20 x 4^subdivisions
    triangles, wound outwards; the flat facets lie at most radius x 0.3 / 4^subdivisions
    inside the sphere)."""
    radius = in_range("radius", radius, limits.LENGTH)
    centre = as_array("centre", centre, np.float64, (3,))
    subdivisions = count("subdivisions", subdivisions, limits.SUBDIVISIONS)
    t = (1 + 5 ** 0.5) / 2
    vertices = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                         [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]])
    triangles = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                          [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                          [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                          [8, 6, 7], [9, 8, 1]])
    vertices = vertices / np.linalg.norm(vertices, axis=1, keepdims=True)
    for _ in range(subdivisions):
        edges, triangles = split_triangles(triangles, len(vertices))
        midpoints = vertices[edges].mean(axis=1)
        vertices = np.vstack([vertices, midpoints / np.linalg.norm(midpoints, axis=1,
                                                                   keepdims=True)])
    return Mesh(vertices * radius + centre, triangles)


def split_triangles(triangles: np.ndarray, vertex_count: int) -> tuple[np.ndarray, np.ndarray]:
    """One midpoint subdivision: (the unique edges (E, 2), whose midpoints become vertices
    vertex_count + e, and the triangles each cut into four at them, wound as before)."""
    edges, middle = unique_rows(triangle_edges(triangles), return_inverse=True)
    middle = middle.reshape(-1, 3) + vertex_count        # (t0t1, t1t2, t2t0) of each
    a, b, c = triangles.T
    ab, bc, ca = middle.T
    return edges, np.concatenate([np.stack(corners, axis=1) for corners in
                                  ((a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca))])


def disc_mesh(radius: float = 0.5, rings: int = 8, centre=(0.0, 0.0, 0.0)) -> Mesh:
    """A horizontal disc (the xz plane through `centre` [m]) of `radius` [m]: a centre vertex
    and `rings` concentric rings, ring k of 6 k vertices at radius k radius / rings, each
    annulus triangulated by walking both rings in angle (triangles of nearly equal size and
    shape, wound with normals up; 1 + 3 rings (rings + 1) vertices). Ring k's vertices are
    numbered after ring k - 1's, from the +x axis towards -z."""
    radius = in_range("radius", radius, limits.LENGTH)
    rings = count("rings", rings, limits.GRID_SIDE)
    limits.check_memory("rings", rings, 1 + 3 * rings * (rings + 1), 6 * rings * rings)
    centre = as_array("centre", centre, np.float64, (3,))
    points, triangles = [np.zeros(2)], []
    inner = np.array([0])
    for k in range(1, rings + 1):
        angle = 2 * np.pi * np.arange(6 * k) / (6 * k)
        outer = len(points) + np.arange(6 * k)
        points += list(k * radius / rings * np.stack([np.cos(angle), np.sin(angle)], 1))
        i = j = 0
        m, n = len(inner), len(outer)
        while i < m or j < n:           # advance the ring whose next vertex comes first
            next_inner = 2 * np.pi * (i + 1) / m if i < m else np.inf
            if j < n and 2 * np.pi * (j + 1) / n <= next_inner:
                triangles.append((inner[i % m], outer[j], outer[(j + 1) % n]))
                j += 1
            else:
                triangles.append((inner[i % m], outer[j % n], inner[(i + 1) % m]))
                i += 1
        inner = outer
    flat = np.array(points)
    triangles = np.array([t for t in triangles if len(set(t)) == 3])   # the centre's fan
    vertices = centre + np.stack([flat[:, 0], np.zeros(len(flat)), -flat[:, 1]], 1)
    return Mesh(vertices, triangles)


def combine_meshes(meshes) -> Mesh:
    """One mesh holding the vertices and triangles of `meshes`, in order."""
    meshes = list(meshes)
    require(len(meshes) > 0 and all(isinstance(m, Mesh) for m in meshes), "meshes", meshes,
            "a non-empty list of Mesh objects")
    offsets = np.cumsum([0] + [m.vertex_count for m in meshes[:-1]])
    return Mesh(np.concatenate([m.vertices for m in meshes]),
                np.concatenate([m.triangles + o for m, o in zip(meshes, offsets)]))


def triangle_edges(triangles: np.ndarray) -> np.ndarray:
    """The edges (t0,t1), (t1,t2), (t2,t0) of every triangle as sorted pairs, shape (3T, 2)."""
    e = triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    return np.sort(e, axis=1)


def nonmanifold(triangles: np.ndarray, vertex_count: int) -> tuple[np.ndarray, np.ndarray]:
    """Where a triangle mesh is not a surface: (edges (E, 2), as sorted pairs, shared by three
    or more triangles; vertices (V,) on more than two boundary edges, where separate sheets
    meet at a point)."""
    triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
    if not len(triangles):
        return np.zeros((0, 2), np.int64), np.zeros(0, np.int64)
    edges, uses = unique_rows(triangle_edges(triangles), return_counts=True)
    on_rim = np.bincount(edges[uses == 1].ravel(), minlength=vertex_count)
    shared = edges[uses > 2]
    on_rim[shared.ravel()] = 0                   # a fin's own corners are not a second sheet
    return shared, np.flatnonzero(on_rim > 2)


def vertex_triangles(triangles: np.ndarray, vertex_count: int) -> tuple[np.ndarray, np.ndarray]:
    """Each vertex's triangles, as CSR lists in triangle order: vertex v's triangles are
    triangle[start[v]:start[v + 1]]. Returns (start (vertex_count + 1,), triangle (3 T,)), int64;
    gathers over them (wind forces, smooth normals) visit triangles in a fixed order."""
    corners = np.asarray(triangles).ravel()
    start = np.zeros(vertex_count + 1, np.int64)
    start[1:] = np.cumsum(np.bincount(corners, minlength=vertex_count))
    return start, np.argsort(corners, kind="stable") // 3


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
    rows, cols = count("rows", rows, limits.GRID_SIDE), count("cols", cols, limits.GRID_SIDE)
    limits.check_memory("rows x cols", f"{rows} x {cols}", rows * cols, 6 * rows * cols)
    size = as_array("size", size, np.float64, (2,))
    for axis in range(2):
        in_range(f"size[{axis}]", size[axis], limits.LENGTH)
    require(plane in PLANES, "plane", plane, f"one of {sorted(PLANES)}")
    origin = as_array("origin", origin, np.float64, (3,))

    a, b = PLANES[plane]
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    vertices = np.tile(origin, (rows * cols, 1))
    vertices[:, a] += size[0] * (c.ravel() / (cols - 1))     # c / (cols - 1) first: the same
    vertices[:, b] += size[1] * (r.ravel() / (rows - 1))     # bits at every refinement

    q = (r[:-1, :-1] * cols + c[:-1, :-1]).ravel()  # lower-left corner of each quad
    lower = np.stack([q, q + 1, q + cols + 1], axis=1)
    upper = np.stack([q, q + cols + 1, q + cols], axis=1)
    triangles = np.stack([lower, upper], axis=1).reshape(-1, 3)
    return Mesh(vertices, triangles, grid_shape=(rows, cols))


def _read_mesh(meshio, path: Path):
    """meshio.read(path); an OBJ whose texture coordinates or normals are not one per vertex
    (seams: meshio keeps no per-corner indices and refuses the file) is read again without
    them."""
    try:
        return meshio.read(path)
    except ValueError as err:
        if path.suffix.lower() != ".obj" or "point_data" not in str(err):
            raise
    text = path.read_text(errors="replace").splitlines(keepends=True)
    kept = "".join(line for line in text if not line.lstrip().startswith(("vt ", "vn ")))
    return meshio.read(io.StringIO(kept), file_format="obj")


def load_mesh(path) -> Mesh:
    """Read a mesh (OBJ, PLY, STL, VTK, MSH, ... anything meshio reads); quads are split in
    two. A volume mesh's tetrahedra are kept, with its outer surface as the triangles. An OBJ's
    texture coordinates become Mesh.uvs when there is one per vertex (meshio keeps no
    per-corner indices, so a file whose UVs have seams, more vt than v, is read without).
    Raises FileNotFoundError, or ValueError for a file that holds no usable mesh."""
    import meshio

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"mesh file not found: {path}")
    try:
        data = _read_mesh(meshio, path)
    except Exception as err:   # meshio raises ReadError, but its parsers also KeyError, IndexError...
        raise ValueError(f"{path}: not a mesh meshio can read ({type(err).__name__}: "
                         f"{str(err)[:200]})") from None
    tetrahedra = [block.data for block in data.cells if block.type == "tetra"]
    if tetrahedra:
        points = np.asarray(data.points, np.float64)
        tets = np.concatenate(tetrahedra)
        try:
            points = as_array("vertices", points, np.float64, (None, 3))
            negative = signed_volumes(points, tets) < 0
            tets[negative] = tets[negative][:, [0, 2, 1, 3]]
            return Mesh(points, surface_triangles(points, tets), tetrahedra=tets)
        except (ValueError, IndexError) as err:
            raise ValueError(f"{path}: {err}") from None
    triangles = []
    for block in data.cells:
        if block.type == "triangle":
            triangles.append(block.data)
        elif block.type == "quad":
            quads = block.data
            triangles += [quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]
    if not triangles:
        raise ValueError(f"{path}: no triangle, quad or tetra cells found (cell types: "
                         f"{[b.type for b in data.cells]})")
    uvs = data.point_data.get("obj:vt")
    if uvs is not None and (uvs.ndim != 2 or len(uvs) != len(data.points) or uvs.shape[1] < 2):
        uvs = None
    try:
        return Mesh(data.points, np.concatenate(triangles),
                    uvs=None if uvs is None else uvs[:, :2])
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from None


def save_mesh(path, mesh: Mesh, vertices=None) -> None:
    """Write `mesh` (or its triangles with other `vertices`, e.g. simulated positions) to `path`.

    The file is written under a temporary name and renamed, so a reader never sees half a file.
    """
    import meshio

    path = Path(path)
    points = mesh.vertices if vertices is None else as_array("vertices", vertices, np.float64,
                                                             (mesh.vertex_count, 3))
    with atomic_path(path) as tmp:
        meshio.write_points_cells(tmp, points, [("triangle", mesh.triangles)])


def uv_warp(mesh: Mesh) -> np.ndarray:
    """d x / d u of each triangle (T, 3): with edges d1, d2 and their uv differences
    (a1, b1), (a2, b2), [d1 d2] = J [[a1, a2], [b1, b2]], and J's first column is
    (b2 d1 - b1 d2) / (a1 b2 - a2 b1) (the tangent of normal mapping). A triangle whose uvs
    have (almost) no area has none: refused, naming it."""
    p = mesh.vertices[mesh.triangles]
    uv = mesh.uvs[mesh.triangles]
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    (a1, b1), (a2, b2) = (uv[:, 1] - uv[:, 0]).T, (uv[:, 2] - uv[:, 0]).T
    det = a1 * b2 - a2 * b1
    scale = np.maximum(np.abs(uv - uv[:, :1]).max(axis=(1, 2)), np.finfo(float).tiny) ** 2
    flat = np.flatnonzero(np.abs(det) <= 1e-9 * scale)
    require(len(flat) == 0, f"uvs of triangles {flat[:5].tolist()}", "(no area)",
            'a uv triangle of non-zero area for warp="uv" (or give warp a direction)')
    return (b2[:, None] * d1 - b1[:, None] * d2) / det[:, None]
