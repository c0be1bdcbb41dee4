"""Scripted handles: particles moved along a path (the lecture's "click one of the particles and
pull it around", headless). A handle's particles are pinned (inverse mass 0) while it holds
them, so the integrators leave them alone; after the integrator of every step they are put
where the path says, with the velocity of that move, before strain limiting and colliders see
them. A handle with a release time lets go: its particles get their inverse mass back and go
on with the velocity the path gave them (no jump)."""

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import taichi as ti

from ..inputs import limits
from ..inputs.validation import as_array, in_range, require
from ..runtime import backend, plan
from ..runtime.plan import ITEM, NOW, STATE, Loop, Phase
from ..runtime.transfer import upload


@dataclass(frozen=True)
class Handle:
    """Particles moved along a scripted path.

    particles: indices of the particles the handle holds; they are pinned (inverse mass 0)
        while it holds them.
    path: t [s] -> displacement [m] from their rest positions, shape (3,) (all move together)
        or (len(particles), 3).
    release: time [s] the handle lets go, or None (it holds to the end). It holds for every
        step ending at or before `release`; the first step ending after it moves the particles
        freely, with their own masses and the velocity of the path's last move. A particle
        the body itself pins stays pinned.
    """

    particles: Sequence[int]
    path: Callable[[float], object]
    release: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "particles", as_array("Handle.particles", self.particles,
                                                       np.int64, (None,)))
        require(len(self.particles) > 0, "Handle.particles", [], "at least one particle index")
        require(callable(self.path), "Handle.path", self.path, "a callable t -> displacement")
        if self.release is not None:
            object.__setattr__(self, "release", in_range("Handle.release", self.release,
                                                         limits.TIME))

    def holds_after(self, t: float, dt: float) -> bool:
        """Whether it still holds in the step after the one ending at t [s] (steps of dt)."""
        return self.release is None or t + dt <= self.release * (1 + 1e-12)


@backend.kernel_argument
class HandleTable:
    """The held particles and their targets at the starts and ends of the steps of a launch
    (one step, or many: stepping.py), for a simulation whose handles hold `capacity`
    particles in all: `held` of them now, target[(2 k + e) * held + h] held particle h's
    target at the start (e = 0) and at the end (e = 1) of the launch's k-th step
    (HandleSet.schedule)."""

    def __init__(self, capacity: int):
        self.capacity = max(capacity, 1)
        fields = backend.FieldGroup()
        self.held = fields.scalar(ti.i32, 1)
        self.index = fields.scalar(ti.i32, self.capacity)
        self.target = fields.vector(3, backend.real(),
                                    2 * limits.SCHEDULED_STEPS * self.capacity)
        fields.finalize(self)

    @staticmethod
    def structure(capacity: int) -> tuple:
        return ("HandleTable", capacity)

    def load(self, capacity: int) -> None:
        """Nothing to load: schedule() writes the table before each launch."""

    def phases(self, model, forces, work) -> tuple:
        """The handle stage as phases (runtime/plan.py; `work` is this table)."""
        return (Phase(Loop(self.capacity, move_held, STATE, work, ITEM, NOW)),)


