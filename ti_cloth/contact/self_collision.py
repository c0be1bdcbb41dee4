"""Self-collision and cloth-on-cloth contact (issue 18): after every step, no particle stays
closer than `thickness` to a triangle it is not a corner of, nor an edge closer than `thickness`
to an edge it shares no particle with, across every body of the simulation. Particles a
garment's seams sew together count as one (Model.particle_weld): a seam is not a contact.

Candidates: contact_pairs.py (a Verlet list of the pairs that may touch before it is made
again, from a grid of swept boxes; nothing tunnels between list and contact). Its skin, the
slack that lets it outlast steps, is SKIN thicknesses, or LEAN_SKIN when it is made after a
step in which two particles moved apart by more than FAST x SKIN thicknesses: a garment on a
turning figure moves its hem centimetres a step against a 4 mm thickness, its list is made
every step whatever the skin, and a lean skin lists fewer pairs (the cape's 12,300 against
4,900, its list made in 7 ms against 11). Any skin is exact: the list is made again before
the passes of a step that moved two particles apart by more than its own (less the margin).
With the fail-safe on, it is made again after the passes where they moved two particles
apart by more than a thickness and its skin since it was made: a pair that met in the step
was then nearer than that where the list was made, so the list holds it, as the
never-through fail-safe assumes (never_through.py; before this check a 24² twist kept 228
crossings through the fail-safe, the passes having carried particles past a lean list's
reach). After a run of the fail-safe that moved particles (back to where the step started
them, or onto a pair's band: never_through.py), the passes run again with those held where
it put them (a particle moved back beside one the passes had moved is nearer than the
thickness: a landing at 1/240 s left a pair 0.709 of it apart, the 24² twist 0.001), the
list made again where the particles moved that far (the paths of those moved changed), and
the fail-safe checks again, until a run moves nobody.

Each contact pass evaluates every listed pair:
- vertex v and triangle t: v's foot on t's plane inside t, and v's height over t, measured on
  the side v was on at the start of the step, below the reach, (1 + MARGIN) thicknesses (a
  vertex that crossed the plane during the step is pushed back to the side it came from);
- edges e and f: the closest points of the two segments, interior to both, nearer than the
  reach or on the other side of each other than at the step's start.
Each contact is the one-sided constraint C = distance - reach >= 0 with gradient g_k n on
its four particles (vertex 1, corners -w; edges (1 - s, s, -(1 - t), -t)), projected
mass-weighted as a position-based constraint: particle k moves by -w_k g_k (C n + f) / W,
W = sum_j w_j g_j^2, where f is the Coulomb friction correction: the tangential relative motion
of the two contact points over the step, removed entirely when it is at most
friction x penetration depth, shortened by that much otherwise (as the colliders do). A pair
that started the step within the reach (an overlap the scene began with, or one the passes
left) is pushed apart by at most SEPARATING x h past where it started: a correction becomes
velocity (v += dx / h), and an overlap removed in one 0.2 ms step flung two sheets apart at
10 m/s. The contacts move the particles one after the other in list order (Gauss-Seidel: the
passes are one serial launch, so no atomics and the same bits in every run), each seeing the
moves before it; a pass settles what the mean of each particle's moves (Jacobi with
averaging, before) took several for (the demos' resting piles: 2 passes against 7). A pass
moves no particle farther than STRIDE thicknesses from where it was at the pass's start (a
contact takes the part of its move that keeps its corners there): one contact after another
in a tight twist carried particles 20 cm in a step and flung them at 16 m/s (3 m/s with the
means, 2.7 with the stride). Only a contact between two held sides (level 0 both, stacking
below: a layer pressed between a handle and the ground) still goes into each particle's mean
of its pass, applied after it: there no move can make room, and one contact after another
pushed the layer sideways through itself. Its move is bounded too, by PRESSED_STRIDE
thicknesses a corner (STRIDE made the landing's pairs beside particles moved back end 0.963
of the thickness apart, where its test asks 0.99): a free corner of small weight (an edge touched near
its held end) between held ones takes the depth over its weight, and one was flung 26 km in
a step of the cape demo with keep_thickness.

The margin: contacts are found, and pushed, MARGIN thicknesses beyond the thickness (C above
is distance - (1 + MARGIN) thickness), and after a first pass the passes go on until an
evaluation finds no pair nearer than (1 - RESOLVED) thicknesses and no sticking contact
(its tangential motion within friction x depth) still moving by more than RESOLVED
thicknesses; the step ends as that evaluation found it (unless the passes run out:
SelfCollision.iterations; reported below half a thickness). A sliding contact does not keep
the passes going: its kinetic friction is applied whenever it moves (counting it, the cape
demo's first 2.5 s ran out of passes in 111 steps, 98 without; the skirt's 18 and 12).
Without the margin the passes must settle every contact to the thickness exactly, and a
pile's ran into a tail of hair-breadth contacts that a neighbour's move brought back by a
rounding (the cloth pile demo took 14.8 passes a step to leave none deeper than 0.1 %, and
8.2 to leave none deeper than 1 %, which is what it settled for before; 7.0 with the margin,
with the Jacobi means of then).
A layer resting on another sits in the margin: its contact, and its friction, hold in every
step. Pushed past the margin instead (found at the thickness, pushed to 1.02 of it), the
layers were in the air every other step and a block on a slope slid twice as far as
Coulomb's law has it. The friction test: the contacts after a sticking one in the pass may
move its particles again, so one pass can leave some of its correction (a block that sticks
on a slope crept 1 mm in 0.4 s when the passes stopped at the first).

Stacking (SelfCollision.stacking): a resting contact moves the side farther from what holds
it up. Under gravity every layer of a pile falls g h^2 in a step and the ground stops only the
lowest, so each step the passes must lift every layer back; mass-weighted, each pass moves the
two sides of a contact half-way, and the lift spreads up an L-layer pile as a diffusion, in
about L^2 passes (the cloth pile of the demos ran out of its 16 passes every step with 200
contacts left deeper than 1 %). Shock propagation (Guendelman, Bridson & Fedkiw, "Nonconvex
rigid bodies with stacking", ACM TOG 22(3), 2003: bodies ordered by the contact graph from the
fixed ones, each level's contacts solved with the levels under it held fixed) settles a layer
a pass instead. Here each step's passes give every particle a level: 0 where it is held (a pin,
a handle), where the step's collision stage pushed it out of a collider (an animated body's
contacts, found per triangle, included) or where it lies within half a thickness of an analytic
or mesh collider's surface (collision.rests_on), then, as contacts are evaluated, one more than
the level of the other side of a contact where that is less (a side's level is the highest of
its corners', so that a side counts as held only where all of it is: a side near the ground at
one corner only is not).
Where the two sides' levels differ, the weights w_k of the side with the lower level (its
inverse masses in W and in its moves) are scaled by s = 1 - (1 - STACK) r, r = 1 while the
pair approached over the step by at most RESTING thicknesses, falling to 0 at twice that. A
contact between unheld sides (in free fall, in the air), an impact and a contact between sides
of one level stay mass-weighted and keep their momentum; the held side keeps a share (STACK),
so that a contact pressed by a held upper side still moves it. In the means of the contacts
between two held sides a particle takes the sum of their moves over the sum of their weights
s, or over 1 where that is less.

Near pairs: the first pass after the list is made evaluates every listed pair and marks
those whose gap (height over the plane, or distance, minus the thickness; negative for a pair
that crossed) is below NEAR thicknesses; later passes, in this step and the next ones while
the list lasts, evaluate those, and mark again the pairs of the particles that are stale at
the pass's start: more than NEAR / 4 thicknesses from their near_at (where they were at the
start of the pass that last marked their pairs), now or at any evaluation since (`far`, kept
up to date by the contact moves, at the end of each pass and at the start of the next), or
more than MOVED thicknesses from where the step started them. Both are taken less a motion
common to all particles (a pair's gap does not change when both sides move alike): the
middle of the box of the displacements since the list was made (frame), and of the step's
(frames[2]), so that a pile falling as a whole marks nothing. A stale particle's near_at is
set again at the pass's start. So a pair none of whose particles has been stale since its
mark is at positions within NEAR / 4 of those of its mark, relative to each other within
NEAR thicknesses: it is not in contact where it is skipped by distance. A pair's side is
taken from the step's start, so a pair also counts in contact by changing sides in the
step, which a pair whose particles moved less than MOVED does only where the side flips
without a crossing (a vertex that comes round an edge onto the other face, nearly parallel
edges whose closest points jump): without MOVED a 24² twist parted from passes that
evaluate every pair at step 216, a vertex 2 cm under a face it had come round taken for
crossed. That is a flaw of the side rule, left as it is: taking the start's side only where
the pair may have met in the step cost the landing scene of
benchmarks/contact_guarantees.py its thickness (0.9993 to 0.90-0.98 with never_through
alone). A pass that ends the passes moves nothing, so it evaluated every pair in contact
where the step ends. The marks are a cost, not a result: the passes give the same bits as
passes that evaluate every pair in every pass (the 24²
twist's first second in tests/test_self_collision.py, against a process whose NEAR makes
every pair near; 400 steps of it with and without keep_thickness, 240 of the 4-layer pile
and 120 of the press of benchmarks/contact_guarantees.py, `/tmp` comparisons), and a run
loaded from its saved state at every step, whose first pass marks every pair, ends on the
bits of the run (tests/test_resume.py). The cost: a pile's 24,000 listed pairs against
its 2,000 near; a 16-layer pile of 64² sheets (65,536 particles, 3.1 million pairs listed)
marked all of them in every step's first pass, and now marks those of the particles that
moved.

No float atomics except exact max/min, so reruns and thread counts give the same bits.
Velocities follow the positions' correction (v += dx / h), as after strain limiting.

Strings and hair (no triangles) do not take part; nor do triangles and edges that lost a spring
to tearing (a torn sheet's pieces pass where the torn triangles were).
"""

