"""The self-contact fail-safe (issue 56): after the contact passes of a step, no listed pair
has passed through itself during the step (SelfCollision.never_through), nor, unless mesh
neighbours, come nearer than KEEP thicknesses (SelfCollision.keep_thickness), by
construction.

The theorem. Over a step every particle moves on the straight line from x0 (the step's
start) to x1 (where the step leaves it). For a vertex p and a triangle abc, and for two edges
ab and cd, call R the largest relative displacement of two of the pair's particles, one from
each element (|(x1 - x0)_p - (x1 - x0)_q|): the displacement of any point of one element
relative to any point of the other is a convex combination of these, so the pair's distance
d(t) is at least d(0) - t R and at least d(1) - (1 - t) R, hence at least (d(0) + d(1) - R) / 2.
So a pair with

    d(0) + d(1) > R                                                          (1)

never touched in the step. Nor did a pair whose four points are never coplanar: the signed
volume V(t) = det(b - a, c - a, p - a) (for edges det(b - a, c - a, d - a)) is a cubic in t,
and a cubic whose four Bernstein coefficients on [0, 1] share a strict sign has no root there
(Farin, "Curves and Surfaces for CAGD", the convex hull property):

    b_k = (1 / C(3, k)) sum over the 8 choices of (x0 or x1) for each of the three edge
          vectors with k of them at x1, of their determinant                   (2)

A pair that meets neither over the step is checked again over each of PIECES equal parts of
the step (the positions on the way are the straight lines' at those times, so the theorem
holds for each part: a pair safe in every part is safe; it tells a pair that passed fast
beside another from one that met). One that fails a part may have met. The fail-safe then
holds it apart by its band ((4), below: only the move across a plane between the elements
taken off), or, where the band has no room or a corner outside it may not be moved, moves
its free particles back to x0 (their velocity 0: they did not move in the step); then it
checks every pair again, until a round moves nobody. It ends ((4)), and where it ends every
listed pair meets (1), (2) or (4), or has all its particles back at x0 or held (a pin, a
handle: scripted, never moved back). By induction over the steps: a cloth that starts with
no pair passing through another never has one, with these assumptions, stated in
docs/api.md:
- the pairs are the candidate list's: those farther apart than the thickness in the rest
  shape (neighbours nearer than that are not contacts), made from the boxes swept in the
  step, so that no pair can meet unlisted (contact_pairs.py); the paths are the particles'
  as they end the step, so a list made for the step's paths before particles were moved back
  may miss a pair one of them now meets (two particles that fell together: one moved back,
  the other not): where the rounds moved particles that far the list is made again for the
  new paths and the rounds run again (after the contact passes, run again with the
  particles moved back held: self_collision.py), the particles moved back staying back and
  unmoved (at a large step, 1/60 s, such pairs had passed through);
- held particles do not carry an element through another by themselves (such a pair is
  counted and reported: SelfContacts.unresolved);
- colliders: a particle is moved back only where that leaves it outside the colliders as
  they are at the step's end, and met by none on the way (an animated body that moved over
  its step start since: colliders.taken_at); elsewhere it stays where the step and the
  colliders left it, held for the rest of the step (counted: SelfContacts.stayed), and a
  pair that only such particles could part is counted with those held particles carried
  (unresolved). Without that, the cape demo with keep_thickness, which moves back far more
  particles than never_through alone, ended 19 particles inside its turning figure.
(1) and (2) are evaluated in floating point with margins (MARGIN) in the safe direction, so
rounding can only move a particle back that did not need it.

The thickness, the same way. With keep_thickness the rounds also move back the free
particles of a listed pair whose distance d at the step's end is

    d(1) < KEEP (1 + ROUNDING) thickness   and   d(1) < d(0)                  (3)

(d the vertex's distance to the triangle's nearest point, or the two segments'), unless
the pair is one of mesh neighbours: a particle of each element on one mesh edge, and the
elements nearer than APART thicknesses in the rest shape. Where the rounds end no listed
pair meets (3) unless its band holds it (then d(1) >= G, (4)) or held particles moved it
(counted in `unresolved` as above): a pair whose particles are all back has d(1) = d(0). So
every pair but mesh neighbours ends a step at least min(d(0), KEEP (1 + ROUNDING) thickness)
apart (d(0) less its rounding, for a band's), and by induction a cloth that
starts with no such pair nearer than KEEP thicknesses never has one, whatever the contact
passes leave when they run out (a fast twist, a landing at a large step); one that starts
nearer (an overlap the scene began with) never has that pair nearer than it began. Mesh
neighbours are the membrane's: where the thickness nears half an edge, a cloth squeezed in
its plane (beside a twist's turning edge) brings a vertex within the thickness of a
triangle one edge away, and the passes push it apart as best they can. Held to (3) such a
pair froze its vertex for good: one beside the turning edge of a 64 x 64 twist (Newton's
cloth_twist, thickness 0.53 of an edge) was moved back in every step from step 226 while its
neighbours turned on, 220 mm from where a step's solve put it by step 404. Layers share no
mesh edge, and a sheet folded onto itself shares them only at its crease: (3) holds them.
The pairs nearer than a thickness at the step's end are listed (the list holds the pairs
that came within thickness + skin over the step, and with keep_thickness it is made again
before the rounds once the passes moved two particles apart by more than the skin:
self_collision.py, _reach_kept), so the list's assumption is the same as above.
Bands: the move across, not the step. Two convex sets apart have a plane between them (the
separating planes of Newton's "Divide and Truncate", VBD, SIGGRAPH 2026). For a pair as the
step started it, n is the unit vector from the nearest point of the second element (the
triangle, or the second edge) to that of the first (the vertex, or the first edge); the
supports a = min n.x0 over the first's corners and b = max n.x0 over the second's leave
a - b = d(0) (but for rounding; any n with a > b will do). The pair's band keeps the first's
corners at n.x >= above and the second's at n.x <= below, with

    above - below = G = min(a - b, KEEP (1 + ROUNDING) thickness)

and the room a - b - G shared between the sides by how far each came towards the other along
n in the step, as its first passes left it (each at least LEAST_SHARE of it; by inverse
masses instead, the lower of two landed sheets, lying on the ground, was pushed into it and
crossed itself). A point of an element is a convex combination of
its corners, so a pair whose corners are inside the band at x0 (by construction) and at x1
is on its sides of the plane all along the straight paths:

    it never met, and it ends at least G apart                                 (4)

A failed pair with a corner outside its band (less than INSIDE / 2 thicknesses in: beyond
the slacks' rounding) has each such free corner hit. A hit particle goes onto the band of its
hitting pair of the highest index (projected: the move across the plane taken off, INSIDE
thicknesses in, the rest of its step kept: a layer pressed by another slides on along it),
up to PROJECTIONS times a step; after that, to the least share of its path from x0 that ends
INSIDE thicknesses inside each band that hit it (x0 and that point are inside, so the whole
path between is, and a band it was cut to holds it for good). Projected, its velocity is its
move over the step over dt less any approach along the band's normal; cut short, it is at
rest (cut to x0, it is moved back). The passes that follow hold it where it is (as one moved
back), so its
pairs are held to (3) whether or not keep_thickness is on: the passes could not part it
from a neighbour. Where a corner outside its band may not be moved (held, kept by a
collider) or is at x0 (the band has no room: a pair that began the step nearer than G
leaves none), or a collider drives a corner of the pair (took its step's start: a band
would push it back into the collider), the pair's free particles go back to x0 as above.
The rounds end: a particle
is projected at most PROJECTIONS times a step and each cut holds its bands for good, and
after PLANE_ROUNDS rounds of a run what fails goes back to x0 (each such round moves at
least one particle back, and one moved back stays). On a wound twist the bands let the
middle move on where moving back stopped it (docs/performance.md).

ROUNDING covers the positions' rounding (f32: about 1e-5 of a 5 mm thickness at a metre from
the origin), so that the guarantee holds measured in float64 too. What it costs is the
passes' work left undone: a pair they could not part in a step moves no nearer than its
band allows (or, without room, stops where the step started it) instead of sinking into the
other.

Bounds: most pairs need no test. The list records, for each particle i, the least distance
m_i of a listed pair of its at the positions L where the list was made (pair_bounds). A
point of an element is a convex combination of its corners, so over the step the distance of
a pair is at least its distance at L less the most each element's corners have been from
their L on the way, and a corner on its straight line from x0 to x1 is never farther from L
than at one end. Taken less a common motion c (any vector for each instant: it moves both
elements alike), a particle's D_i = max(|x0_i - L_i - c0|, |x1_i - L_i - c1|), c0 and c1 the
middles of the boxes of the displacements from L at the step's start and now. A pair whose
every particle has D_i <= m_i / 4 (D_a, D_b the largest of each element's) then has
d(0) + d(1) >= 2 m - 2 (D_a + D_b) >= m and R <= 2 (D_a + D_b) <= m (with m its own distance
at L, at least each corner's m_i), so it meets (1), strictly by the slack below; with
keep_thickness D_i <= (m_i - KEEP ...) / 2 as well makes d(1) >= m - (D_a + D_b) at least
the kept distance, so it does not meet (3). The
first round tests only the pairs of a particle past those bounds (loose; BOUND_SLACK
thicknesses inside them, far beyond rounding): the pairs it skips are exactly those the tests
would pass, so the rounds move back what they moved before, the same bits, for a test of a
few particles where the body moves as a whole or rests (a 16-layer pile of 64² sheets
falling: its 3.1 million pairs were tested every step). Each later round tests only the
pairs of a particle the round before moved (or held): a pair none of whose particles changed
is as the round before found it, passed, or failed with nothing of it left to move (counted
in `unresolved` once, when found). A wound twist's run takes 9 to 16 rounds, each moving a
few hundred particles, and each tested every loose pair before (docs/performance.md).

Cost: the bounds with each list (a distance a pair), then per step a pass over the particles,
the tests of the loose particles' pairs, and a round's tests of the pairs of the particles
the round before moved: one round in a step where nothing is moved back
(benchmarks/contact_guarantees.py measures it).
"""

