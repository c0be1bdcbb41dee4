"""Garments from flat pattern panels, as a tailor (and Marvelous Designer, Blender's sewing
springs) makes them: each panel a polygon cut from flat cloth, triangulated at a chosen edge
length, placed around the body (wrapped onto a cylinder, turned, moved), and seams pairing
boundary edges of panels, which the sewing stage (physics/sewing.py) pulls together.

Triangulation: the outline's edges are divided into pieces of at most `edge_length`, the
inside is filled with an equilateral lattice of that spacing (kept half a spacing from the
outline), and the points are joined by scipy's Delaunay triangulation (Qhull), keeping the
triangles inside the outline. The lattice makes equilateral triangles (a fabric's elements
converge best on them); a lattice has no four points on one empty circle, so the result is
the same on every machine. Why scipy and not Shewchuk's Triangle (the usual quality mesher,
through the `triangle` or `meshpy` packages): Triangle's licence forbids selling it or
including it in commercial products without the author's permission, which would bind every
user of ti_cloth; scipy is BSD and Qhull's licence is permissive. The cost: no constrained
triangulation, so an outline with a corner sharper than about 60 degrees, or a part narrower
than two edge lengths, may lose an outline edge; that is refused, naming the edge.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..inputs import limits
from ..inputs.validation import as_array, finite_number, in_range, require
from .mesh import Mesh

MAX_PANEL_POINTS = 1_000_000
MAX_LATTICE = 4_000_000   # lattice points over the outline's box, before those outside go
SMOOTHING_PASSES = 3      # Laplacian passes on the lattice points next to the outline
PLEAT_EDGES = 4           # a gathered panel's pleats, in edge lengths (the shortest wave drawn well)
PLEAT_NEWTON = 8          # Newton iterations placing a point along its pleats


@dataclass(frozen=True)
class Panel:
    """A triangulated pattern piece.

    flat: (V, 2) its points on the flat pattern [m] (also the mesh's uvs: a Fabric's warp
        follows the pattern's x with Cloth(warp="uv")).
    mesh: the panel where it is placed [m] (at first flat in the z = 0 plane).
    edges: for each outline edge k (from outline point k to point k + 1), the indices of the
        panel's points along it, in that order, both corners included.
    wrapped_radius: the cylinder it was wrapped on, or None.
    """

    flat: np.ndarray
    mesh: Mesh
    edges: tuple
    wrapped_radius: float | None = None
    placed: bool = False

    def wrapped(self, radius: float, flare: float = 0.0, gather: float = 1.0) -> Panel:
        """The flat panel bent round the vertical (y) axis, its pattern x running round it
        (x = 0 on the +z side, x > 0 towards +x), as a skirt panel wraps round hips: onto a
        cylinder of `radius` [m], or with `flare` > 0 onto a cone widening downwards from
        `radius` at the panel's top by `flare` m of radius per m of height (an A-line
        skirt). The pattern's vertical lines keep their length; each horizontal line keeps
        its length round its circle (on a cylinder the wrap is exact: every length is kept),
        times `gather` at the top: with gather < 1 the top edge is placed gathered to that
        fraction of its length, easing linearly to its full length at the bottom (a cape
        gathered at the neck, a skirt into its waistband), each line laid in radial pleats of
        PLEAT_EDGES edge lengths whose depth keeps its length (pleat_slope), so the placed
        cloth starts buckled, not squeezed (its rest state is still the flat pattern).
        Call before moved()."""
        require(not self.placed and self.wrapped_radius is None, "Panel.wrapped", radius,
                "called once, on a panel not yet moved (wrap, then move)")
        radius = in_range("Panel.wrapped radius", radius, limits.LENGTH)
        flare = finite_number("Panel.wrapped flare", flare, 0.0)
        gather = in_range("Panel.wrapped gather", gather, limits.GATHER)
        x, y = self.flat[:, 0], self.flat[:, 1]
        below = y.max() - y
        slope = np.arctan(flare)
        circle = radius + below * np.sin(slope)
        share = gather + (1.0 - gather) * below / np.ptp(y)    # placed / pattern length
        wave = 2 * np.pi / (PLEAT_EDGES * self.edge_length)
        steep = pleat_slope(1.0 / share)
        arc = pleated(x, share, steep, wave)
        angle = arc / circle
        least = (np.abs(x) / np.pi - below * np.sin(slope)).max()
        require(np.abs(angle).max() <= np.pi, "Panel.wrapped radius", radius,
                f"at least {least:.3g} m for this panel: wrapped further than half round each "
                "way, it would pass through itself")
        circle = circle + steep / wave * np.sin(wave * arc)
        vertices = np.column_stack([circle * np.sin(angle), y.max() - below * np.cos(slope),
                                    circle * np.cos(angle)])
        return replace(self, mesh=Mesh(vertices, self.mesh.triangles, uvs=self.flat),
                       wrapped_radius=radius)

    @property
    def edge_length(self) -> float:
        """The median edge of its triangles on the flat pattern [m] (about panel()'s)."""
        corners = self.flat[self.mesh.triangles]
        return float(np.median(np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)))

    def moved(self, translate=(0.0, 0.0, 0.0), rotate=(0.0, 0.0, 0.0)) -> Panel:
        """The panel turned by the rotation vector `rotate` (axis x angle [rad]) about the
        origin, then moved by `translate` [m]."""
        from scipy.spatial.transform import Rotation

        turn = as_array("Panel.moved rotate", rotate, np.float64, (3,))
        shift = as_array("Panel.moved translate", translate, np.float64, (3,))
        matrix = Rotation.from_rotvec(turn).as_matrix()
        vertices = self.mesh.vertices @ matrix.T + shift
        return replace(self, mesh=Mesh(vertices, self.mesh.triangles, uvs=self.flat),
                       placed=True)


