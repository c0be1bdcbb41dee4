"""Tethers: long-range attachments (Kim, Chentanez & Mueller, "Long range attachments - a
method to simulate inextensible clothing in computer games", SCA 2012), XPBD's option
`tethers` (integrators/xpbd.py). Not an energy: a unilateral limit, one per particle and
anchor (a pinned particle), that the particle stays within (1 + s) of its rest geodesic
distance L from the anchor,

    C(x) = |x_i - x_a| - (1 + s) L_ia <= 0,

with s the strain allowed (XPBD.tethers). The anchor is pinned (inverse mass 0), so the
projection moves the particle alone, onto the sphere of that radius: the limit's exact
projection, each particle independent of every other (one parallel loop, no colours). With
two anchors the projection is onto the intersection of the two balls, in closed form
(tether_at): projected onto one at a time, a particle between two pins, where the balls
barely overlap, crept toward their lens by a small part of its excess a round.

Why: a stiff membrane's Gauss-Seidel passes carry a pin's hold one ring of triangles a pass, so
at the steps garments take the passes leave the far cloth hanging from a softer sheet than its
material (issue 53's denim sheet, BDF2 step, 10 passes at 1/240 s: 41 mm from the elastic
sheet, where the converged step is 4.5 mm from it). No
unstretched shape violates a tether (a path in the cloth is at least as long as the straight
line between its ends), and a cloth that stretches by less than s along its paths from the
pins never meets one; what the passes leave beyond that, the tether takes back in one move.
What they cost in physics: a cloth that really stretches by more than s between a pin and a
particle (a soft knit; a stiff one near a pin's stress concentration) is held short there
(docs/integrators.md, "Tethers").

The rest geodesic distance: Dijkstra over the rest mesh's edges (seams joined at no length:
Cloth.seam_indices; a body without triangles, a string or hair, along its stretch springs), at
least the geodesic, and exact where the rest shape is flat and the straight line to the anchor
stays inside the mesh (no boundary edge crossed): a garment's pattern (Cloth(rest="uv")), a
flat sheet; and never shorter than where the body was placed (a garment starts gathered and
wrapped, farther from its pins than its pattern says). Each particle keeps its TETHERS
nearest anchors by that distance, a table for each set of pins (integrators/xpbd.py
XPBD.loaded_workspace); an anchor let go (its inverse mass read in the pass) holds nothing.
XPBD(tethers="auto") takes s from the body (expected_strain).
"""

import heapq

import numpy as np
import taichi as ti

from ..runtime.plan import ITEM, STATE, Loop, Phase

TETHERS = 2             # anchors per particle, at most (tether_at projects onto both)
XPBD_TETHER_STRAIN = 3  # the settings' slot of s (integrators/base.py SETTINGS)
FLAT = 1e-9             # a rest shape within this x its extent of a plane is flat
SWING = 2.5             # a uniform strip swung down from level pulls its pin with 2.5x its weight
GRAVITY = 9.81          # [m/s^2]: expected_strain's load
ACCEPTED = 1e-9         # a point this far (relative) past a ball's radius is in it (rounding)


def tether_table(rest: np.ndarray, triangles: np.ndarray, chain: np.ndarray, seams: np.ndarray,
                 pinned: np.ndarray, start: np.ndarray | None = None,
                 count: int = TETHERS) -> tuple[np.ndarray, np.ndarray]:
    """(anchors (N, count) int32, -1 where none; rest lengths (N, count) [m]) of a body's
    particles at `rest` (N, 3) to their `count` nearest anchors among the `pinned` (N,) bool
    (module doc), nearest first: paths along its `triangles`' edges (T, 3), or without
    triangles along `chain` (C, 2) (a string's stretch springs), joined across `seams`
    (S, 2); no tether shorter than the straight distance at `start` (N, 3), where the body is
    placed (a garment placed gathered and wrapped lies up to 1.4x its pattern's geodesic from
    its pins: tethers shorter than that would snap it at its first step). A particle no
    anchor reaches, an anchor itself, and every particle of a body with neither, has none."""
    n = len(rest)
    anchors = np.full((n, count), -1, np.int32)
    lengths = np.zeros((n, count))
    triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
    edges, uses = np.unique(np.sort(triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1),
                            axis=0, return_counts=True)
    boundary = edges[uses == 1]
    if not len(triangles):
        edges = np.asarray(chain, np.int64).reshape(-1, 2)
    sources = np.flatnonzero(pinned)
    if not len(edges) or not len(sources):
        return anchors, lengths
    rest = np.asarray(rest, np.float64)
    seams = np.asarray(seams, np.int64).reshape(-1, 2)
    ends = np.concatenate([edges, seams])
    weights = np.concatenate([np.linalg.norm(rest[edges[:, 0]] - rest[edges[:, 1]], axis=1),
                              np.zeros(len(seams))])
    found = nearest_sources(n, ends, weights, sources, count)
    for i, row in enumerate(found):
        if not pinned[i]:
            for k, (source, length) in enumerate(row):
                anchors[i, k], lengths[i, k] = source, length
    taken = anchors >= 0
    if len(triangles):              # (a string's chord is shorter than its path)
        straight = straight_inside(rest, boundary, anchors)
        direct = np.linalg.norm(rest[:, None, :] - rest[np.maximum(anchors, 0)], axis=2)
        lengths = np.where(taken & straight, np.minimum(direct, lengths), lengths)
    if start is not None:
        start = np.asarray(start, np.float64)
        placed = np.linalg.norm(start[:, None, :] - start[np.maximum(anchors, 0)], axis=2)
        lengths = np.where(taken, np.maximum(lengths, placed), lengths)
    order = np.argsort(np.where(taken, lengths, np.inf), axis=1, kind="stable")  # nearest first
    return (np.take_along_axis(anchors, order, axis=1),
            np.take_along_axis(lengths, order, axis=1))