import taichi as ti

from ..geometry import (
    TINY,
    segment_distance,
    segment_parameters,
    triangle_closest,
    triangle_distance,
)
from ..runtime import backend
from ..runtime.plan import DT, ITEM, STATE, Loop, Once, Phase, Until
from .broad_phase.contact_pairs import listed, span_middle, torn_pair
from .colliders.collision import taken_at

MARGIN = 1e-6       # relative: (1) needs d0 + d1 > R (1 + MARGIN), (2) |b_k| > MARGIN max |b_k|
PIECES = 8          # a step's parts, each checked by (1) or (2), for a pair the whole step fails
KEEP = 0.999        # keep_thickness: no pair is left nearer than this (in thicknesses), (3)
APART = 2.0         # thicknesses: mesh neighbours nearer than this at rest are not held to (3)
ROUNDING = 1e-4     # relative: (3) is checked at KEEP (1 + ROUNDING) thicknesses, in floats
BOUND_SLACK = 1e-3  # thicknesses: a particle this near its bound is loose (its pairs tested)
FAR = 1e30          # m_i of a particle in no listed pair
LEAST_SHARE = 0.05  # (4): the least share of a band's room either side is given
INSIDE = 1e-4       # thicknesses: (4)'s moves end this far inside their half-space
PROJECTIONS = 4     # (4): a particle is projected this many times a step at most, then cut
PLANE_ROUNDS = 8    # rounds of (4) in a run; after them, what fails is moved back to x0


