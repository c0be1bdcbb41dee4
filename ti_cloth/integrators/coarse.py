"""A coarse level for the conjugate gradients of the implicit solvers: the two-level additive
preconditioner

    z = D^-1 r + P A_c^-1 P^T r,   A_c = P^T A P,

D the 3x3 diagonal of A (Jacobi, conjugate_gradients.py) and P the prolongation of plain
aggregation (Vanek, Mandel & Brezina, "Algebraic multigrid by smoothed aggregation for second
and fourth order elliptic problems", Computing 56, 1996, sec. 3, without the smoothing of P):
the particles are grouped into aggregates of about `size` neighbours, and P copies an
aggregate's 3-vector to every free particle of it (a translation of the aggregate), so
P^T sums a vector over an aggregate's free particles. Jacobi alone leaves the smooth modes:
on a stiff membrane, h^2 k / m of 10^3-10^4, hundreds of CG iterations are the slow
decay of the smooth in-plane stretches, which the aggregates' translations span; the coarse
solve removes them in one application. Both parts are symmetric positive definite, so CG
applies unchanged (Saad, "Iterative methods for sparse linear systems", 2nd ed. 2003,
sec. 14.4: additive two-level Schwarz; Smith, Bjorstad & Gropp 1996).

A_c is assembled exactly from the terms' blocks, as the product A p is (its rows are P^T A's):
the mass and drag, every triangle's membrane block (energies/membrane.face_block, its corners
in one aggregate summed first, so a triangle inside an aggregate adds nothing), every
spring's block (energies/springs: h^2 K + h D, as the solve keeps it per adjacency slot) and
every altitude spring's (energies/altitude.altitude_block: hair's and soft bodies' stiff
springs; without them a strand's coarse translation was too soft and CG took more iterations
than Jacobi, 185 against 160 a step in the hair demo). The mid-edge bending's hinges and the
isometric bending are left to the fine level (their stiffness is small against the
membrane's, and A_c is then P^T of a matrix that is still symmetric positive definite, so the
preconditioner stays one). Aggregates keep a
sewn group of particles whole (the solve's P of seams, conjugate_gradients.py, is then
constant on them); a pinned particle, and every particle of a pinned group, is in no
aggregate's P. An aggregate left with no free particle solves for 0.

A body narrow enough (its particles' Cuthill-McKee band at most EXACT_BAND: hair and strings,
whose strands are chains, or a sheet at most that many particles wide) is its own coarse
level: an aggregate per particle, A_c = A but for the hinges, P the identity on the free
particles, and CG runs on I + D^-1 A, a few iterations whatever the stiffness (the hair
demo's stiff strands took 10-13 a step, where aggregates of a strand each, translations only,
left their bending to the diagonal and CG ran out of its 200 iterations in most steps).

A_c is dense in a band: aggregates are numbered by Cuthill-McKee order (breadth first from a
least-connected one, neighbours by degree), so two that share a triangle or a spring are at
most `band` apart, and A_c (3 x aggregates square) is factored in its band, L L^T (Cholesky,
Golub & Van Loan, "Matrix computations", 4th ed. 2013, alg. 4.3.5), once per linearisation,
by one worker. The solve z's coarse part runs in the solve's scalar steps (plan.Once), every
worker on its own copy, in a fixed order: the same bits on any plan and thread count.
"""

from collections import deque

import numpy as np
import taichi as ti

from ..energies.altitude import altitude_block
from ..energies.faces import corner_coefficients
from ..energies.membrane import face_block
from ..runtime import backend
from ..runtime.team import MAX_WORKERS
from ..runtime.transfer import upload

AGGREGATES = 96     # aggregates a body is split into, about (each at least SMALLEST)
SMALLEST = 12       # particles of an aggregate, at least (smaller ones join a neighbour)
EXACT_BAND = 15     # a body whose particles lie in a band this wide is its own coarse level