import hashlib
import warnings
from dataclasses import dataclass

import numpy as np
import taichi as ti

from .. import saved_state
from ..errors import CrushedContact, StateMismatch
from ..geometry import TINY, edge_contact, point_over_triangle, triangle_closest
from ..inputs import limits
from ..inputs.validation import count, finite_number, keyword_only, require
from ..runtime import backend, plan
from ..runtime.plan import DT, ITEM, STATE, Loop, Once, Phase, Until
from ..runtime.transfer import upload
from ..state import copy_positions, restore_positions
from . import never_through
from .broad_phase.box_grid import BLOCK, BoxGrid
from .broad_phase.contact_pairs import (
    FOUND_KEPT,
    PairList,
    cloth_edges,
    displacement_box,
    list_pairs,
    listed,
    mean_edge,
    prefix_pairs,
    span_middle,
    sweep_boxes,
    torn_pair,
)
from .colliders.collision import near_surface, project_particle_out, rests_on

PAIRS_PER_PARTICLE = 32     # candidate list room at first, per particle
MAX_PAIRS_PER_PARTICLE = 256
SKIN = 1.0                  # the list's slack (skin), in thicknesses
LEAN_SKIN = 0.25            # the skin of a list made after a fast step (cloth moving apart)
FAST = 0.5                  # a step moving particles apart by this x SKIN thicknesses is fast
THICK = 0.5                 # a thickness above this (in mean rest edges) is warned about
RESOLVED = 0.001            # contacts within this (in thicknesses) of resolved end the passes
MARGIN = 0.02               # a contact is pushed this far (in thicknesses) past the thickness
SEPARATING = 0.5            # m/s: a pair that started a step in contact is pushed apart this fast
STRIDE = 0.5                # a pass moves no particle farther than this (in thicknesses)
PRESSED_STRIDE = 2.0        # nor a pressed contact a corner farther than this
CROWDED = 0.5               # a contact left nearer than this (in thicknesses) is reported
STACK = 0.01                # the weight of a resting contact's held side (stacking)
RESTING = 0.25              # a contact approaching by at most this (in thicknesses) a step rests
UNHELD = 1 << 20            # the level of a particle nothing is known to hold up
NEAR = 0.5                  # a pair within this (in thicknesses) of contact is evaluated every pass
MOVED = 0.5                 # a particle moving this far (thicknesses) in a step is stale
PASSES_AGAIN = 2            # most runs of the passes after the fail-safe's, a step (_fail_safe)
INSIDE = 1e-6               # a foot this far outside a triangle (in barycentric terms) is inside


@keyword_only
@dataclass(frozen=True, kw_only=True)
class SelfCollision:
    """thickness: the distance [m] kept between a particle and any triangle it is not a corner
    of, and between edges that share no particle, > 0 (Blender's self_distance_min, 0.015 m).
    friction: Coulomb coefficient between touching layers, >= 0.
    iterations: contact passes per step at most, >= 1; they stop once no contact is deeper
    than 0.1 % of the thickness. A contact the passes leave nearer than half the thickness (a
    layer pressed between a pin or a collider and another layer, or a pile too dense for the
    passes) is reported: a warning, once a run, and SelfContacts.closest_left.
    never_through: after the passes, the fail-safe of contact/never_through.py holds every
    pair that may have passed through the other in the step apart by a plane between them as
    the step started them (its band: only its particles' moves across the plane are taken
    off; where the band has no room, they go back to the step's start), so that no listed
    pair ever passes through another (a theorem, with its assumptions, in that module and
    docs/api.md); False: the passes alone, which a fast twist or fold can beat.
    keep_thickness: the same rounds also hold apart, by its band, a pair the step left
    nearer than 0.999 of the thickness and nearer than it started it, so that no pair that
    starts a step farther apart than that ever ends one nearer, whatever the passes
    leave (the same module's theorem; but mesh neighbours, a particle of each on one mesh
    edge and under two thicknesses apart at rest, which the membrane squeezes, are the
    passes'); False (the default): the passes keep the thickness as far as `iterations`
    allow, and report what they leave (closest_left). A particle is moved only where no
    collider took that place since, and a pair with a particle a collider drives goes back
    rather than by its band (else it stays: a figure pressing the cloth is warned about,
    where the guarantee yields). Off by default for what it costs the garment demos
    (docs/api.md): time, and cloth stopped short where a figure presses it.
    stacking: a resting contact moves the side farther (in contacts) from what holds it up:
    a collider, a pin, a handle (module doc: shock propagation), so the passes settle a pile
    about a layer a pass; False: every contact mass-weighted (piles take many more passes and
    sink deeper into each other). Impacts and contacts in the air are mass-weighted either
    way.
    in_solve: with the xpbd integrator, the contacts join its passes (Simulation runs it): a
    list made before each step for the step's predicted path (each free particle at x + h v
    + h^2 g, held ones where they are), and in every pass, after the membrane and the
    bending, each listed pair in contact projected out (in list order, mass-weighted but for
    the stage's stacking: levels seeded before the step, held particles and those resting on
    a collider at 0), then every particle out of the colliders (a moving one placed first
    where its stage puts it at the step's end; animated meshes only after the step). The
    passes after the step and the fail-safe stay, and keep the list while the step ended
    within its skin of where it was made. The elastic passes then see the contacts and do
    not undo them, so a large step keeps the cloth apart (docs/performance.md: a landing at
    1/60 s); at small steps it may cost a list a step more. False (the default): contact
    after the integrator."""

    thickness: float = 0.005
    friction: float = 0.0
    iterations: int = 16
    never_through: bool = True
    keep_thickness: bool = False
    stacking: bool = True
    in_solve: bool = False

    def __post_init__(self):
        thickness = finite_number("SelfCollision.thickness", self.thickness, 0.0, strict=True,
                                  unit="m")
        require(thickness <= limits.LENGTH.high, "SelfCollision.thickness", thickness,
                f"in (0, {limits.LENGTH.high:g}] m")
        object.__setattr__(self, "thickness", thickness)
        object.__setattr__(self, "friction", finite_number("SelfCollision.friction",
                                                           self.friction, 0.0))
        object.__setattr__(self, "iterations", count("SelfCollision.iterations", self.iterations,
                                                     limits.ITERATIONS))
        require(isinstance(self.never_through, bool), "SelfCollision.never_through",
                self.never_through, "True or False")
        require(isinstance(self.keep_thickness, bool), "SelfCollision.keep_thickness",
                self.keep_thickness, "True or False")
        require(isinstance(self.stacking, bool), "SelfCollision.stacking", self.stacking,
                "True or False")
        require(isinstance(self.in_solve, bool), "SelfCollision.in_solve", self.in_solve,
                "True or False")

    @property
    def fail_safe(self) -> bool:
        """Whether the rounds of contact/never_through.py run after the passes."""
        return self.never_through or self.keep_thickness