def pleat_slope(ratio) -> np.ndarray:
    """The slope a = A k of radial pleats A sin(k s) whose length is `ratio` (>= 1) times the
    line they are laid along: the mean of sqrt(1 + a^2 cos^2) over a period (a complete
    elliptic integral, tabulated and inverted)."""
    slopes = np.linspace(0.0, 40.0, 4001)
    phase = np.linspace(0.0, 2 * np.pi, 256, endpoint=False)
    lengths = np.sqrt(1.0 + np.outer(slopes ** 2, np.cos(phase) ** 2)).mean(axis=1)
    return np.interp(ratio, lengths, slopes)


def pleated(x: np.ndarray, share: np.ndarray, slope: np.ndarray, wave: float) -> np.ndarray:
    """Where along its line a point x of the pattern lies once the line is laid in pleats
    (slope / wave) sin(wave s) [m]: the s whose length along the pleats from 0 is x, so that
    every piece keeps its length, by Newton's method on the length's closed form
    sqrt(1 + a^2) E(wave s | a^2 / (1 + a^2)) / wave (E: the incomplete elliptic integral of
    the second kind), from s = x share."""
    from scipy.special import ellipeinc

    grow = np.sqrt(1.0 + slope ** 2)
    m = slope ** 2 / grow ** 2
    s = x * share
    for _ in range(PLEAT_NEWTON):
        length = grow * ellipeinc(wave * s, m) / wave
        s = s - (length - x) / np.sqrt(1.0 + (slope * np.cos(wave * s)) ** 2)
    return s


def panel(outline, edge_length: float) -> Panel:
    """A flat pattern panel: the polygon `outline` (K, 2) [m] (either orientation; it must
    not cross itself) triangulated with edges of about `edge_length` [m] (module doc)."""
    outline = as_array("outline", outline, np.float64, (None, 2))
    require(len(outline) >= 3, "outline", outline.tolist(), "at least 3 points (a polygon)")
    for k, point in enumerate(outline):
        for axis in range(2):
            in_range(f"outline[{k}][{axis}]", point[axis], limits.COORDINATE)
    h = finite_number("edge_length", edge_length, 0.0, strict=True, unit="m")
    in_range("edge_length", h, limits.LENGTH)
    ends = np.roll(outline, -1, axis=0)
    lengths = np.linalg.norm(ends - outline, axis=1)
    short = np.flatnonzero(lengths <= 0)
    require(len(short) == 0, f"outline[{short[:1].tolist()}]", outline[short[:1]].tolist(),
            "a point apart from the next one (no edge of zero length)")
    crossing = _crossing_edges(outline)
    require(crossing is None, "outline", outline.tolist(),
            f"a polygon that does not cross itself (edges {crossing} cross)")
    area = 0.5 * np.sum(outline[:, 0] * ends[:, 1] - ends[:, 0] * outline[:, 1])
    narrowest = 2 * abs(area) / lengths.max()        # the outline's height over its longest edge
    require(narrowest >= 0.5 * h, "outline", outline.tolist(),
            f"a polygon at least half an edge_length ({0.5 * h:.3g} m) wide: this one is "
            f"{narrowest:.3g} m across its longest edge (its points are (nearly) in a line)")
    estimate = abs(area) / (0.43 * h * h) + lengths.sum() / h
    require(estimate <= MAX_PANEL_POINTS, "edge_length", h,
            f"at least {np.sqrt(abs(area) / (0.43 * MAX_PANEL_POINTS)):.3g} m for this outline "
            f"(at most {MAX_PANEL_POINTS:,} points)")
    extent = np.ptp(outline, axis=0)
    lattice_size = (extent[0] / h + 3) * (extent[1] / (h * np.sqrt(3) / 2) + 2)
    require(lattice_size <= MAX_LATTICE, "edge_length", h,
            f"at least {np.sqrt(extent.prod() / (0.86 * MAX_LATTICE)):.3g} m for an outline "
            f"this size ({extent[0]:.3g} x {extent[1]:.3g} m: the lattice fills its box)")
    # the outline's points: every edge in pieces of at most h
    pieces = np.maximum(1, np.ceil(lengths / h - 1e-9).astype(np.int64))
    boundary, edges, start = [], [], 0
    for k, n in enumerate(pieces):
        s = np.arange(n)[:, None] / n
        boundary.append(outline[k] + s * (ends[k] - outline[k]))
        edges.append(np.append(start + np.arange(n), (start + n) % pieces.sum()))
        start += n
    boundary = np.concatenate(boundary)
    edges = tuple(e.astype(np.int64) for e in edges)
    # the inside: an equilateral lattice, half a spacing clear of the outline
    columns = np.arange(outline[:, 0].min() - h, outline[:, 0].max() + h, h)
    rows = np.arange(outline[:, 1].min(), outline[:, 1].max() + h, h * np.sqrt(3) / 2)
    row, column = np.meshgrid(np.arange(len(rows)), np.arange(len(columns)), indexing="ij")
    lattice = np.column_stack([columns[column.ravel()] + (h / 2) * (row.ravel() % 2),
                               rows[row.ravel()]])
    keep = _inside(lattice, outline) & (_distance_to_outline(lattice, outline) >= 0.5 * h)
    points = np.concatenate([boundary, lattice[keep]])
    triangles = _triangulate(points, outline, edges)
    points = _smoothed(points, triangles, len(boundary))
    vertices = np.column_stack([points, np.zeros(len(points))])
    return Panel(points, Mesh(vertices, triangles, uvs=points), edges)