def expected_strain(mass: float, extent: float, modulus: float, longest: float) -> float:
    """XPBD(tethers="auto")'s s: the strain at the pin of a strip of the body as long as its
    longest tether [m], swung down from level under gravity: SWING g rho L / E, the tension
    of a uniform rod at the bottom of that swing (2.5 m g) over the strip's width, with rho =
    mass [kg] / extent (its rest area [m^2]; a string's rest length [m]) and E = modulus, its
    weakest in-plane stretch modulus [N/m] (weakest_modulus; a string's springs' k l [N]).
    On issue 53's denim-like sheet 0.20 %; on the denim preset, soft in shear, 4.3 %; on the
    interlock knit of demos/study_fabric.toml 17 %, where tethers at 0.1 % held it short, 4x
    farther from the elastic flap than BDF2's passes alone. 0 where nothing is known (no
    extent, no stiffness)."""
    if extent <= 0.0 or modulus <= 0.0 or longest <= 0.0:
        return 0.0
    return SWING * GRAVITY * mass / extent * longest / modulus


def weakest_modulus(moduli: np.ndarray) -> np.ndarray:
    """(F,) each triangle's least Young's modulus over in-plane directions [N/m], from its
    plane-stress (C11, C12, C22, C33) (F, 4): 1 / E(t) = S11 c^4 + S22 s^4 + (2 S12 + S33)
    s^2 c^2 with S = C^-1 (c, s the direction's cosine and sine), sampled every degree. A
    woven fabric soft in shear is weakest on the bias (issue 53's denim-like sheet: 2.9 kN/m
    at 45 degrees against 5 kN/m along its threads; the denim preset 156 N/m against 205)."""
    rows, inverse = np.unique(np.asarray(moduli, np.float64).reshape(-1, 4), axis=0,
                              return_inverse=True)
    c11, c12, c22, c33 = rows.T
    det = c11 * c22 - c12 * c12
    s11, s22, s12, s33 = c22 / det, c11 / det, -c12 / det, 1.0 / c33
    angle = np.radians(np.arange(180.0))[:, None]
    c, s = np.cos(angle), np.sin(angle)
    compliance = s11 * c ** 4 + s22 * s ** 4 + (2.0 * s12 + s33) * s * s * c * c
    return (1.0 / compliance.max(axis=0))[inverse.reshape(-1)]


def nearest_sources(n: int, ends: np.ndarray, weights: np.ndarray, sources, count: int) -> list:
    """For each of n nodes, up to `count` (source, distance) of the nearest distinct sources
    over the undirected graph (ends (E, 2), weights (E,) >= 0), nearest first: Dijkstra from
    all sources at once, each node settled once per source, at most `count` times."""
    order = np.argsort(np.concatenate([ends[:, 0], ends[:, 1]]), kind="stable")
    other = np.concatenate([ends[:, 1], ends[:, 0]])[order]
    weight = np.concatenate([weights, weights])[order]
    start = np.concatenate([[0], np.cumsum(np.bincount(np.concatenate([ends[:, 0], ends[:, 1]]),
                                                        minlength=n))])
    found = [[] for _ in range(n)]
    heap = [(0.0, int(s), int(s)) for s in sources]
    heapq.heapify(heap)
    while heap:
        d, v, s = heapq.heappop(heap)
        row = found[v]
        if len(row) >= count or any(s == r[0] for r in row):
            continue
        row.append((s, d))
        for a in range(start[v], start[v + 1]):
            u = int(other[a])
            if len(found[u]) < count:
                heapq.heappush(heap, (d + float(weight[a]), u, s))
    return found


