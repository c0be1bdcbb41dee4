"""Sewing: the seams of a garment (body/panels.py, Cloth.seam_indices) pulled shut after each
step's integrator and handles, as Blender's sewing springs and Marvelous Designer's seams
close a garment over its first frames.

Each seam pair (i, j) is a distance constraint whose length shrinks at `speed` from the
pair's gap in the rest shape g0 to nothing: after the step ending at t, |x_i - x_j| <= max(0,
g0 - speed t), projected as position-based dynamics does (Mueller et al. 2007, the
lecture's relaxation): i moves w_i / (w_i + w_j) of the excess towards j (w the inverse
masses: a pinned or held particle stays, its partner comes all the way), averaged over its
partners when it has several (a corner where three panels meet). Velocities follow the
correction (v += correction / dt, as after strain limiting), so a seam approaches at about
`speed` and does not overshoot. Once the length is 0 the pair is held together every step,
as if welded; a Fabric's bending crosses it (energies/bending.hinges: a hinge across each
sewn edge, flat at rest), so it bends as the cloth does. The length depends on the time
alone, so a resumed run sews on with the same bits.

Each seam particle reads the positions kept before the stage and writes only its own, in a
fixed order of partners: deterministic, no atomics (Jacobi, one pass per step).
"""

from dataclasses import dataclass

import numpy as np
import taichi as ti

from ..inputs import limits
from ..inputs.validation import in_range, keyword_only
from ..runtime import backend, plan
from ..runtime.plan import ITEM, NOW, STATE, Loop, Phase
from ..runtime.transfer import upload


@keyword_only
@dataclass(frozen=True, kw_only=True)
class Sewing:
    """speed: how fast each seam closes [m/s] (a gap of 5 cm shuts in 0.1 s at 0.5 m/s):
    slow enough that the cloth follows, fast enough to be sewn in the first frames."""

    speed: float = 0.5

    def __post_init__(self):
        object.__setattr__(self, "speed", in_range("Sewing.speed", self.speed,
                                                   limits.SEWING_SPEED))


@backend.kernel_argument
class Seams:
    """The sewing stage of one simulation (stages.STEP_ORDER): the seam particles, each
    one's partners (CSR: partner[start[s]:start[s + 1]], positions in the seam list) and
    their gaps in the rest shape, the seam particles' positions before the stage."""

    def __init__(self, sewing: Sewing, pairs: np.ndarray, rest_position: np.ndarray):
        count, links = self.sizes(pairs)
        fields = backend.FieldGroup()
        self.particle = fields.scalar(ti.i32, count)
        self.start = fields.scalar(ti.i32, count + 1)
        self.partner = fields.scalar(ti.i32, links)
        self.gap = fields.scalar(backend.real(), links)
        self.before = fields.vector(3, backend.real(), count)
        self.speed = fields.scalar(backend.real(), 1)
        fields.finalize(self)
        self.count = count
        self.load(sewing, pairs, rest_position)

    @staticmethod
    def sizes(pairs: np.ndarray) -> tuple[int, int]:
        """(seam particles, partner links) of the seam pairs (P, 2)."""
        return len(np.unique(pairs)), 2 * len(pairs)

    @staticmethod
    def structure(sewing: Sewing, pairs: np.ndarray, rest_position: np.ndarray) -> tuple:
        return ("Seams",) + Seams.sizes(pairs)

    def load(self, sewing: Sewing, pairs: np.ndarray, rest_position: np.ndarray) -> None:
        """Sew the pairs (P, 2) of particle indices, apart by their gaps at `rest_position`
        (N, 3) [m] at first, at sewing.speed."""
        particles = np.unique(pairs)
        slot = np.searchsorted(particles, pairs)
        links = np.concatenate([slot, slot[:, ::-1]])          # both directions
        links = links[np.lexsort((links[:, 1], links[:, 0]))]
        start = np.searchsorted(links[:, 0], np.arange(len(particles) + 1))
        ends = rest_position[particles[links]]
        upload(((self.particle, particles.astype(np.int32)),
                (self.start, start.astype(np.int32)),
                (self.partner, links[:, 1].astype(np.int32)),
                (self.gap, np.linalg.norm(ends[:, 0] - ends[:, 1], axis=1)
                 .astype(backend.numpy_real())),
                (self.speed, [sewing.speed])))

    def phases(self, model, forces, work) -> tuple:
        """Keep the seam particles' positions, then pull each towards its partners."""
        return (Phase(Loop(self.count, keep_seam_position, STATE, work, ITEM)),
                Phase(Loop(self.count, sew, model, STATE, work, ITEM, NOW)))

    @property
    def launched(self):
        """The object a many-steps launch runs this stage's phases on: itself (stages.py)."""
        return self

    def after_step(self, model, state, t: float, dt: float, step_index: int) -> None:
        """The sewing stage of a step, a launch of its phases."""
        plan.run(self, model, state, None, self, dt, step_index, False)


@ti.func
def keep_seam_position(state: ti.template(), seams: ti.template(), s):
    seams.before[s] = state.particle_position[seams.particle[s]]


@ti.func
def sew(model: ti.template(), state: ti.template(), seams: ti.template(), s, now: ti.template()):
    """Seam particle s moved towards its partners (module doc), its velocity following."""
    i = seams.particle[s]
    w_i = model.particle_inv_mass[i]
    if w_i > 0:
        x_i = seams.before[s]
        sewn = seams.speed[0] * (now.step + 1) * now.dt     # how far every seam has closed
        pull = x_i * 0.0
        for k in range(seams.start[s], seams.start[s + 1]):
            o = seams.partner[k]
            gap = seams.before[o] - x_i
            length = gap.norm()
            allowed = ti.max(seams.gap[k] - sewn, 0.0)
            if length > allowed:
                share = w_i / (w_i + model.particle_inv_mass[seams.particle[o]])
                pull += share * (1.0 - allowed / length) * gap
        pull /= seams.start[s + 1] - seams.start[s]
        state.particle_position[i] = x_i + pull
        state.particle_velocity[i] = state.particle_velocity[i] + pull / now.dt