def _triangulate(points: np.ndarray, outline: np.ndarray, edges) -> np.ndarray:
    from scipy.spatial import Delaunay

    simplices = Delaunay(points).simplices.astype(np.int64)
    centroids = points[simplices].mean(axis=1)
    triangles = simplices[_inside(centroids, outline)]
    a, b, c = (points[triangles[:, k]] for k in range(3))
    turn = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]
    triangles[turn < 0] = triangles[turn < 0][:, [0, 2, 1]]      # all counter-clockwise
    present = {tuple(sorted(e)) for t in triangles for e in ((t[0], t[1]), (t[1], t[2]),
                                                             (t[2], t[0]))}
    for k, edge in enumerate(edges):
        lost = [(int(i), int(j)) for i, j in zip(edge[:-1], edge[1:])
                if tuple(sorted((i, j))) not in present]
        require(not lost, f"outline edge {k}", f"{len(lost)} of its pieces lost",
                "kept by the triangulation: an outline corner sharper than about 60 degrees "
                "or a part narrower than two edge lengths loses them; use a smaller "
                "edge_length or a blunter outline")
    used = np.zeros(len(points), bool)
    used[triangles.ravel()] = True
    require(bool(used.all()), "outline", outline.tolist(), "a polygon whose every point "
            "is joined to the triangulation")
    return triangles


def _smoothed(points: np.ndarray, triangles: np.ndarray, fixed: int) -> np.ndarray:
    """The lattice points next to the outline moved towards their neighbours' mean (a few
    Laplacian passes; the outline stays), undone where a triangle would turn over."""
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    edges = np.concatenate([edges, edges[:, ::-1]])
    count = np.bincount(edges[:, 0], minlength=len(points)).astype(np.float64)
    moved = points.copy()
    for _ in range(SMOOTHING_PASSES):
        total = np.zeros_like(moved)
        np.add.at(total, edges[:, 0], moved[edges[:, 1]])
        trial = moved.copy()
        trial[fixed:] = total[fixed:] / count[fixed:, None]
        a, b, c = (trial[triangles[:, k]] for k in range(3))
        turn = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]
        if (turn <= 0).any():
            break
        moved = trial
    return moved