@dataclass(frozen=True)
class SelfContacts:
    """Pairs of a simulation's self-collision (Simulation.self_contacts): vertex_triangle
    (K, 2) rows (vertex, triangle index into the mesh), edge_edge (M, 2) rows of edge
    indices into `edges` (E, 2) particle pairs. closest_left: (distance [m], step) of the
    nearest contact the passes of a step have left, over the run so far, when one was left
    nearer than half the thickness; None otherwise. capacity: the pairs the candidate list
    has room for; grown: (step, capacity) each time a step found more pairs than it had room
    for and the list grew (it never drops a pair: a list past MAX_PAIRS_PER_PARTICLE a
    particle is a CrushedContact). moved_back: the particles the never-through fail-safe
    moved back to their step's start, over the run so far; placed: those it placed on a pair's
    band instead (never_through.py, (4): the move across a plane between the pair taken off,
    or their path cut short), over the run so far; stayed: those it left where the
    step left them instead, a collider having taken their step's start (never_through.py),
    over the run so far; unresolved: (pairs, step) when a step left pairs that may have met,
    or nearer than the thickness (keep_thickness), that only held particles (or particles
    that stayed) moved (the fail-safe's assumption broken), the last such step; None
    otherwise. passes: the contact passes the
    last step made (at most SelfCollision.iterations; the last run of them, where the
    fail-safe had them run again). skin: the slack [m] of the list, which
    holds the pairs that came within thickness + skin: a thickness (SKIN), or a quarter
    (LEAN_SKIN) when it was made after a fast step. tested: the listed pairs the fail-safe
    tested in the last step, over its rounds; it skips those whose particles all stayed
    within their bounds since the list was made (never_through.py, bounds)."""

    vertex_triangle: np.ndarray
    edge_edge: np.ndarray
    edges: np.ndarray
    closest_left: tuple[float, int] | None = None
    capacity: int = 0
    grown: tuple = ()
    moved_back: int = 0
    stayed: int = 0
    unresolved: tuple[int, int] | None = None
    passes: int = 0
    skin: float = 0.0
    tested: int = 0
    placed: int = 0


def warn_if_thick(settings: SelfCollision, cloth) -> None:
    """Warn when the thickness exceeds THICK x the mean rest edge of the cloth's triangles."""
    triangles = np.asarray(cloth.mesh.triangles).reshape(-1, 3)
    if not len(triangles):
        return
    rest = cloth.particle_position
    mean = float(np.linalg.norm(rest[triangles] - rest[np.roll(triangles, 1, axis=1)],
                                axis=2).mean())
    if settings.thickness > THICK * mean:
        warnings.warn(
            f"SelfCollision.thickness {settings.thickness:g} m is more than {THICK:g} x the "
            f"mean rest edge ({mean:.3g} m): pairs of the mesh that are neighbours but farther "
            "apart than the thickness at rest touch as soon as the cloth wrinkles - it "
            "stiffens, and each step costs many contact passes. Use a thickness below "
            f"{THICK * mean:.3g} m or a coarser mesh", stacklevel=3)


