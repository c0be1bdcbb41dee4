"""The broad phase of contact with animated meshes (animated_bodies.py, animated_contact.py,
animated_edges.py): a traversal of the bodies' box hierarchy, and candidate lists that let a
particle skip it.

Candidate lists (a Verlet list per particle and body, as molecular dynamics keeps): a
particle's traversal also writes down, in index order, the triangles whose boxes meet its
path's box grown by 3 x SKIN x thickness, and it tests only those while it stays within SKIN x
thickness of where it was then and the body's vertices stay within SKIN x thickness of the
reference they were at (place_vertex, body_drift: beyond it, a new epoch makes every list
stale). Any
triangle whose box meets a later path's box was then within reach (the particle moved at most
one skin, each triangle corner at most two), so the list holds every triangle a traversal
would visit, in the same order: the answers are the same bits as a traversal every step.
More than LISTED candidates, and the particle traverses until its next list.
"""

import taichi as ti

from ...runtime import backend

SKIN = 0.5          # candidate lists hold while particle and body move less than this x thickness


LISTED = 32         # candidates a particle keeps per body (more: it traverses every time)


@backend.kernel_argument
class CandidateLists:
    """Candidate lists (module doc) in `slots` slots, one per element (a particle or an edge)
    and body: up to `size` triangles each (listed[slot * size + k]; count -1: it overflowed),
    the `anchors` positions of the element's particles when it was made (anchor[slot *
    anchors + k]) and the body's epoch then."""

    def __init__(self, slots: int, anchors: int, size: int):
        self.size, self.anchors = size, anchors        # read at compile time (structure)
        fields = backend.FieldGroup()
        self.listed = fields.scalar(ti.i32, slots * self.size)
        self.count = fields.scalar(ti.i32, slots)
        self.anchor = fields.vector(3, backend.real(), slots * anchors)
        self.epoch = fields.scalar(ti.i32, slots)
        fields.finalize(self)

    def forget(self) -> None:
        """Every list made again on first use."""
        self.anchor.fill(FAR)
        self.epoch.fill(-1)

    def overflowed(self) -> tuple[int, int]:
        """(lists that overflowed, lists made): an overflowed list held more than `size`
        candidates, and its element traverses the hierarchy every step until its next list
        (the same answers, at a traversal's cost)."""
        count, epoch = self.count.to_numpy(), self.epoch.to_numpy()
        made = epoch >= 0
        return int((count[made] < 0).sum()), int(made.sum())


@ti.func
def _meets(bodies: ti.template(), k, lo, hi):
    return (bodies.lo[k] <= hi).all() and (lo <= bodies.hi[k]).all()


@ti.func
def stale_list(bodies: ti.template(), lists: ti.template(), slot, b, k, x0, x, skin):
    """Whether list `slot` (of body b) no longer holds for its particle k moving x0 -> x: made
    in another epoch, or the particle is farther than the skin from its anchor."""
    anchor = lists.anchor[slot * lists.anchors + k]
    return (lists.epoch[slot] != bodies.epoch[b] or (x0 - anchor).norm() > skin
            or (x - anchor).norm() > skin)


@ti.func
def _wanted(bodies: ti.template(), f, edges: ti.template()):
    """Whether triangle f is visited: always, or (edges) when it has an edge to test."""
    wanted = True
    if ti.static(edges):
        wanted = (bodies.tested[f] != 0).any()
    return wanted


@ti.func
def visit_near(bodies: ti.template(), lists: ti.template(), slot, b, lo, hi, stale, skin,
               visit: ti.template(), query, found, edges: ti.template()):
    """found = visit(bodies, f, query, found) for every triangle f of body b whose box meets
    the box [lo, hi] (with `edges`, of those with an edge to test), in the hierarchy's order:
    from list `slot` while it holds, else by traversing the hierarchy, and when it is stale
    making it anew (the triangles within three skins of the box; the caller sets its
    anchors).

    One loop yields the candidates of either source, the traversal walking groups, blocks
    and triangles as a cursor, so `visit` (the contact test, most of the code) is compiled
    once: two call sites, one per source, took a third more of the build of a step with an
    animated collider (docs/performance.md)."""
    traverse = stale or lists.count[slot] < 0
    reach = ti.select(stale, 3.0 * skin, 0.0)
    count = 0
    blocks = bodies.triangle_total
    groups = blocks + bodies.block_total
    g, g_end = bodies.body_groups[b], bodies.body_groups[b + 1]
    k, k_end, f, f_end, n = 0, 0, 0, 0, 0
    more = True
    while more:
        candidate = -1
        if not traverse:
            if n < lists.count[slot]:
                candidate = lists.listed[slot * lists.size + n]
                n += 1
            else:
                more = False
        elif f < f_end:                        # the next triangle of the current block
            if _wanted(bodies, f, edges):
                candidate = f
            f += 1
        elif k < k_end:                        # the next block of the current group
            if _meets(bodies, blocks + k, lo - reach, hi + reach):
                f, f_end = bodies.block_first[k], bodies.block_first[k + 1]
            k += 1
        elif g < g_end:                        # the next group of the body
            if _meets(bodies, groups + g, lo - reach, hi + reach):
                k, k_end = bodies.group_first[g], bodies.group_first[g + 1]
            g += 1
        else:
            more = False
        if candidate >= 0:      # nested ifs: a ti.func in `and` runs whatever the left side
            if traverse and stale:
                if _meets(bodies, candidate, lo - reach, hi + reach):
                    if count >= 0 and count < lists.size:
                        lists.listed[slot * lists.size + count] = candidate
                        count += 1
                    else:
                        count = -1
            if _meets(bodies, candidate, lo, hi):
                found = visit(bodies, candidate, query, found)
    if stale:
        lists.count[slot] = count
        lists.epoch[slot] = bodies.epoch[b]
    return found


FAR = 1e30          # an anchor no particle is near: its list is made on first use