@ti.func
def _determinant(u, v, w):
    return u.dot(v.cross(w))


@ti.func
def _never_coplanar(e0, e1, f0, f1, g0, g1):
    """Whether det(e(t), f(t), g(t)) keeps one strict sign on [0, 1], e, f and g moving
    linearly from e0, f0, g0 to e1, f1, g1 (module doc, (2))."""
    b0 = _determinant(e0, f0, g0)
    b3 = _determinant(e1, f1, g1)
    b1 = (_determinant(e1, f0, g0) + _determinant(e0, f1, g0) + _determinant(e0, f0, g1)) / 3.0
    b2 = (_determinant(e1, f1, g0) + _determinant(e1, f0, g1) + _determinant(e0, f1, g1)) / 3.0
    floor = MARGIN * ti.max(ti.abs(b0), ti.abs(b1), ti.abs(b2), ti.abs(b3))
    positive = b0 > floor and b1 > floor and b2 > floor and b3 > floor
    negative = b0 < -floor and b1 < -floor and b2 < -floor and b3 < -floor
    return positive or negative


@ti.func
def _distance(p, q, r, s, vertex_triangle):
    """The pair's distance: vertex p to triangle q r s, or segment p q to segment r s."""
    d = 0.0
    if vertex_triangle:
        d = triangle_distance(p, q, r, s)
    else:
        d = segment_distance(p, q, r, s)
    return d