def coupled_pairs(cloth) -> np.ndarray:
    """(P, 2): the particle pairs of every spring, every triangle's edge and every two corners
    of an altitude spring: the blocks of A that A_c sums (all but the hinges')."""
    faces = np.asarray(cloth.face_indices, np.int64).reshape(-1, 3)
    altitudes = np.asarray(cloth.altitude_indices, np.int64).reshape(-1, 4)
    corners = [(0, 1), (1, 2), (2, 0)]
    return np.concatenate([np.asarray(cloth.spring_indices, np.int64).reshape(-1, 2)]
                          + [faces[:, list(c)] for c in corners]
                          + [altitudes[:, [a, b]] for a in range(4) for b in range(a + 1, 4)])


def particle_graph(cloth) -> list[list[int]]:
    """Each particle's neighbours through a spring, a triangle's edge or an altitude spring
    (coupled_pairs), with the particles sewn together (Cloth.particle_weld) as their
    representative, in increasing order."""
    weld = np.asarray(cloth.particle_weld, np.int64)
    ends = weld[coupled_pairs(cloth)]
    ends = np.unique(np.sort(ends[ends[:, 0] != ends[:, 1]], axis=1), axis=0)
    graph = [[] for _ in range(len(weld))]
    for a, b in ends:
        graph[a].append(int(b))
        graph[b].append(int(a))
    return [sorted(n) for n in graph]


def aggregates(cloth, size: int) -> np.ndarray:
    """Each particle's aggregate (N,): breadth-first balls of `size` representatives from the
    least unassigned one in turn; a ball under a quarter of `size` joins its first neighbouring
    aggregate. Sewn particles share their representative's."""
    weld = np.asarray(cloth.particle_weld, np.int64)
    graph = particle_graph(cloth)
    roots = np.flatnonzero(weld == np.arange(len(weld)))
    owner = np.full(len(weld), -1, np.int64)
    balls = []
    for seed in roots:
        if owner[seed] >= 0:
            continue
        owner[seed] = len(balls)
        ball, queue = [seed], deque([seed])
        while queue and len(ball) < size:
            for v in graph[queue.popleft()]:
                if owner[v] < 0 and len(ball) < size:
                    owner[v] = len(balls)
                    ball.append(v)
                    queue.append(v)
        balls.append(ball)
    merged = np.arange(len(balls))
    for k, ball in enumerate(balls):
        if len(ball) * 4 < size:
            near = sorted({owner[v] for u in ball for v in graph[u]} - {k})
            if near:
                merged[k] = merged[near[0]]
    _, owner[roots] = np.unique(merged[owner[roots]], return_inverse=True)
    return owner[weld]


def cuthill_mckee(pairs: np.ndarray, count: int, most: int | None = None) -> np.ndarray | None:
    """The rank of each of `count` nodes in Cuthill-McKee order of the graph of `pairs`
    ((P, 2), each pair once): breadth first from a node of least degree, neighbours by
    (degree, index). With `most`: None as soon as the order's band must exceed it (when a
    node is taken, the nodes found but not yet taken each follow it by their place in the
    queue and were found from a node taken no later, so the band is at least the queue's
    length): a wide graph is given up after about most^2 nodes."""
    ends = np.concatenate([pairs, pairs[:, ::-1]]).reshape(-1, 2)
    degree = np.bincount(ends[:, 0], minlength=count)
    ends = ends[np.lexsort((ends[:, 1], degree[ends[:, 1]], ends[:, 0]))]
    start = np.concatenate([[0], np.cumsum(degree)]).tolist()
    neighbour = ends[:, 1].tolist()
    rank = [-1] * count
    found = 0                   # nodes ranked (in BFS, found and taken in the same order)
    for root in np.lexsort((np.arange(count), degree)).tolist():
        if rank[root] >= 0:
            continue
        rank[root] = found
        found += 1
        queue = deque([root])
        while queue:
            if most is not None and len(queue) - 1 > most:
                return None
            u = queue.popleft()
            for v in neighbour[start[u]:start[u + 1]]:
                if rank[v] < 0:
                    rank[v] = found
                    found += 1
                    queue.append(v)
    return np.asarray(rank, np.int64)