@backend.kernel_argument
class SelfCollisionStage:
    """The self-collision stage of one simulation: the body's triangles and edges, each
    particle's edges (CSR), the grid, the candidate list and the positions at the start of the
    step and at the list's making. Its contact passes are phases (runtime/plan.py), but it
    runs launch by launch only (its candidate lists are made on the host, and may grow): no
    `launched` object (stages.py)."""

    launched = None

    def __init__(self, settings: SelfCollision, cloth):
        n = cloth.particle_count
        triangles = np.asarray(cloth.mesh.triangles, np.int64).reshape(-1, 3)
        edges = cloth_edges(cloth)[0]
        self.particle_count = n
        self.triangle_count = len(triangles)
        self.edge_count = len(edges)
        self.edge_rows = edges
        real = backend.real()
        fields = backend.FieldGroup()
        self.triangles = fields.vector(3, ti.i32, max(len(triangles), 1))
        self.edges = fields.vector(2, ti.i32, max(len(edges), 1))
        self.triangle_spring = fields.vector(3, ti.i32, max(len(triangles), 1))
        self.triangle_face = fields.scalar(ti.i32, max(len(triangles), 1))
        self.edge_spring = fields.scalar(ti.i32, max(len(edges), 1))
        self.neighbour_start = fields.scalar(ti.i32, n + 1)     # each particle's mesh edges'
        self.neighbours = fields.scalar(ti.i32, max(2 * len(edges), 1))     # other ends
        self.step_start = fields.vector(3, real, n)
        self.before = fields.vector(3, real, n)
        self.listed_at = fields.vector(3, real, n)
        self.block_count = -(-n // BLOCK)
        self.edge_block_count = max(-(-len(edges) // BLOCK), 1)
        self.block_span = fields.vector(3, real, 2 * self.block_count)
        self.span = fields.vector(3, real, 2)      # the box of the displacements since listing
        self.shift = fields.vector(3, real, ())    # the middle of the displacements in the step
        self.block_length = fields.scalar(real, self.edge_block_count)
        self.mean_edge = fields.scalar(real, ())
        self.pair_start = fields.scalar(ti.i32, len(triangles) + len(edges) + 1)
        # the first FOUND_KEPT pairs each triangle and edge found when the list was counted
        # (contact_pairs.py: the write copies them)
        self.found = fields.scalar(ti.i32, FOUND_KEPT * max(len(triangles) + len(edges), 1))
        self.touching = fields.vector(2, ti.i32, ())
        self.deepest = fields.scalar(real, ())    # the smallest gap of a contact evaluated
        self.thickness = fields.scalar(real, ())  # the settings' (loaded: kernels outlive them)
        self.friction = fields.scalar(real, ())
        self.stack = fields.scalar(real, ())      # the held side's weight (STACK, or 1: off)
        self.level = fields.scalar(ti.i32, n)     # contacts from what holds it up (stacking)
        self.iterations = fields.scalar(ti.i32, ())
        self.passes = fields.scalar(ti.i32, ())   # passes made in this step
        self.go = fields.scalar(ti.i32, ())       # 1: another pass (or the last evaluation)
        self.applying = fields.scalar(ti.i32, ())     # 1: this pass moves the particles
        self.left_deep = fields.scalar(ti.i32, ())    # 1: the passes ran out, contacts deep
        self.full = fields.scalar(ti.i32, ())         # 1: this pass evaluates every pair
        self.near_at = fields.vector(3, real, n)      # where its pairs were last marked
        self.frame = fields.vector(3, real, ())       # the common motion those are taken less
        self.far = fields.scalar(real, n)             # the most it has been from there since
        self.stale = fields.scalar(ti.i32, n)         # 1: its pairs are marked in this pass
        self.stale_count = fields.scalar(ti.i32, ())  # particles stale in this pass
        self.pass_at = fields.vector(3, real, n)      # the positions at this pass's start
        self.moved = fields.scalar(ti.i32, ())        # 1: this pass moved a particle
        self.move_sum = fields.vector(3, real, n)     # a pass's held contacts' moves
        self.share_sum = fields.scalar(real, n)       # and their shares, per particle
        self.back = fields.scalar(ti.i32, n)          # never_through.py: moved back this step
        self.marked = fields.scalar(ti.i32, n)        # to move back in this round
        self.moved_back = fields.scalar(ti.i32, ())   # in this round
        self.moved_total = fields.scalar(ti.i32, ())  # in this step
        self.cut = fields.scalar(ti.i32, ())          # in this run: placings by bands
        self.placed = fields.scalar(ti.i32, ())       # in this run: particles first placed
        self.hits = fields.scalar(ti.i32, n)          # never_through.py (4): bands it is out of
        self.which = fields.scalar(ti.i32, n)         # such a pair: the highest index
        self.fraction = fields.scalar(real, n)        # the share of its step they allow it
        self.projections = fields.scalar(ti.i32, n)   # onto a band, in this step
        self.first_end = fields.vector(3, real, n)    # where the step's first passes left it
        self.stayed = fields.scalar(ti.i32, ())       # in this step: a collider took the place
        self.rounds = fields.scalar(ti.i32, ())
        self.unresolved = fields.scalar(ti.i32, ())
        self.through = fields.scalar(ti.i32, ())      # 1: never_through
        self.keep = fields.scalar(real, ())           # keep_thickness's distance, or 0
        self.again = fields.scalar(ti.i32, ())        # 1: passes after the fail-safe
        self.bound = fields.scalar(real, n)           # never_through.py's bounds: m_i
        self.loose = fields.scalar(ti.i32, n)         # 1: its pairs are tested this round
        self.frames = fields.vector(3, real, 3)       # c0, c1 (never_through); the step's
        self.checked = fields.scalar(ti.i32, ())      # pairs tested in the last run
        self.loosening = fields.scalar(ti.i32, ())    # 1: bounds made (else all loose)
        fields.finalize(self)
        self.grid = BoxGrid(n, len(edges))         # particles, then edges
        self.candidates = PairList(PAIRS_PER_PARTICLE * max(n, 1))
        self.load(settings, cloth)
        ends = np.concatenate([edges, edges[:, ::-1]]) if len(edges) else np.zeros((0, 2))
        ends = ends[np.lexsort((ends[:, 1], ends[:, 0]))]
        upload(((self.triangles, triangles), (self.edges, edges),
                (self.neighbour_start, np.searchsorted(ends[:, 0], np.arange(n + 1))),
                (self.neighbours, ends[:, 1])))

    @staticmethod
    def structure(settings: SelfCollision, cloth) -> tuple:
        triangles = np.ascontiguousarray(cloth.mesh.triangles).tobytes()
        return ("SelfCollisionStage", cloth.particle_count, settings.fail_safe,
                hashlib.blake2b(triangles, digest_size=16).hexdigest())

    def load(self, settings: SelfCollision, cloth) -> None:
        require(isinstance(settings, SelfCollision), "self_collision", settings,
                "None or a SelfCollision")
        self.settings = settings
        self.thickness[None] = settings.thickness
        self.friction[None] = settings.friction
        self.stack[None] = STACK if settings.stacking else 1.0
        self.iterations[None] = settings.iterations
        self.through[None] = int(settings.never_through)
        self.keep[None] = (never_through.KEEP * (1.0 + never_through.ROUNDING)
                           * settings.thickness if settings.keep_thickness else 0.0)
        self.colliders = None
        self.forget()
        if self.triangle_count:
            springs = np.asarray(cloth.triangle_edge_spring, np.int64).reshape(-1, 3)
            upload(((self.triangle_spring, springs), (self.triangle_face, cloth.triangle_face),
                    (self.edge_spring, cloth_edges(cloth)[1])))

    def attach(self, colliders) -> None:
        """The simulation's ColliderSet (or None): each contact pass ends by projecting the
        particles out of the colliders again, so a pile on the ground is not pushed into it;
        what rests on them holds up the layers above (stacking)."""
        self.colliders = colliders

    def forget(self) -> None:
        """Drop the candidate list: the next step makes a new one (after a restart)."""
        self.listed = False
        self.bounded = False            # never_through's bounds made for the list
        self.listed_step = -1           # the step it was made in
        self.skin = SKIN                # the list's, in thicknesses (_make_list)
        self.pair_total = self.vertex_pairs = 0
        self.closest_left = None
        self.grown = []
        self.moved_total_run = 0
        self.placed_run = 0
        self.stayed_run = 0
        self.unresolved_left = None
        self.passed = False             # the last step ran the passes (else it made none)
        self.tested = 0                 # pairs the fail-safe tested in the last step
        self.step_contacts = None       # its contacts, where its list was made again after them

    def saved(self) -> dict:
        """The candidate list and where it was made: a list made at another step would order
        the per-particle sums differently (different bits). With it what self_contacts()
        reports of the last step: its passes and, where the list was made again after them,
        the pairs in contact (the new list's flags do not hold them)."""
        total = self.pair_total
        arrays = {"listed": np.array(self.listed), "skin": np.array(self.skin),
                  "pair_total": np.array(total),
                  "vertex_pairs": np.array(self.vertex_pairs),
                  "capacity": np.array(self.candidates.capacity),
                  "listed_at": self.listed_at.to_numpy(),
                  "pair_start": self.pair_start.to_numpy(),
                  "elements": self.candidates.elements.to_numpy()[:total],
                  "particles": self.candidates.particles.to_numpy()[:total],
                  "active": self.candidates.active.to_numpy()[:total],
                  "passes": np.array(int(self.passes[None]) if self.passed else 0)}
        if self.step_contacts is not None:
            arrays["step_vertex_triangle"], arrays["step_edge_edge"] = self.step_contacts
        return arrays

    def check_saved(self, path, arrays: dict, limit: float) -> None:
        """errors.StateMismatch naming the array unless `arrays` is what saved() of this body
        returns: every array in its shape and dtype, finite, and its counts in range (the
        list's capacity within what it may grow to, its pairs within the capacity, starts
        rising within the pairs, indices within the body), so that restore() allocates
        nothing unbounded and no kernel reads out of its fields."""
        scalars = ("listed", "skin", "pair_total", "vertex_pairs", "capacity", "passes")
        missing = sorted(set(scalars) - set(arrays))
        if missing:
            raise StateMismatch(f"{path}: self_contact arrays missing: {missing}; it is "
                                "damaged: run it again")
        values = {}
        for name, high in (("capacity", MAX_PAIRS_PER_PARTICLE * self.particle_count),
                           ("pair_total", None), ("vertex_pairs", None), ("listed", 1)):
            if high is None:            # the pairs within the room, the vertex pairs within them
                high = values["capacity" if name == "pair_total" else "pair_total"]
            value = arrays[name]
            if not (value.shape == () and (np.issubdtype(value.dtype, np.integer)
                                           or value.dtype == bool) and 0 <= value <= high):
                raise StateMismatch(f"{path}: self_contact {name} is {value!r}, not a count "
                                    f"in [0, {high}]")
            values[name] = int(value)
        skin = arrays["skin"]
        if not (skin.shape == () and skin.dtype.kind == "f" and float(skin) in (SKIN, LEAN_SKIN)):
            raise StateMismatch(f"{path}: self_contact skin is {skin!r}, not {SKIN} or "
                                f"{LEAN_SKIN}")
        self._check_step_report(path, arrays)
        total = values["pair_total"]
        expected = {"elements": np.empty((total, 2), np.int32),       # PairList's fields
                    "particles": np.empty((total, 4), np.int32),
                    "active": np.empty(total, np.int32)}
        expected |= {name: getattr(self, name).to_numpy() for name in ("listed_at", "pair_start")}
        saved_state.check_arrays(path, {f"self_contact.{k}": arrays[k] for k in expected
                                        if k in arrays},
                                 {f"self_contact.{k}": v for k, v in expected.items()}, limit)
        for name, high in (("pair_start", total),
                           ("elements", max(self.triangle_count, self.edge_count, 1) - 1),
                           ("particles", self.particle_count - 1), ("active", 1)):
            array = arrays[name]
            rising = "start" not in name or bool((np.diff(array) >= 0).all())
            if array.size and not (rising and array.min() >= 0 and array.max() <= high):
                raise StateMismatch(f"{path}: self_contact {name} holds values outside "
                                    f"[0, {high}]{'' if rising else ' or falling'}; it is "
                                    "damaged: run it again")

    def _check_step_report(self, path, arrays: dict) -> None:
        """StateMismatch unless the last step's report in `arrays` is a pass count within
        the iterations and, where saved() wrote them, rows of (vertex, triangle) and (edge,
        edge) indices within the body."""
        passes = arrays["passes"]
        if not (passes.shape == () and np.issubdtype(passes.dtype, np.integer)
                and 0 <= passes <= self.settings.iterations):
            raise StateMismatch(f"{path}: self_contact passes is {passes!r}, not a count in "
                                f"[0, {self.settings.iterations}]")
        rows = [name for name in ("step_vertex_triangle", "step_edge_edge") if name in arrays]
        if rows and len(rows) != 2:
            raise StateMismatch(f"{path}: self_contact holds {rows[0]} without its other "
                                "half; it is damaged: run it again")
        bounds = {"step_vertex_triangle": (self.particle_count, self.triangle_count),
                  "step_edge_edge": (self.edge_count, self.edge_count)}
        for name in rows:
            array = arrays[name]
            if not (array.ndim == 2 and array.shape[1] == 2
                    and np.issubdtype(array.dtype, np.integer)):
                raise StateMismatch(f"{path}: self_contact {name} is {array.dtype}"
                                    f"{list(array.shape)}, not rows of two indices")
            if len(array) and not (array.min() >= 0
                                   and (array.max(axis=0) < bounds[name]).all()):
                raise StateMismatch(f"{path}: self_contact {name} holds indices outside this "
                                    "body; it is damaged: run it again")

    def restore(self, arrays: dict) -> None:
        """Load what saved() returned (for this body; check_saved first)."""
        capacity = int(arrays["capacity"])
        if capacity != self.candidates.capacity:
            self.candidates = PairList(capacity)
        self.listed_at.from_numpy(arrays["listed_at"])
        self.pair_start.from_numpy(arrays["pair_start"])
        total = int(arrays["pair_total"])
        for name, width in (("elements", 1), ("particles", 1), ("active", 1)):
            field = getattr(self.candidates, name)
            full = field.to_numpy()
            full[:width * total] = arrays[name]
            field.from_numpy(full)
        self.listed, self.pair_total = bool(arrays["listed"]), total
        self.full[None] = 1         # its near pairs not saved: marked again, the same bits
        self.skin = float(arrays["skin"])
        self.vertex_pairs = int(arrays["vertex_pairs"])
        self.bounded = False
        self.listed_step = -1
        passes = int(arrays["passes"])
        self.passes[None] = passes
        self.passed = passes > 0
        self.step_contacts = ((arrays["step_vertex_triangle"], arrays["step_edge_edge"])
                              if "step_vertex_triangle" in arrays else None)

    def before_step(self, state, t: float) -> None:
        copy_positions(state, self.step_start)

    def list_for_solve(self, model, state, dt: float, gravity, step_index: int) -> None:
        """SelfCollision.in_solve: after before_step, the list for the step's predicted path
        (each free particle at x + h v + h^2 g, a held one where it is: the boxes swept from
        the step's start to there, with the skin), for the passes of the integrator: the
        list kept where the prediction is within its skin (less the margin) of where it was
        made, as after_step keeps it, else made again; the positions left as they were.
        After the step, after_step keeps it while the cloth ended within the skin of where
        it was made (listed_at)."""
        if self.triangle_count == 0:
            return
        if self.colliders is None:
            seed_levels(self, model)
        else:
            seed_levels_on(self, model, state, self.colliders)
        predict_path(model, state, dt, gravity[0], gravity[1], gravity[2])
        if not self.listed or self._moved_past(state, self.skin - MARGIN):
            self._make_list(model, state, step_index)
        restore_positions(state, self.step_start)

    def after_step(self, model, state, t: float, dt: float, step_index: int) -> None:
        """The self-collision stage of a step ending at time t (stages.STEP_ORDER): the list
        made again when the cloth has moved more than its skin less the margin since it was
        made (a pair it left out was a thickness and the skin apart: it stays out of a
        contact's reach; on the host: it may grow), then the contact passes (phases). If the
        passes moved the cloth more than a thickness and the skin (the skin alone with
        keep_thickness: _reach_kept; less the margin) since the list was made, it is made
        again, so that it holds every pair that met in the step (never_through.py's
        assumption: a pair that met is nearer than that wherever the list was made); then
        the fail-safe."""
        self.passed = False
        self.step_contacts = None
        self.tested = 0
        if self.triangle_count == 0:
            return
        thickness = self.settings.thickness
        displacement_box(self, state.particle_position, self.step_start)
        never_through.keep_frame(self, 2)             # the step's common motion: MOVED
        if not self.listed or self._moved_past(state, self.skin - MARGIN):
            self._make_list(model, state, step_index)
        if self.pair_total == 0:
            return
        plan.run(self, model, state, None, self.candidates, dt, step_index, False,
                 serial=True)
        self.passed = True
        if self.left_deep[None]:
            self._report((1.0 + MARGIN) * thickness + float(self.deepest[None]), step_index)
        if self.settings.fail_safe:
            self._fail_safe(model, state, dt, step_index)

    def _fail_safe(self, model, state, dt: float, step_index: int) -> None:
        """never_through.py's rounds until a run moves nobody back. Particles moved back took
        another path through the step: where they moved that far the list is made again for
        those paths, and the passes run again with them held where they started (one moved
        back beside one that was not is nearer than the thickness; nor is it projected out
        of a collider again: the rounds could not move it back twice), then the rounds check
        again. Those moved back stay back: each run moves new ones, or is the last. The
        passes run again at most PASSES_AGAIN times a step: a run of the rounds ends with
        every listed pair passing, so after that the rounds run again only on a list made
        again for the paths they changed (a wound 64 x 64 twist ran the passes about six
        times a step for a tail of a few particles a run; with the passes run again once, a
        press thicker than half an edge crossed itself between mesh neighbours, pairs no list
        holds: docs/performance.md)."""
        again = False
        passes_again = 0
        stale = self._list_stale(state)
        try:
            while True:
                if stale:
                    self._list_again(model, state, step_index)
                if not self.bounded and self.listed_step < step_index:
                    never_through.pair_bounds(self, self.candidates, self.listed_at)
                    self.bounded = True     # from a list's second step (made every step:
                self.loosening[None] = int(self.bounded)        # no bounds, all tested)
                if self.bounded:
                    for k, positions in enumerate((self.step_start, state.particle_position)):
                        displacement_box(self, positions, self.listed_at)  # never_through's
                        never_through.keep_frame(self, k)                  # c0 and c1
                plan.run(self, model, state, None, self.candidates, dt, step_index, False,
                         part="fail_safe", serial=True)
                back = int(self.moved_total[None])
                moved = back + int(self.cut[None])
                self.tested += int(self.checked[None])
                self.moved_total_run += back
                self.placed_run += int(self.placed[None])
                self.stayed_run += int(self.stayed[None])
                if moved == 0:
                    break
                if not again:
                    self.again[None] = again = 1
                if passes_again == PASSES_AGAIN:    # the run left every listed pair passing:
                    stale = self._list_stale(state)     # another run only on a list made again
                    if not stale:
                        break
                    continue
                if self._moved_past(state, self.skin - MARGIN):
                    self._list_again(model, state, step_index)
                plan.run(self, model, state, None, self.candidates, dt, step_index, False,
                         serial=True)
                passes_again += 1
                stale = self._list_stale(state)
        finally:        # the next step's passes start with nobody moved back
            if again:
                self.again[None] = 0
        if self.unresolved[None]:
            self._unresolved(int(self.unresolved[None]), step_index)

    def _list_stale(self, state) -> bool:
        """Whether the rounds need the list made again first: two particles moved apart by
        more than _reach_kept and the skin (less the margin) since it was made."""
        return self._moved_past(state, self._reach_kept() + self.skin - MARGIN)

    def _reach_kept(self) -> float:
        """How near [thicknesses] a pair left out of the list may come before the fail-safe
        misses it: 1 for never_through (a pair that met is at 0), 0 with keep_thickness (a
        pair nearer than the thickness is one the rounds must see). A list is made again
        before the rounds once the passes moved two particles apart by more than this and
        the skin since it was made: at 1 with keep_thickness, a 128 x 128 twist (Newton's
        cloth_twist, step 1,084) ended a pair missing from the list at 0.92 of the
        thickness."""
        return 0.0 if self.settings.keep_thickness else 1.0

    def _list_again(self, model, state, step_index: int) -> None:
        """The list made again within a step: the pairs found in contact so far kept for
        self_contacts() (the new list's flags cleared)."""
        if self.step_contacts is None:
            self.step_contacts = self._rows(True)
        self._make_list(model, state, step_index)
        self.candidates.active.fill(0)

    def _moved_past(self, state, thicknesses: float) -> bool:
        """Whether two particles moved apart by more than `thicknesses` since the list was
        made."""
        return (displacement_box(self, state.particle_position, self.listed_at)
                > thicknesses * self.settings.thickness)

    def phases(self, model, forces, pairs) -> tuple:
        """The contact passes as phases (runtime/plan.py; `pairs` the PairList, the
        workspace: a bigger list is another kernel), one serial launch (after_step: each
        pass moves the particles contact by contact, in pair order). At most `iterations`
        passes, each evaluating the listed pairs near contact (marked in the first, and again
        once a particle has been NEAR / 4 thicknesses away since: module doc), moving the
        particles by their contacts and out of the colliders again; they stop at a pass that
        finds none unresolved, which moves nothing (end_pass). Passes run out with contacts
        still deep: one more evaluation measures what is left (left_deep, deepest). Then the
        velocities follow the corrections."""
        n = model.particle_count
        colliders = self.colliders
        out_of_colliders = (() if colliders is None else
                            (Phase(Loop(n, _out_of_colliders, self, model, STATE, colliders,
                                        ITEM)),))
        seed = (Loop(n, seed_level, self, model, STATE, ITEM) if colliders is None else
                Loop(n, seed_level_on, self, model, STATE, colliders, ITEM))
        marks = ((Loop(n, _clear_back, self, ITEM),)
                 if self.settings.fail_safe else ())
        return (Phase(Loop(n, keep_position, STATE, self.before, ITEM), *marks),
                Phase(seed),
                Once(begin_passes, self),
                Until(passing,
                      Once(clear_counts, self),
                      Phase(Loop(n, keep_pass_start, self, STATE, ITEM)),
                      Phase(Loop(listed(self, pairs), evaluate_pair, self, pairs, model,
                                 STATE, ITEM, DT)),
                      Phase(Loop(n, apply_means, self, model, STATE, ITEM)),
                      *out_of_colliders,
                      Phase(Loop(n, measure_drift, self, STATE, ITEM)),
                      Once(end_pass, self),
                      args=(self,)),
                Phase(Loop(n, follow_correction, self, STATE, ITEM, DT)))

    def fail_safe(self, model, forces, pairs) -> tuple:
        """never_through.py's rounds, after the passes (a part of its own: the passes may
        make the list again before it)."""
        return never_through.phases(self, model, pairs)

    def _unresolved(self, count: int, step_index: int) -> None:
        """Keep the last step whose held particles carried a pair through, or nearer than the
        thickness (never_through.py's assumption); warn the first time."""
        if self.unresolved_left is None:
            warnings.warn(
                f"self-collision: in step {step_index}, {count} pair(s) may have passed "
                "through each other, or come nearer than the thickness, by the motion of held "
                "particles alone (pins, handles, attachments), which the fail-safe does not "
                "move back, or of particles whose step start a collider had taken, which it "
                "cannot: a scripted motion presses the cloth into itself there "
                "(Simulation.self_contacts().unresolved follows the last; .stayed counts the "
                "particles a collider kept)", stacklevel=2)
        self.unresolved_left = (count, step_index)

    def _report(self, distance: float, step_index: int) -> None:
        """Keep the nearest contact the passes left (closest_left); warn the first time one is
        left nearer than CROWDED thicknesses."""
        thickness = self.settings.thickness
        if distance >= CROWDED * thickness:
            return
        first = self.closest_left is None
        if first or distance < self.closest_left[0]:
            self.closest_left = (distance, step_index)
        if first:
            kept = (" keep_thickness then holds such a pair apart by a plane between its "
                    "elements as the step started them, so it ends the step no nearer than it "
                    "began, that part of the cloth moving only along the plane."
                    if self.settings.keep_thickness else "")
            warnings.warn(
                f"self-collision left a contact {distance / thickness:.2f} of the thickness "
                f"apart ({distance:.3g} m of {thickness:.3g} m) after "
                f"{self.settings.iterations} passes in step {step_index}: a layer may be held "
                "against another by a pin, a handle, a collider or a seam being sewn shut, or "
                "the pile is too dense for the passes; raise SelfCollision.iterations, add "
                "substeps or use a smaller thickness (Simulation.self_contacts().closest_left "
                f"follows the nearest).{kept}",
                stacklevel=2)

    def _make_list(self, model, state, step_index: int) -> None:
        """List the pairs that met within thickness + skin during the step (their swept boxes
        meet) and are now nearer than that plus how far they moved relative to each other.
        The skin is SKIN thicknesses, or LEAN_SKIN after a step that moved two particles
        apart by more than FAST x SKIN thicknesses: such a list would not outlast the next
        step or two whatever its skin, and a lean one lists fewer pairs (module doc). The
        step's displacement box is measured again here: _moved_past left span holding the
        box since the list, and sweep_boxes takes the step's."""
        thickness = self.settings.thickness
        moved = displacement_box(self, state.particle_position, self.step_start)
        self.skin = LEAN_SKIN if moved > FAST * SKIN * thickness else SKIN
        near = (1.0 + self.skin) * thickness
        sweep_boxes(self, state)
        cell = float(mean_edge(self, state)) + 2.0 * near       # about a query's size
        self.grid.build(cell)
        list_pairs(self, self.candidates, model, state, near, self.settings.thickness, 0)
        total = prefix_pairs(self)
        if total > self.candidates.capacity:
            if total > MAX_PAIRS_PER_PARTICLE * self.particle_count:
                raise CrushedContact(
                    step_index,
                    f"self-collision found {total} pairs within {near:.3g} m in step "
                    f"{step_index}, more than {MAX_PAIRS_PER_PARTICLE} per particle: the cloth "
                    "is crushed far below its thickness; use more substeps or a smaller "
                    "thickness")
            self.candidates = PairList(min(2 * total,
                                           MAX_PAIRS_PER_PARTICLE * self.particle_count))
            self.grown.append((step_index, self.candidates.capacity))
        list_pairs(self, self.candidates, model, state, near, self.settings.thickness, 1)
        copy_positions(state, self.listed_at)
        self.listed, self.pair_total = True, total
        self.listed_step = step_index
        self.bounded = False            # its bounds are made when the fail-safe first needs them
        self.full[None] = 1         # the next pass marks every pair of it
        self.vertex_pairs = int(self.pair_start[self.triangle_count])

    def pairs(self, active: bool = True) -> SelfContacts:
        """The listed candidate pairs, or (active) those in contact in any pass of the last
        step (kept from the list they were found on where the list was made again after
        the passes)."""
        vertex_rows, edge_rows = (self.step_contacts if active and self.step_contacts is not None
                                  else self._rows(active))
        return SelfContacts(vertex_rows, edge_rows, self.edge_rows,
                            self.closest_left, self.candidates.capacity, tuple(self.grown),
                            self.moved_total_run, self.stayed_run, self.unresolved_left,
                            int(self.passes[None]) if self.passed else 0,
                            self.skin * self.settings.thickness, self.tested, self.placed_run)

    def _rows(self, active: bool) -> tuple:
        """The (vertex, triangle) and (edge, edge) rows of the listed pairs, or of those
        marked active."""
        total = self.pair_total
        kept = np.arange(total)
        if active:
            kept = kept[self.candidates.active.to_numpy()[:total] > 0]
        elements = self.candidates.elements.to_numpy()[kept]
        vertex = kept < self.vertex_pairs
        return elements[vertex], elements[~vertex]


@ti.func
def _vertex_triangle(positions: ti.template(), start: ti.template(), corners, thickness):
    """(in contact, n, gap, w) of vertex corners[0] and triangle corners[1:] at `positions`.
    Its foot on the plane inside the triangle: the side taken from `start`, n the unit normal
    towards the vertex's side at the start, gap = its height over the plane along n minus
    thickness (< 0 in contact), w the barycentric coordinates of its foot. Its foot outside
    (the vertex beside an edge or a corner, on no side of the triangle): n from the nearest
    point of the triangle to the vertex, gap = their distance minus thickness, w the nearest
    point's coordinates (geometry.triangle_closest; the point's slide along the border moves
    the distance to first order by nothing, so the gradient is as inside); where its height
    alone is NEAR thicknesses past the thickness, gap = |height| - thickness (no contact: the
    distance is at least the height; a pair with gap >= NEAR thicknesses is not near)."""
    v, a, b, c = corners[0], corners[1], corners[2], corners[3]
    p = positions[v]
    n, h, w = point_over_triangle(p, positions[a], positions[b], positions[c])
    inside = w.min() >= -INSIDE
    touching = False
    gap = ti.abs(h) - thickness
    if n.norm() > 0 and inside:
        n0, h0, _ = point_over_triangle(start[v], start[a], start[b], start[c])
        side = ti.select(h0 >= 0.0, 1.0, -1.0)
        if n.dot(n0) < 0.0:
            side = -side                             # the triangle turned over in the step
        n *= side
        gap = side * h - thickness
        touching = gap < 0.0
    elif n.norm() > 0 and gap < NEAR * thickness:
        nearest, w, _ = triangle_closest(p, positions[a], positions[b], positions[c])
        between = p - nearest
        distance = between.norm()
        gap = distance - thickness
        touching = gap < 0.0 and distance > 0.0 and ti.abs(h) < thickness  # (>= |h|: rounding)
        n = between / ti.max(distance, TINY)
    return touching, n, gap, w


@ti.func
def _edge_edge(positions: ti.template(), start: ti.template(), corners, thickness):
    """(in contact, n, gap, s, t) of edges corners[0:2] and corners[2:4]
    (geometry.edge_contact): n from the second edge's point to the first's."""
    a, b, c, d = corners[0], corners[1], corners[2], corners[3]
    return edge_contact(positions[a], positions[b], positions[c], positions[d], start[a],
                        start[b], start[c], start[d], thickness)


@ti.func
def _contact_move(stage: ti.template(), model: ti.template(), state: ti.template(), corners,
                  weights, n, gap, friction, first, dt):
    """The position-based projection of a contact with its friction: particle k of
    `corners` moves by -w_k s_k g_k (d n + f) / sum_j w_j s_j g_j^2, s_k its share
    (stack_shares), d the depth to push (gap, or less for a pair that started the step within
    the reach: pushed apart by SEPARATING x dt past where it started), at once (Gauss-Seidel:
    the passes are one serial launch, so the contacts move the particles in pair order, the
    same bits in every run), or into the pass's means between two holders (pressed). It
    moves them in a pass that applies, if the contact is unresolved or the pass is the
    step's first. Returns whether it is unresolved: deeper than RESOLVED thicknesses past
    the margin (or its separation), or sticking (its tangential motion within friction x
    depth) and still moving tangentially by more than that."""
    motion = ti.Vector([0.0, 0.0, 0.0])
    for k in ti.static(range(4)):
        i = corners[k]
        motion += weights[k] * (state.particle_position[i] - stage.step_start[i])
    shares, pressed = stack_shares(stage, corners, weights, motion, n)
    norm = 0.0
    for k in ti.static(range(4)):
        norm += _inverse_mass(stage, model, corners[k]) * shares[k] * weights[k] * weights[k]
    started = gap - motion.dot(n)              # the gap at the step's start, along n
    depth = ti.min(gap - ti.min(started + SEPARATING * dt, 0.0), 0.0)
    tangential = motion - motion.dot(n) * n
    length = tangential.norm()
    slip = 0.0
    if length > 0:
        slip = ti.min(friction * -depth / length, 1.0)
    resolved = RESOLVED * stage.thickness[None]
    unresolved = (depth < -MARGIN * stage.thickness[None] - resolved
                  or (slip >= 1.0 and length > resolved))
    if stage.applying[None] and (first or unresolved) and norm > 0:
        move = -(depth * n + slip * tangential) / norm
        part = 1.0           # of the move, keeping every corner within STRIDE of its pass start
        for k in ti.static(range(4)):
            i = corners[k]
            length = (_inverse_mass(stage, model, i) * shares[k] * ti.abs(weights[k])
                      * move.norm())
            if length > 0:
                room = PRESSED_STRIDE * stage.thickness[None]   # a mean's share, at most
                if not pressed:
                    room = (STRIDE * stage.thickness[None]
                            - (state.particle_position[i] - stage.pass_at[i]).norm())
                part = ti.min(part, ti.max(room, 0.0) / length)
        for k in ti.static(range(4)):
            i = corners[k]
            step = part * _inverse_mass(stage, model, i) * shares[k] * weights[k] * move
            if pressed:                     # between two holders: the pass's mean
                stage.move_sum[i] = stage.move_sum[i] + step
                stage.share_sum[i] = stage.share_sum[i] + shares[k]
            else:
                state.particle_position[i] += step
                stage.far[i] = ti.max(stage.far[i], _from_near_at(stage, state, i))
        stage.moved[None] = 1
    return unresolved


@ti.func
def stack_shares(stage: ti.template(), corners, weights, motion, n):
    """Each corner's share of a contact's correction (module doc, stacking): 1, but on the
    side of a resting contact whose level is the lower, 1 - (1 - stack) r, r = 1 while the
    pair approached over the step (along n: -motion . n) by at most RESTING thicknesses, 0
    from twice that. A side's level is the highest of its corners' (weights != 0; the vertex
    side has weights > 0). Then each side's corners take the other side's level + 1 where
    that is less (the support spreads through the contacts). Also returns whether both
    sides are held (level 0)."""
    near, far = 0, 0                      # the vertex (first edge) side's, the other side's
    for k in ti.static(range(4)):
        if weights[k] > 0:
            near = ti.max(near, stage.level[corners[k]])
        elif weights[k] < 0:
            far = ti.max(far, stage.level[corners[k]])
    shares = ti.Vector([1.0, 1.0, 1.0, 1.0])
    pressed = near == 0 and far == 0
    if near != far:
        limit = RESTING * stage.thickness[None]
        resting = ti.min(ti.max(2.0 + motion.dot(n) / limit, 0.0), 1.0)
        held = 1.0 - (1.0 - stage.stack[None]) * resting
        for k in ti.static(range(4)):
            if (weights[k] > 0 and near < far) or (weights[k] < 0 and far < near):
                shares[k] = held
    for k in ti.static(range(4)):
        i = corners[k]
        if weights[k] > 0:
            stage.level[i] = ti.min(stage.level[i], far + 1)
        elif weights[k] < 0:
            stage.level[i] = ti.min(stage.level[i], near + 1)
    return shares, pressed


@ti.func
def _inverse_mass(stage: ti.template(), model: ti.template(), i):
    """Particle i's inverse mass in the passes: 0 once the fail-safe moved it back in this
    step (it stays where the step started it: held, as a pin)."""
    return ti.select(stage.back[i] == 0, model.particle_inv_mass[i], 0.0)


@ti.func
def _out_of_colliders(stage: ti.template(), model: ti.template(), state: ti.template(),
                      colliders: ti.template(), i):
    """Particle i projected out of the colliders again if the pass moved it, unless the
    fail-safe moved it back in this step: it stays where the step started it. One the pass
    did not move is where the colliders' stage or an earlier pass left it, out of them: on a
    garment most particles, and their projections (an animated figure's mesh queried for
    each) were most of the passes' time."""
    if stage.back[i] == 0 and (state.particle_position[i] != stage.pass_at[i]).any():
        project_particle_out(model, state, colliders, i, stage.moved)


@ti.func
def _clear_back(stage: ti.template(), i):
    """None moved back yet, before a step's first passes (not before the passes that follow
    the fail-safe)."""
    if stage.again[None] == 0:
        never_through.clear_back(stage, i)


@ti.func
def seed_level(stage: ti.template(), model: ti.template(), state: ti.template(), i):
    """Before a step's passes: level 0 for a held particle (a pin, a handle), else UNHELD."""
    stage.level[i] = ti.select(_inverse_mass(stage, model, i) > 0, UNHELD, 0)


@ti.func
def seed_level_on(stage: ti.template(), model: ti.template(), state: ti.template(),
                  colliders: ti.template(), i):
    """seed_level, and level 0 for a particle resting on a collider: pushed out of one in the
    step, or within half a thickness of its surface (collision.rests_on)."""
    seed_level(stage, model, state, i)
    if rests_on(colliders, i, state.particle_position[i], 0.5 * stage.thickness[None]):
        stage.level[i] = 0


@ti.func
def keep_position(state: ti.template(), kept: ti.template(), i):
    kept[i] = state.particle_position[i]


@ti.func
def begin_passes(stage: ti.template()):
    """Before the first pass: passing and moving, none made, nothing left deep (the near
    pairs are marked as the passes find stale particles, or all of them in the first pass
    on a new list: `full`, set where the list is made)."""
    stage.passes[None] = 0
    stage.go[None] = 1
    stage.applying[None] = 1
    stage.left_deep[None] = 0
    stage.frame[None] = ti.Vector([0.0, 0.0, 0.0])
    if not stage.full[None]:        # span: the displacements since the list (after_step)
        stage.frame[None] = span_middle(stage)


@ti.func
def passing(stage: ti.template()):
    """Whether another pass (or the evaluation after the last) runs."""
    return stage.go[None]


@ti.func
def clear_counts(stage: ti.template()):
    """Before a pass: no contact counted or moved yet, no particle stale yet."""
    stage.touching[None] = ti.Vector([0, 0])
    stage.deepest[None] = 0.0
    stage.moved[None] = 0
    stage.stale_count[None] = 0


@ti.func
def keep_pass_start(stage: ti.template(), state: ti.template(), i):
    """Before a pass: where particle i is (pass_at), and whether it is stale: more than
    NEAR / 4 thicknesses from its near_at now or on the way since (far), or more than MOVED
    from its step's start (less the step's common motion, frames[2]); every particle in a
    pass that marks every pair. A stale particle's pairs are marked in this pass, from here:
    near_at is set again (module doc, near pairs)."""
    x = state.particle_position[i]
    stage.pass_at[i] = x
    far = ti.max(stage.far[i], _from_near_at(stage, state, i))
    moved = (x - stage.step_start[i] - stage.frames[2]).norm()
    stale = (stage.full[None] != 0 or far > 0.25 * NEAR * stage.thickness[None]
             or moved > MOVED * stage.thickness[None])
    stage.stale[i] = ti.select(stale, 1, 0)
    if stale:
        stage.near_at[i] = x - stage.frame[None]
        far = 0.0
        ti.atomic_add(stage.stale_count[None], 1)
    stage.far[i] = far


@ti.func
def measure_drift(stage: ti.template(), state: ti.template(), i):
    """far: the most particle i has been from its near_at, at the end of a pass too (the
    means and the colliders move it after the contacts)."""
    stage.far[i] = ti.max(stage.far[i], _from_near_at(stage, state, i))


@ti.func
def _from_near_at(stage: ti.template(), state: ti.template(), i):
    """How far particle i is from its near_at, less the common motion (frame)."""
    return (state.particle_position[i] - stage.frame[None] - stage.near_at[i]).norm()


@ti.func
def _pair_contact(stage: ti.template(), pairs: ti.template(), state: ti.template(), p):
    """Listed pair p at the current positions: (in contact, n, gap, weights g_k of its four
    particles), against the reach (1 + MARGIN thicknesses: module doc)."""
    reach = (1.0 + MARGIN) * stage.thickness[None]
    corners = pairs.particles[p]
    touching = False
    n = ti.Vector([0.0, 0.0, 0.0])
    gap = 0.0
    weights = ti.Vector([0.0, 0.0, 0.0, 0.0])
    if p < stage.pair_start[stage.triangle_count]:
        touching, n, gap, w = _vertex_triangle(state.particle_position, stage.step_start,
                                               corners, reach)
        weights = ti.Vector([1.0, -w[0], -w[1], -w[2]])
    else:
        touching, n, gap, s, t = _edge_edge(state.particle_position, stage.step_start,
                                            corners, reach)
        weights = ti.Vector([1.0 - s, s, t - 1.0, -t])
    touching = touching and not torn_pair(stage, state, pairs.elements[p],
                                          p < stage.pair_start[stage.triangle_count])
    return touching, n, gap, weights


@ti.func
def project_listed(stage: ti.template(), pairs: ti.template(), model: ti.template(),
                   state: ti.template(), item):
    """SelfCollision.in_solve, in a pass of the integrator (a loop of one item: the pairs in
    list order, the same bits in every run): each listed pair in contact at the current
    positions (_pair_contact: the side taken from the step's start) moved apart to the reach,
    mass-weighted along its weights, each corner's share by stacking (stack_shares, on the
    levels seed_levels gave before the step)."""
    total = stage.pair_start[stage.triangle_count + stage.edge_count]
    for p in range(ti.min(total, pairs.capacity)):
        touching, n, gap, weights = _pair_contact(stage, pairs, state, p)
        if touching:
            corners = pairs.particles[p]
            motion = ti.Vector([0.0, 0.0, 0.0])
            for k in ti.static(range(4)):
                motion += weights[k] * (state.particle_position[corners[k]]
                                        - stage.step_start[corners[k]])
            shares, _ = stack_shares(stage, corners, weights, motion, n)
            norm = 0.0
            for k in ti.static(range(4)):
                norm += (model.particle_inv_mass[corners[k]] * shares[k] * weights[k]
                         * weights[k])
            if norm > 0:
                for k in ti.static(range(4)):
                    i = corners[k]
                    state.particle_position[i] += (-model.particle_inv_mass[i] * shares[k]
                                                   * weights[k] * gap / norm) * n


@ti.func
def _held_level(stage: ti.template(), model: ti.template(), i):
    """Particle i's level before the integrator's passes (in_solve): 0 held, else UNHELD
    (seed_level's, from the state alone: not from the last step's moves back)."""
    stage.level[i] = ti.select(model.particle_inv_mass[i] > 0, UNHELD, 0)


@backend.kernel
def seed_levels(stage: ti.template(), model: ti.template()):
    """Every particle's _held_level."""
    for i in stage.level:
        _held_level(stage, model, i)


@backend.kernel
def seed_levels_on(stage: ti.template(), model: ti.template(), state: ti.template(),
                   colliders: ti.template()):
    """seed_levels, and 0 for a particle within half a thickness of a collider's surface
    (collision.near_surface: animated bodies are not asked, nor whether the last step's
    response touched it, which a saved state does not hold)."""
    for i in stage.level:
        _held_level(stage, model, i)
        if near_surface(colliders, i, state.particle_position[i], 0.5 * stage.thickness[None]):
            stage.level[i] = 0


@backend.kernel
def predict_path(model: ti.template(), state: ti.template(), dt: float, gx: float, gy: float,
                 gz: float):
    """Each free particle's position moved to x + dt v + dt^2 g (list_for_solve)."""
    g = ti.Vector([gx, gy, gz])
    for i in state.particle_position:
        if model.particle_inv_mass[i] > 0:
            state.particle_position[i] += dt * state.particle_velocity[i] + (dt * dt) * g


@ti.func
def evaluate_pair(stage: ti.template(), pairs: ti.template(), model: ti.template(),
                  state: ti.template(), p, dt):
    """Listed pair p at the current positions, if it is near or of a stale particle, whose
    pairs this pass marks near when their gap is below NEAR thicknesses (every pair where
    most particles are stale: a mark more is no harm, and reading the flags cost a busy
    pile's passes 5 %; a pair neither near nor marked is out of contact: module doc):
    active[p] (in contact in this or an earlier evaluation of
    the step; a pair skipped in the step's first pass is not) and, in contact, its moves
    (_contact_move); counts the contacts and those unresolved in touching, the smallest gap
    in deepest."""
    first = stage.passes[None] == 0           # the step's first evaluation
    mark = 2 * stage.stale_count[None] > stage.particle_count   # most: all, unread
    if stage.stale_count[None] > 0 and not mark:
        corners = pairs.particles[p]
        mark = (stage.stale[corners[0]] + stage.stale[corners[1]] + stage.stale[corners[2]]
                + stage.stale[corners[3]]) > 0
    if mark or pairs.near[p]:
        touching, n, gap, weights = _pair_contact(stage, pairs, state, p)
        if mark:
            pairs.near[p] = ti.select(gap < NEAR * stage.thickness[None], 1, 0)
        pairs.active[p] = ti.select(touching or (pairs.active[p] != 0 and not first), 1, 0)
        if touching:
            unresolved = _contact_move(stage, model, state, pairs.particles[p], weights, n,
                                       gap, stage.friction[None], first, dt)
            stage.touching[None][0] += 1
            stage.deepest[None] = ti.min(stage.deepest[None], gap)
            if unresolved:
                stage.touching[None][1] += 1
    elif first:
        pairs.active[p] = 0


@ti.func
def apply_means(stage: ti.template(), model: ti.template(), state: ti.template(), i):
    """Particle i moves by the sum of its moves from contacts between two held sides over the
    sum of their shares, or over 1 if less (module doc); the sums start again at 0."""
    shares = stage.share_sum[i]
    if _inverse_mass(stage, model, i) > 0 and shares > 0:
        state.particle_position[i] += stage.move_sum[i] / ti.max(shares, 1.0)
    stage.move_sum[i] = ti.Vector([0.0, 0.0, 0.0])
    stage.share_sum[i] = 0.0


@ti.func
def end_pass(stage: ti.template()):
    """After a pass: one that applied counts. No contact, or none unresolved in a pass that
    moved none (any but the step's first, which moves every contact: a step's contacts apply
    their friction at least once), ends the passes in the state it evaluated; after the last
    pass, one more evaluation only measures what is left. The next pass marks the pairs of
    the particles then stale (keep_pass_start), not every pair."""
    first = stage.applying[None] and stage.passes[None] == 0
    if stage.applying[None] and stage.touching[None][0] > 0:
        stage.passes[None] += 1
    if stage.touching[None][0] == 0 or (stage.touching[None][1] == 0 and not first):
        stage.go[None] = 0
    elif not stage.applying[None]:
        stage.left_deep[None] = 1
        stage.go[None] = 0
    elif stage.passes[None] == stage.iterations[None]:
        stage.applying[None] = 0
    stage.full[None] = 0


@ti.func
def follow_correction(stage: ti.template(), state: ti.template(), i, dt):
    """Particle i's velocity follows the contact corrections of this stage (v += dx / h)."""
    x = state.particle_position[i]
    state.particle_velocity[i] += (x - stage.before[i]) / dt