def straight_inside(rest: np.ndarray, boundary: np.ndarray, anchors: np.ndarray) -> np.ndarray:
    """(N, K) bool: where the rest shape is flat, whether the straight segment from each
    particle to each of its anchors stays in the mesh (crosses no `boundary` edge (B, 2),
    nor passes through a boundary corner; running along the boundary is inside); all False
    on a curved rest shape."""
    straight = np.zeros(anchors.shape, bool)
    centre = rest.mean(axis=0)
    extent = float(np.ptp(rest, axis=0).max()) if len(rest) else 0.0
    _, _, axes = np.linalg.svd(rest - centre, full_matrices=False)
    if extent == 0.0 or np.abs((rest - centre) @ axes[2]).max() > FLAT * extent:
        return straight
    flat = (rest - centre) @ axes[:2].T
    b0, b1 = flat[boundary[:, 0]], flat[boundary[:, 1]]
    zero = FLAT * extent * extent
    rows, ks = np.nonzero(anchors >= 0)
    chunk = max(1, 2_000_000 // max(len(boundary), 1))
    for begin in range(0, len(rows), chunk):
        i, k = rows[begin:begin + chunk], ks[begin:begin + chunk]
        p, q = flat[i][:, None, :], flat[anchors[i, k]][:, None, :]
        d1, d2 = _orient(p, q, b0), _orient(p, q, b1)
        d3, d4 = _orient(b0, b1, p), _orient(b0, b1, q)
        d1, d2, d3, d4 = (np.where(np.abs(d) <= zero, 0.0, d) for d in (d1, d2, d3, d4))
        collinear = (d1 == 0.0) & (d2 == 0.0)
        crossed = (d1 * d2 <= 0.0) & (d3 * d4 < 0.0) & ~collinear
        straight[i, k] = ~crossed.any(axis=1)
    return straight


def _orient(a, b, c):
    """Twice the signed area of the 2-D triangles (a, b, c) (broadcast)."""
    return ((b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
            - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0]))


@ti.func
def _onto(x, centre, radius):
    """The point of the ball (centre, radius) nearest x."""
    d = x - centre
    distance = d.norm()
    if distance > radius:
        x = centre + (radius / distance) * d
    return x


@ti.func
def tether_at(model: ti.template(), state: ti.template(), work: ti.template(), i):
    """Particle i moved to the nearest point within both its tethers (module doc): its
    projection onto one ball where that lies in the other, else the nearest point of the
    circle where the two spheres meet (both limits active: the optimum lies on both); where
    the balls do not meet (handles pulled the pins apart), the second anchor's. An anchor let
    go (inverse mass > 0) holds nothing."""
    if model.particle_inv_mass[i] > 0.0:
        x = state.particle_position[i]
        allowed = 1.0 + ti.cast(work.settings[XPBD_TETHER_STRAIN], float)
        a, b = work.tether_anchor[i][0], work.tether_anchor[i][1]
        held_a = a >= 0 and model.particle_inv_mass[ti.max(a, 0)] == 0.0
        held_b = b >= 0 and model.particle_inv_mass[ti.max(b, 0)] == 0.0
        ca, cb = state.particle_position[ti.max(a, 0)], state.particle_position[ti.max(b, 0)]
        ra, rb = allowed * work.tether_length[i][0], allowed * work.tether_length[i][1]
        if held_a and not held_b:
            x = _onto(x, ca, ra)
        elif held_b and not held_a:
            x = _onto(x, cb, rb)
        elif held_a and held_b and ((x - ca).norm() > ra or (x - cb).norm() > rb):
            on_a, on_b = _onto(x, ca, ra), _onto(x, cb, rb)
            if (on_a - cb).norm() <= rb * (1.0 + ACCEPTED):
                x = on_a
            elif (on_b - ca).norm() <= ra * (1.0 + ACCEPTED):
                x = on_b
            else:
                axis = cb - ca
                apart = axis.norm()
                u = axis / ti.max(apart, 1e-30)
                along = (apart * apart + ra * ra - rb * rb) / (2.0 * ti.max(apart, 1e-30))
                squared = ra * ra - along * along
                x = on_b
                if apart > 0.0 and squared > 0.0:
                    w = x - ca
                    w = w - w.dot(u) * u
                    if w.norm() > 0.0:
                        x = ca + along * u + (ti.sqrt(squared) / w.norm()) * w
        state.particle_position[i] = x


def xpbd_nodes(model, forces, work) -> tuple:
    """(loops clearing multipliers: none, sweeps) of XPBD's tethers: one loop over the
    particles at the end of each pass where the workspace has them (XPBD.tethers)."""
    if not getattr(work, "tethered", False):
        return (), ()
    return (), (Phase(Loop(model.particle_count, tether_at, model, STATE, work, ITEM)),)
