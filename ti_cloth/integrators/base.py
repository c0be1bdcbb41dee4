"""What every integrator offers: a name, its order of accuracy, its stability rule and its step,
written once as phases (runtime/plan.py)."""

import math
import warnings
from contextlib import contextmanager
from typing import ClassVar

from ..body.modes import stiffest_mode
from ..runtime import backend, plan
from . import fused


@backend.kernel_argument
class Integrator:
    """Advances a State by one step of dt [s] on a fixed Model.

    phases(model, forces, work) is the step, written once: a tuple of runtime/plan.py's nodes
    whose bodies are ti.funcs, read like a list of physical concerns. plan.run launches them
    phase by phase (GPUs, single steps); stepping.py runs many steps of them in one launch
    shared by a team of CPU workers. Options are keyword-only arguments of the constructor,
    validated there (they are compile-time constants of the kernels). stable_step() is the
    integrator's own stability rule.

    A fused integrator needs nothing but the force at the start of the step: it defines the
    ti.func move(model, state, i, f, dt, step, start), which moves particle i given its total
    force f (start: 1 when the state has no history yet), and inherits fused.py's phases.
    """

    name: ClassVar[str]
    order: ClassVar[int]           # global order of accuracy in positions, smooth conservative forces
    position_based: ClassVar[bool] = False  # True: springs are constraints projected on positions
    step_limited: ClassVar[bool] = True     # False: stable at any step (stable_dt is inf)
    fused: ClassVar[bool] = False           # True: defines move(), fused.py writes the phases
    records_history: ClassVar[bool] = False  # True: a step leaves x_n in particle_prev_position
    runs_fabric: ClassVar[bool] = True      # False: steps springs only, not a Fabric's elements
    # named sets of options that trade the solve's accuracy for speed, which the study and the
    # advisor sweep beside the defaults (app/study.py: solves)
    presets: ClassVar[dict[str, dict]] = {}

    def phases(self, model, forces, work) -> tuple:
        """One step as runtime/plan.py's nodes; `work` is workspace()'s object."""
        if not self.fused:
            raise NotImplementedError
        return fused.phases(self, model, forces)

    def step(self, model, state, dt: float, forces, step_index: int) -> None:
        """One step, a launch per phase (plan.run); `step_index` is the step's global index,
        recorded by the divergence guard."""
        work = self.workspace(model, state)
        plan.run(self, model, state, forces, work, dt, step_index, not state.prev_valid)
        state.prev_valid = self.records_history
        self.after_launch(work)

    def workspace(self, model, state):
        """The working storage the phases read (a kernel argument; the State when none)."""
        return state

    def step_work(self, model) -> int:
        """A step's work in spring evaluations, for sizing launches (stepping.py)."""
        return fused.spring_work(model)

    def after_launch(self, work) -> None:
        """Read back what a launch left for reports (the last solve's figures)."""

    def copy_reports(self, stepper) -> None:
        """Take the reports of the last steps (the last solve's figures) from `stepper`, the
        equal integrator the simulation's kernels ran with (pool.py)."""

    def stable_step(self, cloth, drag: float, pinned) -> float:
        """Largest stable step [s] predicted for `cloth` with uniform drag [1/s] and `pinned`
        (N,) bool: inf when this integrator has no limit. A step-limited integrator applies
        its mode_stable_step to the stiffest mode of the springs (modes.stiffest_mode)."""
        if not self.step_limited:
            return math.inf
        w2, g = stiffest_mode(cloth, drag, pinned)
        return math.inf if w2 <= 0 else self.mode_stable_step(w2, g)

    def mode_stable_step(self, w2: float, g: float) -> float:
        """Largest stable step [s] on one mode of angular frequency^2 w2 [1/s^2] and damping
        rate g [1/s], from the linear analysis of this integrator's update matrix."""
        raise NotImplementedError

    def buffers(self, state, make):
        """This integrator's working storage for `state`, made by make() on first use and
        kept with the State (State.workspace, under buffer_key(): an integrator of a later
        simulation lent the same State reuses it)."""
        return state.workspace(self.buffer_key(), make)

    def buffer_key(self):
        """What this integrator's working storage depends on: its class (and options that
        change what it holds)."""
        return type(self)

    def options(self) -> dict:
        """Constructor options, for reports and repr."""
        return {}

    def __eq__(self, other) -> bool:
        """Integrators of one class with equal options are the same method (and share
        compiled kernels: pool.py)."""
        return type(other) is type(self) and other.options() == self.options()

    def __hash__(self) -> int:
        return hash((type(self), repr(sorted(self.options().items()))))

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options().items())
        return f"{type(self).__name__}({opts})"


def report_unconverged(integrator, stepper, reason: str) -> None:
    """Count into integrator.unconverged_solves the solves of the steps just taken that
    stopped at their cap short of their tolerance (`stepper`'s ran_out_pending, summed over
    its launches by after_launch from the workspace's RAN_OUT, which it clears; `stepper` may
    be `integrator`), and warn of the first (RuntimeWarning, once per integrator) with
    `reason`."""
    new, stepper.ran_out_pending = stepper.ran_out_pending, 0
    integrator.unconverged_solves += new
    if new and not integrator.warned_unconverged:
        integrator.warned_unconverged = True
        warnings.warn(
            f"{integrator.name}: {new} of the solves just made ended with {reason}: "
            "such a step is damped, not the implicit step asked for. Raise the cap or take "
            f"smaller steps; {type(integrator).__name__}.unconverged_solves counts them (warned "
            "once)", RuntimeWarning, stacklevel=4)


@contextmanager
def unconverged_unreported():
    """Within it, solves that stop at their cap are not warned of (report_unconverged's
    warning), for callers that measure what the steps did instead (the study's errors, a
    drape's settled speed); unconverged_solves still counts them."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "[^:]*: [0-9]+ of the solves just made ended",
                                RuntimeWarning)
        yield


def take_ran_out(work, slot: int) -> int:
    """The solves a launch left counted in work.iterations[slot] (row 0), cleared for the
    next launch (a workspace may serve another simulation next: pool.py)."""
    count = int(work.iterations[slot])
    if count:
        work.iterations[slot] = 0
    return count