class HandleSet:
    """The handles of one simulation: which particles they hold and where those rest.

    handles: Handle objects; rest_position: the body's rest positions [m], shape (N, 3);
    body_pinned: (N,) bool, the body's own pins (released particles never leave those).
    """

    def __init__(self, handles: Sequence[Handle], rest_position: np.ndarray,
                 body_pinned: np.ndarray):
        self.handles = tuple(handles)
        count = len(rest_position)
        for h in self.handles:
            require(isinstance(h, Handle), "handles", h, "Handle objects")
            bad = h.particles[(h.particles < 0) | (h.particles >= count)]
            require(len(bad) == 0, "Handle.particles", bad.tolist(),
                    f"particle indices in [0, {count - 1}]")
        self.rest_position = rest_position
        self.body_pinned = np.asarray(body_pinned, bool)
        self._hold(self.handles)

    def _hold(self, holding: Sequence[Handle]) -> None:
        self.holding = tuple(holding)
        self.index = (np.concatenate([h.particles for h in self.holding]).astype(np.int32)
                      if self.holding else np.zeros(0, np.int32))

    def pinned(self, permanent: bool = False) -> np.ndarray:
        """(N,) bool: the body's pins and the particles of the handles holding now, or with
        `permanent` of those that never let go (the stable step is found without the rest)."""
        pinned = self.body_pinned.copy()
        held = [h for h in self.handles if h.release is None] if permanent else self.holding
        for h in held:
            pinned[h.particles] = True
        return pinned

    def targets(self, t: float) -> np.ndarray:
        """Where the held particles belong at time t [m], shape (len(index), 3)."""
        targets = []
        for h in self.holding:
            offset = np.asarray(h.path(t))
            shape = (3,) if offset.shape == (3,) else (len(h.particles), 3)
            offset = as_array(f"Handle.path({t})", offset, np.float64, shape)
            targets.append(self.rest_position[h.particles] + offset)
        target = np.concatenate(targets)
        far = np.abs(target).max()
        require(far <= limits.COORDINATE.high, f"Handle.path({t})", far,
                f"displacements keeping particles at coordinates {limits.COORDINATE.text()}")
        return target

    @property
    def launched(self):
        """The object a many-steps launch runs this stage's phases on: the HandleTable, which
        schedule() fills before each launch (stages.py)."""
        return self.table

    def after_step(self, model, state, t: float, dt: float, step_index: int) -> None:
        """The handle stage of a step ending at time t (stages.STEP_ORDER): the held
        particles to their targets, moving at the path's velocity over the step (dt [s]);
        handles whose release falls before the next step's end let go (model.set_pinned)."""
        if not self.holding:
            return
        self.schedule(step_index, 1, dt)
        plan.run(self.table, model, state, None, self.table, dt, step_index, False)
        self.let_go(model, t, dt)

    def steps_before_release(self, first: int, dt: float) -> int:
        """How many steps from step `first` on run before the step in whose handle stage a
        holding handle lets go (its particles are free for the stages after it in that
        step, so a many-steps launch stops before it)."""
        steps = limits.STEPS.high
        for h in self.holding:
            if h.release is not None:
                step = max(first, int(h.release / dt) - 2)
                while h.holds_after((step + 1) * dt, dt):
                    step += 1
                steps = min(steps, step - first)
        return steps

    def schedule(self, first: int, count: int, dt: float) -> int:
        """Table the targets of the held particles for steps first .. first + count - 1
        (count at most limits.SCHEDULED_STEPS) in `table` (a HandleTable); returns how many
        particles are held."""
        if not len(self.index):
            return self._table([])
        rows = []
        for k in range(count):
            t = (first + k + 1) * dt
            rows += [self.targets(max(t - dt, 0.0)), self.targets(t)]
        return self._table(rows)

    def _table(self, rows) -> int:
        """Write the held particles and `rows` (start and end targets of each step, in
        turn) into the HandleTable; returns how many particles are held."""
        held = len(self.index)
        if not held:
            upload(((self.table.held, [0]),))
            return 0
        # only the launch's rows: the rest of the table is never read
        target = np.concatenate(rows).astype(backend.numpy_real())
        upload(((self.table.index, self.index), (self.table.target, target),
                (self.table.held, [held])))
        return held

    def let_go(self, model, t: float, dt: float) -> None:
        """After the step ending at t [s]: handles whose release falls before the next
        step's end let go (model.set_pinned)."""
        still = [h for h in self.holding if h.holds_after(t, dt)]
        if len(still) < len(self.holding):
            self._hold(still)
            model.set_pinned(self.pinned())

    def place_at_start(self, model, state, dt: float) -> None:
        """Every handle holding again, its particles at their t = 0 targets, at rest (and let
        go at once by a handle whose release is before the first step's end)."""
        self._hold(self.handles)
        target = self.targets(0.0)
        if self._table([target, target]):
            plan.run(self.table, model, state, None, self.table, dt, 0, False)
        still = [h for h in self.holding if h.holds_after(0.0, dt)]
        self._hold(still)
        model.set_pinned(self.pinned())

    def hold_at(self, model, t: float, dt: float) -> None:
        """The handles holding after the step ending at t [s] (a loaded state's time) hold;
        the rest have let go (model.set_pinned)."""
        self._hold([h for h in self.handles if h.holds_after(t, dt)])
        model.set_pinned(self.pinned())


@ti.func
def move_held(state: ti.template(), table: ti.template(), h, now: ti.template()):
    """Held particle h (if that many are held) on its target of the launch's step now.k, with
    the path's history: the previous position its target a step ago and velocity =
    (target - previous) / dt, whatever the integrator did to it in between (it moves pinned
    particles by their velocity)."""
    held = table.held[0]
    if h < held:
        i = table.index[h]
        x_old = table.target[2 * now.k * held + h]
        x_new = table.target[(2 * now.k + 1) * held + h]
        state.particle_prev_position[i] = x_old
        state.particle_position[i] = x_new
        state.particle_velocity[i] = (x_new - x_old) / now.dt
