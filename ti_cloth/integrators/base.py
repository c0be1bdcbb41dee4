"""What every integrator offers: a name, its order of accuracy, its stability rule and its step,
written once as phases (runtime/plan.py)."""

import inspect
import math
import warnings
from contextlib import contextmanager
from typing import ClassVar

import numpy as np
import taichi as ti

from ..body.modes import stiffest_mode
from ..runtime import backend, plan, transfer
from . import fused

SETTINGS = 4    # run-time settings a workspace holds at most (Integrator.runtime_options)
PASSES = 0      # the settings' slot of a position-based step's passes (pbd, xpbd)


@backend.kernel_argument
class Integrator:
    """Advances a State by one step of dt [s] on a fixed Model.

    phases(model, forces, work) is the step, written once: a tuple of runtime/plan.py's nodes
    whose bodies are ti.funcs, read like a list of physical concerns. plan.run launches them
    phase by phase (GPUs, single steps); stepping.py runs many steps of them in one launch
    shared by a team of CPU workers. Options are keyword-only arguments of the constructor,
    validated there. They are compile-time constants of the kernels, except runtime_options:
    those (a solve's tolerances and caps, a number of passes) a kernel reads from its
    workspace's settings (settings_values, loaded before each launch by load_settings), so
    integrators that differ only in them are equal and share their compiled kernels, and a
    study sweeping them, or a user changing one, compiles nothing. stable_step() is the
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
    preset_noun: ClassVar[str] = "solves"   # what a preset names, in reports: "loose solves"
    runtime_options: ClassVar[tuple[str, ...]] = ()   # options kernels read at run time

    def phases(self, model, forces, work) -> tuple:
        """One step as runtime/plan.py's nodes; `work` is workspace()'s object."""
        if not self.fused:
            raise NotImplementedError
        return fused.phases(self, model, forces)

    def step(self, model, state, dt: float, forces, step_index: int) -> None:
        """One step, a launch per phase (plan.run); `step_index` is the step's global index,
        recorded by the divergence guard."""
        work = self.loaded_workspace(model, state)
        plan.run(self, model, state, forces, work, dt, step_index, not state.prev_valid)
        state.prev_valid = self.records_history
        self.after_launch(work)

    def workspace(self, model, state):
        """The working storage the phases read (a kernel argument; the State when none)."""
        return state

    def loaded_workspace(self, model, state):
        """workspace() with this integrator's settings in it (load_settings): what a launch
        of the phases gets."""
        work = self.workspace(model, state)
        self.load_settings(work)
        return work

    def settings_values(self) -> tuple[float, ...]:
        """The runtime_options as the kernels read them from work.settings, in slot order
        (at most SETTINGS; none by default)."""
        return ()

    def load_settings(self, work) -> None:
        """Upload settings_values() into work.settings (add_settings) unless it holds them."""
        values = self.settings_values()
        if values and work.loaded != values:
            transfer.upload(((work.settings, np.array(values, np.float64)),))
            work.loaded = values

    def take_settings(self, integrator) -> None:
        """Take the runtime_options of `integrator`, an equal integrator (the simulation's
        own, whose steps this one, the pool's copy, runs: Simulation.step)."""
        for name in self.runtime_options:
            setattr(self, name, getattr(integrator, name))

    def step_work(self, model) -> int:
        """A step's work in spring evaluations, for sizing launches (stepping.py)."""
        return fused.spring_work(model)

    def saved_history(self, model, state) -> dict:
        """What this integrator keeps of the steps before, beyond the State's fields, as
        numpy arrays for a saved state (Simulation.save_state); none by default."""
        return {}

    def restore_history(self, model, state, arrays: dict) -> None:
        """Load what saved_history returned (arrays of its shapes and types)."""

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

    def fit(self, cloth, drag: float, pinned) -> None:
        """Adapt run-time options to the body before its simulation is built (Simulation,
        with its drag [1/s] and held particles); nothing by default."""

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

    def changed_options(self) -> dict:
        """The options() not at their constructor's defaults: what a saved state's fingerprint
        holds of the integrator, so that an option a later version adds, at the default
        that keeps the motion as it was, leaves the states saved before it loadable."""
        defaults = {}
        for cls in reversed(type(self).__mro__):       # a subclass's defaults over its base's
            if "__init__" in vars(cls):
                defaults |= {name: p.default for name, p
                             in inspect.signature(cls.__init__).parameters.items()
                             if p.default is not inspect.Parameter.empty}
        return {k: v for k, v in self.options().items()
                if not (k in defaults and defaults[k] == v)}

    def compiled_options(self) -> dict:
        """The options the kernels are compiled for: all but runtime_options."""
        return {k: v for k, v in self.options().items() if k not in self.runtime_options}

    def __eq__(self, other) -> bool:
        """Integrators of one class with equal compiled options run the same kernels (and
        share them: pool.py); their runtime_options may differ."""
        return type(other) is type(self) and other.compiled_options() == self.compiled_options()

    def __hash__(self) -> int:
        return hash((type(self), repr(sorted(self.compiled_options().items()))))

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options().items())
        return f"{type(self).__name__}({opts})"


def add_settings(work, fields) -> None:
    """Give a workspace its run-time settings (Integrator.runtime_options): SETTINGS float64
    values in work.settings, a field of `fields` (a backend.FieldGroup not yet finalised),
    and the values last loaded into it, work.loaded (None: none yet)."""
    work.settings = fields.scalar(ti.f64, SETTINGS)
    work.loaded = None


def report_unconverged(integrator, stepper, reason: str, meaning: str) -> None:
    """Count into integrator.unconverged_solves the solves of the steps just taken that
    stopped at their cap short of their tolerance (`stepper`'s ran_out_pending, summed over
    its launches by after_launch from the workspace's RAN_OUT, which it clears; `stepper` may
    be `integrator`), and warn of the first (RuntimeWarning, once per integrator) with
    `reason` and what it means for such a step, and what to do (`meaning`)."""
    new, stepper.ran_out_pending = stepper.ran_out_pending, 0
    integrator.unconverged_solves += new
    if new and not integrator.warned_unconverged:
        integrator.warned_unconverged = True
        warnings.warn(
            f"{integrator.name}: {new} of the solves just made ended with {reason}: "
            f"{meaning}; {type(integrator).__name__}.unconverged_solves counts them (warned "
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
