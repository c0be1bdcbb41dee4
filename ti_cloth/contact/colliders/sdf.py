"""Signed distance grids of triangle meshes, for mesh colliders (mesh_collider.py).

A grid of nodes spaced `cell` apart covers the mesh's bounding box and a margin. Each node holds
the distance to the nearest triangle, negative inside, and the distance's gradient (a unit
vector). Inside is where the generalised winding number (Jacobson et al. 2013) exceeds 1/2 in
magnitude, which stays right for meshes with holes, overlapping parts or either orientation.
Closest surface points are found with libigl (a base dependency) for the
nodes within `margin` of the surface; a node beyond takes the closest point of the nearest node
within (a distance at least the true one, exact where both share the closest point: the field
still grows away from the surface, so a particle deep inside finds the way out). A node's
distance and gradient follow from its closest point. The collision kernels sample the grid
trilinearly (`sample_grid`).

Grids are cached: in memory for the process, and on disk (`cache_folder()`) under a hash of the
mesh, the resolution and the margin, written atomically; a mesh builds once per machine.
"""

import hashlib
import os
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import taichi as ti

from ...inputs.files import atomic_path

FORMAT = 1            # bump when the grid's meaning or layout changes: old cache files are ignored
MEMORY_CACHE = 4      # grids kept in memory
INSIDE = 0.5          # |winding number| above this: inside


@dataclass(frozen=True, eq=False)
class DistanceGrid:
    """origin: position of node (0, 0, 0) [m], shape (3,). cell: node spacing [m].
    distance: signed distance to the mesh [m] at node (i, j, k) = origin + cell (i, j, k),
        negative inside, shape (nx, ny, nz), float32.
    gradient: unit gradient of the distance at each node, shape (nx, ny, nz, 3), float32."""

    origin: np.ndarray
    cell: float
    distance: np.ndarray
    gradient: np.ndarray

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.distance.shape

    def samples(self, solid: bool) -> np.ndarray:
        """(distance, gradient) per node, shape (nodes, 4), node (i, j, k) in row i*ny*nz +
        j*nz + k. A shell (solid False) is two-sided: the unsigned distance, and its gradient
        (away from the surface on either side)."""
        d, g = self.distance, self.gradient
        if not solid:
            d, g = np.abs(d), g * np.where(d < 0, -1, 1)[..., None].astype(np.float32)
        return np.concatenate([d[..., None], g], axis=-1).reshape(-1, 4)


def layout(vertices: np.ndarray, resolution: int, margin: float) -> tuple[np.ndarray, float,
                                                                           tuple[int, int, int]]:
    """(origin, cell, shape) of the grid of `resolution` cells along the longest side of the
    vertices' bounding box grown by `margin` [m] on every side (at least 2 nodes per axis)."""
    lo, hi = vertices.min(axis=0) - margin, vertices.max(axis=0) + margin
    cell = float((hi - lo).max()) / resolution
    shape = tuple(int(n) for n in np.maximum(np.ceil((hi - lo) / cell - 1e-9).astype(int) + 1, 2))
    centre = 0.5 * (lo + hi)
    origin = centre - 0.5 * cell * (np.asarray(shape) - 1)     # the box centred on the mesh's
    return origin, cell, shape


def distance_grid(vertices: np.ndarray, triangles: np.ndarray, resolution: int,
                  margin: float) -> DistanceGrid:
    """The grid of the mesh (vertices [m] (V, 3), triangles (T, 3)): from memory, the disk
    cache, or built (`build`) and cached."""
    vertices = np.ascontiguousarray(vertices, np.float64)
    triangles = np.ascontiguousarray(triangles, np.int64)
    key = grid_key(vertices, triangles, resolution, margin)
    grid = _in_memory.pop(key, None) or _read(key) or _write(key, build(vertices, triangles,
                                                                        resolution, margin))
    _in_memory[key] = grid
    while len(_in_memory) > MEMORY_CACHE:
        _in_memory.popitem(last=False)
    return grid