def _inside(points: np.ndarray, outline: np.ndarray) -> np.ndarray:
    """Even-odd rule: whether each point is inside the polygon."""
    inside = np.zeros(len(points), bool)
    x, y = points[:, 0], points[:, 1]
    for (x0, y0), (x1, y1) in zip(outline, np.roll(outline, -1, axis=0)):
        straddles = (y0 > y) != (y1 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            cross = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
        inside ^= straddles & (x < cross)
    return inside


def _distance_to_outline(points: np.ndarray, outline: np.ndarray) -> np.ndarray:
    best = np.full(len(points), np.inf)
    for p, q in zip(outline, np.roll(outline, -1, axis=0)):
        s = np.clip((points - p) @ (q - p) / ((q - p) @ (q - p)), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(p + s[:, None] * (q - p) - points, axis=1))
    return best


def _crossing_edges(outline: np.ndarray):
    """(k, l) of two non-adjacent outline edges that cross, or None."""
    count = len(outline)
    ends = np.roll(outline, -1, axis=0)

    def side(a, b, c):
        return np.sign((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))

    for k in range(count):
        for m in range(k + 2, count):
            if k == 0 and m == count - 1:
                continue
            p, q, r, s = outline[k], ends[k], outline[m], ends[m]
            if side(p, q, r) * side(p, q, s) < 0 and side(r, s, p) * side(r, s, q) < 0:
                return (k, m)
    return None


@dataclass(frozen=True)
class Garment:
    """Panels sewn together: one mesh of all their points (panel after panel) and the seams'
    particle pairs.

    panels: Panel objects, placed. seams: (panel_a, edge_a, panel_b, edge_b) each, pairing
    outline edge edge_a of panel_a with edge_b of panel_b, a's start with b's end (two
    panels both drawn counter-clockwise and laid face to face meet that way); points are
    paired by their place along the edges, each with the nearest on the other edge.
    """

    panels: Sequence[Panel]
    seams: Sequence[tuple]

    def __post_init__(self):
        panels = tuple(self.panels)
        require(len(panels) > 0 and all(isinstance(p, Panel) for p in panels), "panels",
                self.panels, "a non-empty list of Panel objects (tc.panel)")
        seams = [tuple(s) if isinstance(s, (list, tuple)) else s for s in self.seams]
        used = set()
        for k, seam in enumerate(seams):
            require(isinstance(seam, tuple) and len(seam) == 4
                    and all(isinstance(v, (int, np.integer)) and not isinstance(v, bool)
                            for v in seam), f"seams[{k}]", seam,
                    "(panel_a, edge_a, panel_b, edge_b), four indices")
            for p, e in (seam[:2], seam[2:]):
                require(0 <= p < len(panels), f"seams[{k}] panel", p,
                        f"a panel index in [0, {len(panels) - 1}]")
                require(0 <= e < len(panels[p].edges), f"seams[{k}] edge of panel {p}", e,
                        f"an outline edge in [0, {len(panels[p].edges) - 1}]")
                require((p, e) not in used, f"seams[{k}]", seam,
                        f"edges sewn once (edge {e} of panel {p} is in another seam)")
                used.add((p, e))
        object.__setattr__(self, "panels", panels)
        object.__setattr__(self, "seams", tuple(seams))

    @property
    def offsets(self) -> np.ndarray:
        """The index of each panel's first point in the garment's mesh."""
        return np.cumsum([0] + [p.mesh.vertex_count for p in self.panels[:-1]])

    @property
    def mesh(self) -> Mesh:
        """All panels' points and triangles, panel after panel (uvs: the flat pattern)."""
        offsets = self.offsets
        return Mesh(np.concatenate([p.mesh.vertices for p in self.panels]),
                    np.concatenate([p.mesh.triangles + o for p, o in zip(self.panels, offsets)]),
                    uvs=np.concatenate([p.flat for p in self.panels]))

    def particles(self, panel_index: int, edge: int | None = None) -> np.ndarray:
        """The garment's particles of a panel, or of one of its outline edges (a waistband
        to attach, a hem to weight)."""
        require(0 <= panel_index < len(self.panels), "panel", panel_index,
                f"a panel index in [0, {len(self.panels) - 1}]")
        chosen = self.panels[panel_index]
        offset = self.offsets[panel_index]
        if edge is None:
            return offset + np.arange(chosen.mesh.vertex_count)
        require(0 <= edge < len(chosen.edges), "edge", edge,
                f"an outline edge in [0, {len(chosen.edges) - 1}]")
        return offset + chosen.edges[edge]

    @property
    def seam_pairs(self) -> np.ndarray:
        """(P, 2) particle pairs the seams pull together (Cloth(seams=...))."""
        pairs = []
        for pa, ea, pb, eb in self.seams:
            a = self.particles(pa, ea)
            b = self.particles(pb, eb)[::-1]
            place_a = _arc_places(self.panels[pa].flat[a - self.offsets[pa]])
            place_b = _arc_places(self.panels[pb].flat[b - self.offsets[pb]])
            nearest_b = np.abs(place_a[:, None] - place_b[None]).argmin(axis=1)
            nearest_a = np.abs(place_b[:, None] - place_a[None]).argmin(axis=1)
            pairs += list(zip(a, b[nearest_b])) + list(zip(a[nearest_a], b))
        if not pairs:
            return np.zeros((0, 2), np.int64)
        return np.unique(np.sort(np.array(pairs, np.int64), axis=1), axis=0)


def _arc_places(points: np.ndarray) -> np.ndarray:
    """Each point's place along the polyline, from 0 at the first to 1 at the last."""
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    along = np.concatenate([[0.0], np.cumsum(steps)])
    return along / along[-1]