class Layout:
    """A body's aggregates for the coarse level: `aggregate` (N,) each particle's, numbered
    in Cuthill-McKee order; `count` aggregates; `band` the most two coupled aggregates are
    apart; `start` / `member` each aggregate's particles in increasing order (CSR).

    size None: an aggregate per particle (or sewn group) where that order's band is at most
    EXACT_BAND, A_c then A itself (strands, strings, small sheets: the band is their width in
    particles); else about 1 / AGGREGATES of the body, at least SMALLEST particles each."""

    def __init__(self, cloth, size: int | None = None):
        n = cloth.particle_count
        layout = None
        if size in (None, 1):       # a particle (or sewn group) each
            owner = np.unique(np.asarray(cloth.particle_weld, np.int64), return_inverse=True)[1]
            layout = _ranked(owner, cloth, EXACT_BAND if size is None else None)
            if layout is not None and size is None and layout[2] > EXACT_BAND:
                layout = None
        if layout is None:
            layout = _ranked(aggregates(cloth, size or max(SMALLEST, -(-n // AGGREGATES))),
                             cloth)
        self.aggregate, self.count, self.band = layout
        self.start = np.concatenate([[0], np.cumsum(np.bincount(self.aggregate,
                                                                minlength=self.count))])
        self.member = np.argsort(self.aggregate, kind="stable")


def _ranked(owner: np.ndarray, cloth, most: int | None = None) -> tuple | None:
    """(each particle's aggregate in Cuthill-McKee order, the aggregates, the band) of the
    aggregates `owner` (N,) numbers; None where the band must exceed `most`."""
    count = int(owner.max()) + 1 if len(owner) else 1
    ends = owner[coupled_pairs(cloth)] if len(owner) else np.zeros((0, 2), np.int64)
    ends = np.sort(ends[ends[:, 0] != ends[:, 1]], axis=1)
    keys = np.unique(ends[:, 0] * count + ends[:, 1])      # each pair once, in row order
    coupled = np.stack([keys // count, keys % count], axis=1)
    rank = cuthill_mckee(coupled, count, most)
    if rank is None:
        return None
    band = np.abs(rank[coupled[:, 0]] - rank[coupled[:, 1]]).max(initial=0)
    return rank[owner], count, int(band)


def add_fields(ws, fields, layout: Layout) -> None:
    """The coarse level's fields on the workspace ws (allocated with its FieldGroup); Python
    attributes coarse_count (aggregates), coarse_size (unknowns: 3 per aggregate) and
    coarse_width (the band of A_c and L, in unknowns, the diagonal's included)."""
    real = backend.real()
    n = len(layout.aggregate)
    ws.coarse_count = layout.count
    ws.coarse_size = 3 * layout.count
    ws.coarse_width = 3 * layout.band + 3
    ws.coarse_aggregate = fields.scalar(ti.i32, n)
    ws.coarse_start = fields.scalar(ti.i32, layout.count + 1)
    ws.coarse_member = fields.scalar(ti.i32, n)
    ws.coarse_free = fields.scalar(real, n)              # 1: in P (free, its group free)
    # A_c, then L, row by row: row i's entries (i, i - k) at [i width + k], k < width
    ws.coarse_band = fields.scalar(real, ws.coarse_size * ws.coarse_width)
    # each worker's P^T r, solved in place for A_c^-1 P^T r (a row of coarse_size per worker)
    ws.coarse_solution = fields.scalar(real, MAX_WORKERS * ws.coarse_size)


def upload_layout(ws, layout: Layout) -> None:
    upload(((ws.coarse_aggregate, layout.aggregate), (ws.coarse_start, layout.start),
            (ws.coarse_member, layout.member)))


@ti.func
def _add(ws: ti.template(), row_aggregate, column_aggregate, block):
    """A_c's (row, column) aggregates' 3x3 block += `block`, kept in the lower band: the
    block's lower triangle on the diagonal, its transpose above it."""
    for a, b in ti.static(ti.ndrange(3, 3)):
        i, j = 3 * row_aggregate + a, 3 * column_aggregate + b
        if row_aggregate < column_aggregate:
            i, j = 3 * column_aggregate + b, 3 * row_aggregate + a
        if i >= j and i - j < ws.coarse_width:     # Layout's band holds every coupled pair
            ws.coarse_band[i * ws.coarse_width + i - j] += block[a, b]


@ti.func
def _mark_free(model: ti.template(), ws: ti.template()):
    """coarse_free: 1.0 on a particle that moves in the solve (free, and so is its sewn group:
    newton.py's pins), else 0.0."""
    for i in range(model.particle_count):
        ws.coarse_free[i] = ti.cast(model.particle_inv_mass[i] > 0, float)
    if ti.static(model.sewn):
        for g in range(model.weld_count):
            free = 1.0
            for k in range(model.weld_start[g], model.weld_start[g + 1]):
                free = ti.min(free, ws.coarse_free[model.weld_member[k]])
            for k in range(model.weld_start[g], model.weld_start[g + 1]):
                ws.coarse_free[model.weld_member[k]] = free


@ti.func
def assemble(model: ti.template(), forces: ti.template(), ws: ti.template(), h):
    """A_c = P^T A P at the linearisation (module doc) of a solve of sub-step h, then its
    Cholesky factor in place: run by one worker."""
    for k in range(ws.coarse_size * ws.coarse_width):
        ws.coarse_band[k] = 0.0
    _mark_free(model, ws)
    eye = ti.Matrix.identity(float, 3)
    for i in range(model.particle_count):
        if ws.coarse_free[i] > 0:
            own = ws.coarse_aggregate[i]
            _add(ws, own, own, model.particle_mass[i] * (1.0 + h * forces.drag) * eye)
            for a in range(model.particle_spring_start[i], model.particle_spring_start[i + 1]):
                j = model.adjacency_other[a]
                other, free = ws.coarse_aggregate[j], ws.coarse_free[j] > 0
                m = ws.adjacency_block[a]
                block = ti.Matrix([[m[0], m[3], m[4]], [m[3], m[1], m[5]], [m[4], m[5], m[2]]])
                if other != own or not free:     # (i, i) and (i, j) cancel inside one
                    _add(ws, own, own, block)
                if free and other < own:         # the lower band: (j, i) adds the upper
                    _add(ws, own, other, -block)
    if ti.static(model.face_count > 0):
        for f in range(model.face_count):
            _add_face(model, ws, f, h)
    if ti.static(model.altitude_count > 0):
        for e in range(model.altitude_count):
            _add_altitude(model, ws, e, h)
    _factor(ws)


@ti.func
def _owners(ws: ti.template(), corner):
    """The aggregates of an element's corners (a vector like `corner`)."""
    return ti.Vector([ws.coarse_aggregate[corner[c]] for c in ti.static(range(corner.n))])


@ti.func
def _first(owner, c):
    """Whether corner c is the first of the element's corners in its aggregate."""
    first = True
    for d in range(c):
        if owner[d] == owner[c]:
            first = False
    return first


@ti.func
def _summed(ws: ti.template(), corner, owner, values, c):
    """The sum of `values` (one per corner) over the element's free corners in corner c's
    aggregate: what the corners moved as one by P contribute together."""
    total = 0.0
    for e in ti.static(range(corner.n)):
        if owner[e] == owner[c]:
            total += ws.coarse_free[corner[e]] * values[e]
    return total


@ti.func
def _add_face(model: ti.template(), ws: ti.template(), f, h):
    """Triangle f's membrane blocks between the aggregates of its free corners, each
    aggregate's corners summed first (a triangle inside one adds nothing: its corners'
    gradients sum to 0, but for pinned corners)."""
    corner = model.face_indices[f]
    owner = _owners(ws, corner)
    alpha, beta = corner_coefficients(model, f)
    for c in range(3):
        if _first(owner, c):
            alpha_c = _summed(ws, corner, owner, alpha, c)
            beta_c = _summed(ws, corner, owner, beta, c)
            for d in range(c + 1):
                if _first(owner, d):
                    block = face_block(model, ws, f, alpha_c, beta_c,
                                       _summed(ws, corner, owner, alpha, d),
                                       _summed(ws, corner, owner, beta, d),
                                       h * h + h * model.face_damping[f], h * h)
                    _add(ws, owner[c], owner[d], block)


@ti.func
def _add_altitude(model: ti.template(), ws: ti.template(), e, h):
    """Altitude spring e's blocks between the aggregates of its free corners (likewise)."""
    corner = model.altitude_indices[e]
    owner = _owners(ws, corner)
    weight = ti.Vector([ws.altitude_weight[4 * e + c] for c in ti.static(range(4))])
    for c in range(4):
        if _first(owner, c):
            weight_c = _summed(ws, corner, owner, weight, c)
            for d in range(c + 1):
                if _first(owner, d):
                    block = altitude_block(model, ws, e, h, weight_c,
                                           _summed(ws, corner, owner, weight, d))
                    _add(ws, owner[c], owner[d], block)


@ti.func
def _factor(ws: ti.template()):
    """L L^T = A_c in the band, in place (an unknown of an aggregate with no free particle has
    a 0 row and column: its diagonal is set to 1, it solves for 0)."""
    width = ws.coarse_width
    for j in range(ws.coarse_size):
        pivot = ws.coarse_band[j * width]
        for k in range(ti.max(0, j - width + 1), j):
            pivot -= ws.coarse_band[j * width + j - k] ** 2
        if pivot <= 0.0:
            pivot = 1.0
        pivot = ti.sqrt(pivot)
        ws.coarse_band[j * width] = pivot
        for i in range(j + 1, ti.min(ws.coarse_size, j + width)):
            value = ws.coarse_band[i * width + i - j]
            for k in range(ti.max(0, i - width + 1), j):
                value -= ws.coarse_band[i * width + i - k] * ws.coarse_band[j * width + j - k]
            ws.coarse_band[i * width + i - j] = value / pivot


@ti.func
def solve(ws: ti.template(), residual: ti.template(), row):
    """The worker's row of coarse_solution = A_c^-1 P^T residual; returns (P^T residual) .
    (A_c^-1 P^T residual), the coarse part of r . z (= y . y, y = L^-1 P^T residual)."""
    width, size = ws.coarse_width, ws.coarse_size
    base = row * size
    for g in range(ws.coarse_count):
        total = ti.Vector([0.0, 0.0, 0.0])
        for k in range(ws.coarse_start[g], ws.coarse_start[g + 1]):
            i = ws.coarse_member[k]
            total += ws.coarse_free[i] * residual[i]
        for a in ti.static(range(3)):
            ws.coarse_solution[base + 3 * g + a] = total[a]
    dot = 0.0
    for i in range(size):                        # L y = P^T r
        value = ws.coarse_solution[base + i]
        for k in range(ti.max(0, i - width + 1), i):
            value -= ws.coarse_band[i * width + i - k] * ws.coarse_solution[base + k]
        value /= ws.coarse_band[i * width]
        ws.coarse_solution[base + i] = value
        dot += value * value
    for step in range(size):                     # L^T x = y
        i = size - 1 - step
        value = ws.coarse_solution[base + i]
        for k in range(i + 1, ti.min(size, i + width)):
            value -= ws.coarse_band[k * width + k - i] * ws.coarse_solution[base + k]
        ws.coarse_solution[base + i] = value / ws.coarse_band[i * width]
    return dot


@ti.func
def correction(ws: ti.template(), i, row):
    """Particle i's share of P A_c^-1 P^T r (the worker's solve): its aggregate's vector, 0 on
    a particle the solve holds."""
    base = row * ws.coarse_size + 3 * ws.coarse_aggregate[i]
    return ws.coarse_free[i] * ti.Vector([ws.coarse_solution[base], ws.coarse_solution[base + 1],
                                          ws.coarse_solution[base + 2]])