_in_memory: OrderedDict[str, DistanceGrid] = OrderedDict()


def clear_memory_cache() -> None:
    """Forget the grids held in memory (the disk cache stays): the next request reads or builds."""
    _in_memory.clear()


def grid_key(vertices: np.ndarray, triangles: np.ndarray, resolution: int, margin: float) -> str:
    """Hex digest naming a grid: the format, the mesh's bytes, the resolution and margin."""
    digest = hashlib.sha256(f"{FORMAT}:{resolution}:{float(margin)!r}:".encode())
    digest.update(vertices.tobytes())
    digest.update(triangles.tobytes())
    return digest.hexdigest()[:32]


def cache_folder() -> Path:
    """Where grids are cached: $TI_CLOTH_CACHE, else $XDG_CACHE_HOME/ti_cloth, else
    ~/.cache/ti_cloth."""
    if os.environ.get("TI_CLOTH_CACHE"):
        return Path(os.environ["TI_CLOTH_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "ti_cloth"


def _cache_file(key: str) -> Path:
    return cache_folder() / f"sdf-{key}.npz"


def _read(key: str) -> DistanceGrid | None:
    try:
        with np.load(_cache_file(key)) as data:
            return DistanceGrid(data["origin"], float(data["cell"]), data["distance"],
                                data["gradient"])
    except (OSError, KeyError, ValueError):    # absent, unreadable or damaged: build again
        return None


def _write(key: str, grid: DistanceGrid) -> DistanceGrid:
    """Cache `grid` on disk (a cache that cannot be written is skipped: the grid still works)."""
    try:
        with atomic_path(_cache_file(key)) as tmp:
            np.savez(tmp, origin=grid.origin, cell=grid.cell, distance=grid.distance,
                     gradient=grid.gradient)
    except OSError:
        pass
    return grid


def build(vertices: np.ndarray, triangles: np.ndarray, resolution: int,
          margin: float) -> DistanceGrid:
    """Compute the grid (see the module doc) with libigl."""
    try:
        import igl
        from scipy import ndimage
    except ImportError as err:
        raise ImportError("mesh colliders build their distance grid with libigl: "
                          "pip install libigl scipy (both are ti_cloth dependencies: reinstall it)") from err
    origin, cell, shape = layout(vertices, resolution, margin)
    axes = [origin[a] + cell * np.arange(shape[a]) for a in range(3)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    unsigned, _, closest, _ = igl.signed_distance(nodes, vertices, triangles,
                                                  sign_type=igl.SIGNED_DISTANCE_TYPE_UNSIGNED,
                                                  lower_bound=-margin, upper_bound=margin)
    far = ~(np.abs(unsigned) < margin)       # NaN, or a bound rather than a distance
    if far.all():                            # no node near the surface (a coarse grid)
        unsigned, _, closest, _ = igl.signed_distance(
            nodes, vertices, triangles, sign_type=igl.SIGNED_DISTANCE_TYPE_UNSIGNED)
        far[:] = False
    _, nearest = ndimage.distance_transform_edt(far.reshape(shape), return_indices=True)
    nearest = np.ravel_multi_index(tuple(nearest.reshape(3, -1)), shape)
    closest = np.where(far[:, None], closest[nearest], closest)
    away = nodes - closest
    unsigned = np.linalg.norm(away, axis=1)
    winding = igl.fast_winding_number(vertices, triangles, nodes)
    sign = np.where(np.abs(winding) > INSIDE, -1.0, 1.0)
    grid_distance = (sign * unsigned).reshape(shape)
    exact = unsigned > 1e-9 * cell             # else the node is on the surface: no direction
    gradient = sign[:, None] * away / np.where(exact, unsigned, 1.0)[:, None]
    if not exact.all():
        differences = np.stack(np.gradient(grid_distance, cell), axis=-1).reshape(-1, 3)
        gradient[~exact] = differences[~exact]
    norm = np.linalg.norm(gradient, axis=1)
    gradient = np.where(norm[:, None] > 0, gradient / np.maximum(norm, 1e-300)[:, None],
                        (0.0, 1.0, 0.0))
    return DistanceGrid(origin, cell, grid_distance.astype(np.float32),
                        gradient.reshape(*shape, 3).astype(np.float32))


def mesh_distance(vertices: np.ndarray, triangles: np.ndarray, points: np.ndarray,
                  solid: bool) -> tuple[np.ndarray, np.ndarray]:
    """(distance [m] of each point (N, 3) from the triangles' surface, negative inside when
    `solid` (winding number, as the grids); unit normal away from the closest point, outward
    inside) by libigl, exactly (no grid)."""
    try:
        import igl
    except ImportError as err:
        raise ImportError("distances to meshes are measured with libigl: "
                          "pip install libigl scipy (both are ti_cloth dependencies: reinstall it)") from err
    vertices = np.ascontiguousarray(vertices, np.float64)
    triangles = np.ascontiguousarray(triangles, np.int64)
    unsigned, _, closest, _ = igl.signed_distance(points, vertices, triangles,
                                                  sign_type=igl.SIGNED_DISTANCE_TYPE_UNSIGNED)
    away = points - closest
    length = np.linalg.norm(away, axis=1)
    sign = np.ones(len(points))
    if solid:
        sign = np.where(np.abs(igl.fast_winding_number(vertices, triangles, points)) > INSIDE,
                        -1.0, 1.0)
    normal = sign[:, None] * away / np.where(length > 0, length, 1.0)[:, None]
    return sign * np.abs(unsigned), normal


def nearest_triangles(vertices: np.ndarray, triangles: np.ndarray, points: np.ndarray
                      ) -> np.ndarray:
    """The index of the triangle nearest each point (N, 3), by libigl (an AABB tree)."""
    try:
        import igl
    except ImportError as err:
        raise ImportError("nearest triangles are found with libigl: "
                          "pip install libigl scipy (both are ti_cloth dependencies: reinstall it)") from err
    _, index, _ = igl.point_mesh_squared_distance(np.ascontiguousarray(points, np.float64),
                                                  np.ascontiguousarray(vertices, np.float64),
                                                  np.ascontiguousarray(triangles, np.int64))
    return np.asarray(index, np.int64)


@ti.func
def sample_grid(samples: ti.template(), start, shape, origin, cell, q):
    """(distance [m], gradient) of the grid whose nodes are samples[start:] (DistanceGrid.samples
    layout; shape: nodes per axis; node 0 at `origin` [m], spaced `cell` [m]) at q [m],
    interpolated trilinearly. Beyond the grid: the distance at the nearest point of its box
    plus the distance to it, the gradient pointing away from the box."""
    u = (q - origin) / cell
    inner = ti.math.clamp(u, 0.0, ti.cast(shape - 1, float))
    base = ti.min(ti.cast(ti.floor(inner), ti.i32), shape - 2)
    f = inner - ti.cast(base, float)
    value = ti.Vector([0.0, 0.0, 0.0, 0.0])
    for corner in ti.static(range(8)):
        di, dj, dk = ti.static(corner >> 2, (corner >> 1) & 1, corner & 1)
        weight = ((f[0] * di + (1 - f[0]) * (1 - di)) * (f[1] * dj + (1 - f[1]) * (1 - dj))
                  * (f[2] * dk + (1 - f[2]) * (1 - dk)))
        node = ((base[0] + di) * shape[1] + base[1] + dj) * shape[2] + base[2] + dk
        value += weight * samples[start + node]
    d = value[0]
    g = ti.Vector([value[1], value[2], value[3]])
    outside = (u - inner) * cell
    if outside.norm() > 0:
        d += outside.norm()
        g = outside / outside.norm()
    return d, g