@ti.func
def _safe_between(p0, q0, r0, s0, p1, q1, r1, s1, vertex_triangle):
    """Whether the pair, moving linearly from (p0, q0, r0, s0) to (p1, q1, r1, s1), certainly
    did not meet on the way (module doc, (1) or (2))."""
    reach = 0.0                                   # the largest relative displacement: R
    if vertex_triangle:
        move = p1 - p0
        reach = ti.max((move - (q1 - q0)).norm(), (move - (r1 - r0)).norm(),
                       (move - (s1 - s0)).norm())
    else:
        reach = ti.max(((p1 - p0) - (r1 - r0)).norm(), ((p1 - p0) - (s1 - s0)).norm(),
                       ((q1 - q0) - (r1 - r0)).norm(), ((q1 - q0) - (s1 - s0)).norm())
    safe = reach == 0.0
    if not safe:        # apart: a ti.func in `or` runs whatever the left side
        safe = (_distance(p0, q0, r0, s0, vertex_triangle)
                + _distance(p1, q1, r1, s1, vertex_triangle) > reach * (1.0 + MARGIN))
    if not safe:
        if vertex_triangle:     # det(r - q, s - q, p - q): the triangle is q, r, s here
            safe = _never_coplanar(r0 - q0, r1 - q1, s0 - q0, s1 - q1, p0 - q0, p1 - q1)
        else:
            safe = _never_coplanar(q0 - p0, q1 - p1, r0 - p0, r1 - p1, s0 - p0, s1 - p1)
    return safe


@ti.func
def _safe(start: ti.template(), now: ti.template(), corners, vertex_triangle):
    """Whether the pair on `corners` (a vertex and a triangle, or two edges) certainly did not
    meet in the step from `start` to `now`: (1) or (2) over the whole step, or else over each
    of its PIECES equal parts (a pair that passed near but beside the other is then told
    apart from one that met, for a pair in fast motion). One loop, so that the tests are
    compiled once: part 0 is the whole step, parts 1 to PIECES its pieces."""
    a, b, c, d = corners[0], corners[1], corners[2], corners[3]
    p0, q0, r0, s0 = start[a], start[b], start[c], start[d]
    p1, q1, r1, s1 = now[a], now[b], now[c], now[d]
    whole, pieces = False, True
    for part in range(PIECES + 1):
        if not whole and pieces:
            u, w = 0.0, 1.0
            if part > 0:
                u, w = (part - 1) / PIECES, part / PIECES
            safe = _safe_between(p0 + u * (p1 - p0), q0 + u * (q1 - q0), r0 + u * (r1 - r0),
                                 s0 + u * (s1 - s0), p0 + w * (p1 - p0), q0 + w * (q1 - q0),
                                 r0 + w * (r1 - r0), s0 + w * (s1 - s0), vertex_triangle)
            if part == 0:
                whole = safe
            else:
                pieces = safe
    return whole or pieces


@ti.func
def _nearer(start: ti.template(), now: ti.template(), corners, vertex_triangle, keep):
    """Whether the pair on `corners` ends the step nearer than `keep` and nearer than it
    started it (module doc, (3)); never for keep 0 (keep_thickness off: no distance taken)."""
    a, b, c, d = corners[0], corners[1], corners[2], corners[3]
    near = False
    if keep > 0.0:
        end = _distance(now[a], now[b], now[c], now[d], vertex_triangle)
        if end < keep:
            near = end < _distance(start[a], start[b], start[c], start[d], vertex_triangle)
    return near


@ti.func
def _adjacent(stage: ti.template(), i, j):
    """Whether particles i and j are the ends of a mesh edge."""
    found = False
    for k in range(stage.neighbour_start[i], stage.neighbour_start[i + 1]):
        if stage.neighbours[k] == j:
            found = True
    return found


@ti.func
def _mesh_neighbours(stage: ti.template(), rest: ti.template(), corners, vertex_triangle):
    """Whether the pair on `corners` is one of mesh neighbours (module doc, (3)): a particle of
    each element on one mesh edge, the elements nearer than APART thicknesses at rest."""
    joined = False
    if vertex_triangle:         # the vertex and a corner
        for k in ti.static(range(1, 4)):
            if _adjacent(stage, corners[0], corners[k]):
                joined = True
    else:                       # an end of each edge
        for k in ti.static(range(4)):
            if _adjacent(stage, corners[k // 2], corners[2 + k % 2]):
                joined = True
    near = False
    if joined:
        near = (_distance(rest[corners[0]], rest[corners[1]], rest[corners[2]],
                          rest[corners[3]], vertex_triangle) < APART * stage.thickness[None])
    return near


@ti.func
def _thickness_kept(stage: ti.template()):
    """The distance (3) and (4) keep: KEEP thicknesses, checked with the rounding's margin."""
    return KEEP * (1.0 + ROUNDING) * stage.thickness[None]


@ti.func
def _band(stage: ti.template(), corners, vertex_triangle):
    """The pair's band (module doc, (4)), from where the step started it: (n, below, above,
    found). Side A (the vertex, or the first edge) keeps n.x >= above, side B (the triangle,
    or the second edge) n.x <= below; found is False where the start gives no band (the
    elements touching, or the closest points' rounding leaving no gap between the supports).
    The room is shared by how far each side came towards the other along n in the step as
    its first passes left it (`first_end`: the same for every round of the step)."""
    a, b, c, d = corners[0], corners[1], corners[2], corners[3]
    p, q, r, s = stage.step_start[a], stage.step_start[b], stage.step_start[c], stage.step_start[d]
    between = p - r
    if vertex_triangle:
        closest, _, _ = triangle_closest(p, q, r, s)
        between = p - closest
    else:
        u, w = segment_parameters(p, q, r, s)
        between = p + u * (q - p) - r - w * (s - r)
    n = between / ti.max(between.norm(), TINY)
    least_a = n.dot(p)                      # the supports: A's lowest, B's highest along n
    most_b = ti.max(n.dot(q), n.dot(r), n.dot(s))
    towards_a = -n.dot(stage.first_end[a] - p)      # each side's move towards the other
    towards_b = ti.max(n.dot(stage.first_end[b] - q), n.dot(stage.first_end[c] - r),
                       n.dot(stage.first_end[d] - s))
    if not vertex_triangle:
        least_a = ti.min(least_a, n.dot(q))
        most_b = ti.max(n.dot(r), n.dot(s))
        towards_a = ti.max(towards_a, -n.dot(stage.first_end[b] - q))
        towards_b = ti.max(n.dot(stage.first_end[c] - r), n.dot(stage.first_end[d] - s))
    towards_a, towards_b = ti.max(towards_a, 0.0), ti.max(towards_b, 0.0)
    gap = least_a - most_b
    kept = ti.min(gap, _thickness_kept(stage))
    share = 0.5                             # of the room, side B's
    if towards_a + towards_b > 0.0:
        share = ti.math.clamp(towards_b / (towards_a + towards_b), LEAST_SHARE,
                              1.0 - LEAST_SHARE)
    below = most_b + share * (gap - kept)
    return n, below, below + kept, gap > 0.0


@ti.func
def _side(k: ti.template(), vertex_triangle):
    """1 for a corner of side A (the vertex, or the first edge), -1 for side B."""
    side = -1.0
    if ti.static(k == 0):
        side = 1.0
    if ti.static(k == 1):
        side = ti.select(vertex_triangle, -1.0, 1.0)
    return side


@ti.func
def _slack(n, below, above, x, k: ti.template(), vertex_triangle):
    """How far corner k at x is inside its half-space of the band (negative: outside)."""
    side = _side(k, vertex_triangle)
    return side * n.dot(x) - ti.select(side > 0.0, above, -below)


@ti.func
def _movable(stage: ti.template(), model: ti.template(), i):
    """Whether the rounds may move particle i: free, and neither back at its step's start
    nor kept where it is by a collider (back 1, 2); one cut or projected (back 3) may be cut
    again."""
    return model.particle_inv_mass[i] > 0 and (stage.back[i] == 0 or stage.back[i] == 3)


@ti.func
def _inside(stage: ti.template(), n, below, above, x: ti.template(), corners, vertex_triangle):
    """Whether every corner of the pair at positions x is inside its half-space of the band,
    by half INSIDE thicknesses at least (beyond the rounding of the slacks)."""
    inside = True
    for k in ti.static(range(4)):
        if (_slack(n, below, above, x[corners[k]], k, vertex_triangle)
                < 0.5 * INSIDE * stage.thickness[None]):
            inside = False
    return inside


@ti.func
def _divide(stage: ti.template(), model: ti.template(), state: ti.template(),
            colliders: ti.template(), outside: ti.template(), corners, vertex_triangle, p, n,
            below, above):
    """Failed pair p, its band (n, below, above) not holding it (module doc, (4)): each
    corner outside its half-space (less than half INSIDE thicknesses in) is hit (hits; the
    pair, `which`; the share of its step that ends INSIDE thicknesses before the plane,
    `fraction`: the least of its pairs'), or, where a corner outside may not be moved, is
    where the step started it (the band has no room there) or is driven by a collider (one
    took its step's start: `outside`, colliders.taken_at), the pair's movable particles are
    marked to go back to x0, as without bands."""
    inside = 0.5 * INSIDE * stage.thickness[None]
    stuck = False
    for k in ti.static(range(4)):
        i = corners[k]
        if _slack(n, below, above, state.particle_position[i], k, vertex_triangle) < inside:
            if (not _movable(stage, model, i)
                    or (state.particle_position[i] == stage.step_start[i]).all()):
                stuck = True
    if ti.static(outside):
        for k in range(4):      # not unrolled: the colliders' query compiled once, not 4 times
            i = ti.select(k < 2, ti.select(k == 0, corners[0], corners[1]),
                          ti.select(k == 2, corners[2], corners[3]))
            if not stuck:
                stuck = taken_at(colliders, i, stage.step_start[i])
    for k in ti.static(range(4)):
        i = corners[k]
        if _movable(stage, model, i):
            if stuck:
                stage.marked[i] = 1
            else:
                now = _slack(n, below, above, state.particle_position[i], k, vertex_triangle)
                if now < inside:
                    begin = _slack(n, below, above, stage.step_start[i], k, vertex_triangle)
                    share = 0.0
                    if begin > 4.0 * inside:
                        share = (begin - 2.0 * inside) / (begin - now)
                    ti.atomic_add(stage.hits[i], 1)
                    ti.atomic_max(stage.which[i], p)
                    ti.atomic_min(stage.fraction[i], share)


@backend.kernel
def pair_bounds(stage: ti.template(), pairs: ti.template(), x: ti.template()):
    """bound[i]: the least distance of a listed pair of particle i at positions x, where the
    list was made (module doc, bounds; FAR for a particle in none: an exact min, in any
    order)."""
    for i in range(stage.particle_count):
        stage.bound[i] = FAR
    for p in range(stage.pair_start[stage.triangle_count + stage.edge_count]):
        corners = pairs.particles[p]
        d = _distance(x[corners[0]], x[corners[1]], x[corners[2]], x[corners[3]],
                      p < stage.pair_start[stage.triangle_count])
        for k in ti.static(range(4)):
            ti.atomic_min(stage.bound[corners[k]], d)


@backend.kernel
def keep_frame(stage: ti.template(), k: ti.i32):
    """frames[k] = the middle of span (displacement_box's last box): c0 (k = 0), c1 (1), or
    self_collision.py's step's common motion (2)."""
    for _ in range(1):
        stage.frames[k] = span_middle(stage)


@ti.func
def begin_rounds(stage: ti.template()):
    stage.moved_back[None] = 1
    stage.moved_total[None] = 0
    stage.cut[None] = 0
    stage.placed[None] = 0
    stage.stayed[None] = 0
    stage.rounds[None] = 0
    stage.checked[None] = 0
    stage.unresolved[None] = 0


@ti.func
def loosen(stage: ti.template(), state: ti.template(), i):
    """Whether particle i is loose: past its bound, D_i > m_i / 4 (and (m_i - keep) / 2)
    less BOUND_SLACK thicknesses (module doc, bounds); every particle where the list has no
    bounds (loosening 0: a list is given them from its second step, so a list made every
    step, as a busy pile's is, costs none)."""
    _reset_hits(stage, i)
    if stage.again[None] == 0:                      # the step's first run: as the passes left it
        stage.first_end[i] = state.particle_position[i]
    stage.loose[i] = 1
    if stage.loosening[None]:
        at = stage.listed_at[i]
        reach = ti.max((stage.step_start[i] - at - stage.frames[0]).norm(),
                       (state.particle_position[i] - at - stage.frames[1]).norm())
        m = stage.bound[i]
        allowed = 0.25 * m
        if stage.keep[None] > 0.0:
            allowed = ti.min(allowed, 0.5 * (m - stage.keep[None]))
        stage.loose[i] = ti.select(reach > allowed - BOUND_SLACK * stage.thickness[None], 1, 0)


@ti.func
def going(stage: ti.template()):
    """Another round while the last moved a particle back or held it (at most one a
    particle)."""
    return (stage.moved_back[None] > 0
            and stage.rounds[None] <= stage.particle_count + PLANE_ROUNDS)


@ti.func
def clear_round(stage: ti.template()):
    stage.moved_back[None] = 0
    stage.rounds[None] += 1


@ti.func
def clear_back(stage: ti.template(), i):
    stage.back[i] = 0
    stage.marked[i] = 0
    stage.projections[i] = 0


@ti.func
def _kept(stage: ti.template(), corners):
    """The distance (3) holds the pair to: keep_thickness's, or, for a pair with a particle
    its band placed (back 3: held there by the passes that follow, which cannot part it
    from its neighbours), the same distance without keep_thickness; 0 (none) otherwise."""
    keep = stage.keep[None]
    if keep == 0.0:
        placed = False
        for k in ti.static(range(4)):
            if stage.back[corners[k]] == 3:
                placed = True
        if placed:
            keep = _thickness_kept(stage)
    return keep


@ti.func
def check_pair(stage: ti.template(), pairs: ti.template(), model: ti.template(),
               state: ti.template(), p):
    """_check without colliders."""
    _check(stage, pairs, model, state, stage, False, p)


@ti.func
def check_pair_outside(stage: ti.template(), pairs: ti.template(), model: ti.template(),
                       state: ti.template(), colliders: ti.template(), p):
    """_check with colliders: a corner one drives is not placed by a band."""
    _check(stage, pairs, model, state, colliders, True, p)


@ti.func
def _check(stage: ti.template(), pairs: ti.template(), model: ti.template(),
           state: ti.template(), colliders: ti.template(), outside: ti.template(), p):
    """Listed pair p (not beside a tear: torn pieces pass through the opening) fails if it may
    have met in the step (never_through), or the step left it nearer than the kept distance
    and than it started, unless mesh neighbours (keep_thickness, or a particle of it placed:
    _kept), and its band does not hold it ((4)). A failed pair's corners outside its band
    are hit (_divide), or, in rounds past PLANE_ROUNDS or with no band, its movable
    particles are marked to go back (marked: written 1 by any pair, the same value in any
    order); it is counted if it has none left to move (unresolved: its particles stay as they
    are, so no later round tests it again). Only a pair of a loose particle is tested (module
    doc, bounds: past its bound in the first round, moved in the round before later; the
    others are as their last test left them), and counted in `checked`."""
    corners = pairs.particles[p]
    if (stage.loose[corners[0]] + stage.loose[corners[1]] + stage.loose[corners[2]]
            + stage.loose[corners[3]] > 0):
        ti.atomic_add(stage.checked[None], 1)
        elements = pairs.elements[p]
        vertex_triangle = p < stage.pair_start[stage.triangle_count]
        failed = False
        if not torn_pair(stage, state, elements, vertex_triangle):
            if stage.through[None]:
                failed = not _safe(stage.step_start, state.particle_position, corners,
                                   vertex_triangle)
            if not failed:
                failed = _nearer(stage.step_start, state.particle_position, corners,
                                 vertex_triangle, _kept(stage, corners))
                if failed:
                    failed = not _mesh_neighbours(stage, model.particle_rest_position,
                                                  corners, vertex_triangle)
        n = 0.0 * stage.step_start[corners[0]]
        below, above, found = 0.0, 0.0, False
        if failed:                  # (4): held apart by its band, it passes
            n, below, above, found = _band(stage, corners, vertex_triangle)
            if found:
                failed = not _inside(stage, n, below, above, state.particle_position,
                                     corners, vertex_triangle)
        if failed:
            left = 0
            for k in ti.static(range(4)):
                left += ti.select(_movable(stage, model, corners[k]), 1, 0)
            if left == 0:
                ti.atomic_add(stage.unresolved[None], 1)
            elif found and stage.rounds[None] <= PLANE_ROUNDS:
                _divide(stage, model, state, colliders, outside, corners, vertex_triangle, p,
                        n, below, above)
            else:
                for k in ti.static(range(4)):
                    if _movable(stage, model, corners[k]):
                        stage.marked[corners[k]] = 1


@ti.func
def _put_back(stage: ti.template(), state: ti.template(), i, free):
    """Marked particle i goes back to the step's start, at rest (it did not move); unless
    not `free` (a collider took that place: colliders.taken_at): then it stays where the step
    left it, held there for the rest of the step as one moved back is (back 2, `stayed`)."""
    stage.marked[i] = 0
    stage.loose[i] = 1              # a new path: its pairs are tested next round
    if free:
        stage.back[i] = 1
        state.particle_position[i] = stage.step_start[i]
        state.particle_velocity[i] = 0.0 * state.particle_velocity[i]
        ti.atomic_add(stage.moved_total[None], 1)
    else:
        stage.back[i] = 2
        ti.atomic_add(stage.stayed[None], 1)
    ti.atomic_add(stage.moved_back[None], 1)


@ti.func
def _cut(stage: ti.template(), pairs: ti.template(), state: ti.template(), i):
    """Where hit particle i goes (module doc, (4)), and the unit normal of the band it was
    projected onto, towards its own side (0 if cut short): projected fewer than PROJECTIONS
    times this step, onto the band of its hitting pair of the highest index (`which`),
    INSIDE thicknesses in (its move across the band taken off, the rest of its step kept);
    else the share `fraction` of its path, which keeps it inside every band that hit it."""
    start, x = stage.step_start[i], state.particle_position[i]
    target = start + stage.fraction[i] * (x - start)
    normal = 0.0 * x
    if stage.projections[i] < PROJECTIONS:
        p = stage.which[i]
        corners = pairs.particles[p]
        vertex_triangle = p < stage.pair_start[stage.triangle_count]
        n, below, above, _ = _band(stage, corners, vertex_triangle)
        for k in ti.static(range(4)):
            if corners[k] == i:
                normal = _side(k, vertex_triangle) * n
                target = x + (INSIDE * stage.thickness[None]
                              - _slack(n, below, above, x, k, vertex_triangle)) * normal
        stage.projections[i] += 1
    return target, normal


@ti.func
def _place(stage: ti.template(), state: ti.template(), i, target, normal, dt):
    """Hit particle i placed at `target` (back 3: held there by the passes that follow, and
    movable by the next rounds). Projected onto a band (`normal` its unit normal towards
    the particle's side), its velocity is its step's move over dt less any part of it
    towards the band (a contact ends the approach; it keeps sliding); cut short on its path,
    it is at rest, as one moved back."""
    if stage.back[i] != 3:
        ti.atomic_add(stage.placed[None], 1)        # its first placing in the step
    stage.back[i] = 3
    stage.loose[i] = 1              # a new path: its pairs are tested next round
    state.particle_position[i] = target
    v = (target - stage.step_start[i]) / dt
    state.particle_velocity[i] = ti.select(normal.dot(normal) > 0.0,
                                           v - ti.min(v.dot(normal), 0.0) * normal, 0.0 * v)
    ti.atomic_add(stage.cut[None], 1)
    ti.atomic_add(stage.moved_back[None], 1)


@ti.func
def _reset_hits(stage: ti.template(), i):
    stage.hits[i] = 0
    stage.which[i] = -1
    stage.fraction[i] = 1.0


@ti.func
def move_back(stage: ti.template(), pairs: ti.template(), state: ti.template(), i, dt):
    """A marked particle goes back to the step's start, a hit one where its bands allow
    (no colliders; cut short to its start, it is moved back). Only the particles it moves are
    loose in the next round."""
    stage.loose[i] = 0
    if stage.marked[i]:
        _put_back(stage, state, i, True)
    elif stage.hits[i] > 0:
        target, normal = _cut(stage, pairs, state, i)
        if (target == stage.step_start[i]).all():
            _put_back(stage, state, i, True)
        else:
            _place(stage, state, i, target, normal, dt)
    if stage.hits[i] > 0:                  # the others are as loosen left them
        _reset_hits(stage, i)


@ti.func
def move_back_outside(stage: ti.template(), pairs: ti.template(), state: ti.template(),
                      colliders: ti.template(), i, dt):
    """A marked particle goes back to the step's start where no collider took that place at
    the step's end (module doc: the colliders' assumption); a hit one where its bands allow
    if no collider took that place either (cut short to its start, it is moved back), else
    as a marked one."""
    stage.loose[i] = 0              # loose in the next round if moved (or held) here
    if stage.marked[i] or stage.hits[i] > 0:
        start = stage.step_start[i]
        target, normal = start, 0.0 * start
        if not stage.marked[i]:
            target, normal = _cut(stage, pairs, state, i)
        done = False
        for _ in range(2):      # the target, then the start: the colliders' query compiled once
            if not done:
                taken = taken_at(colliders, i, target)
                if (target == start).all():
                    _put_back(stage, state, i, not taken)
                    done = True
                elif not taken:
                    _place(stage, state, i, target, normal, dt)
                    done = True
                else:
                    target = start
    if stage.hits[i] > 0:                  # the others are as loosen left them
        _reset_hits(stage, i)


def phases(stage, model, pairs) -> tuple:
    """The fail-safe's rounds (module doc), after the contact passes and their velocities:
    stage.moved_total[None] the particles moved back in this run, stage.unresolved[None] the
    pairs left that held particles carried (each counted in the round that found it). A step
    may run them again on a list made for the paths of the particles moved back
    (self_collision.py); the particles moved back stay marked back over the step (`back`,
    cleared by clear_back before the step's contact passes)."""
    n = model.particle_count
    colliders = stage.colliders
    back = (Loop(n, move_back, stage, pairs, STATE, ITEM, DT) if colliders is None else
            Loop(n, move_back_outside, stage, pairs, STATE, colliders, ITEM, DT))
    check = (Loop(listed(stage, pairs), check_pair, stage, pairs, model, STATE, ITEM)
             if colliders is None else
             Loop(listed(stage, pairs), check_pair_outside, stage, pairs, model, STATE,
                  colliders, ITEM))
    return (Once(begin_rounds, stage),
            Phase(Loop(n, loosen, stage, STATE, ITEM)),
            Until(going,
                  Once(clear_round, stage),
                  Phase(check),
                  Phase(back),
                  args=(stage,)))
