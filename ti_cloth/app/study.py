"""The speed/accuracy study: how much error each integrator and step buy, at what cost, and
where each one blows up, for one scene.

    reference = reference_trajectory(scene)          # rk4, f64, converged by halving dt
    result = run_study(scene)                        # integrator x dt x precision (x iterations,
                                                     # x solves)
    result.write("renders/study_cloth")              # study.csv, study.md, study.png

Every run starts the scene from rest and samples positions at each frame time; errors are
against the reference at the same times, at the scene file's own particles (the first ones at
every resolution, scene.own_particles), as a fraction of the cloth size (the diagonal of its
rest bounding box).

Resolution is an axis too (`resolutions=(1, 2, 4)`: the scene's bodies refined that many
times, scene.refined). The reference is then the scene at a finer resolution than any swept
(default twice the finest), and each run's error splits into discretisation (its
resolution's converged run, rk4/f64 as the reference, against the reference) and integration
(the run against its resolution's converged run). Orders of spatial convergence come from the
discretisation errors of successive resolutions (spatial_orders), and with them an estimate
of the reference's own error and of the resolution a tolerance needs. With one resolution
only, the reference is that resolution's own converged run (integration error alone). Cost is wall time per simulated second of the stepping alone (kernels are
compiled before timing; one Simulation per integrator and precision is restarted for each dt),
the median of `repeats` timings. Each configuration (precision, integrator, iterations or
solve) is one task: run here one after the other, or on local processes or a Dask cluster
(sweep.py; the timings are then taken with other tasks running, and the result says so).
"""

from __future__ import annotations

import gc
import math
import statistics
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import SimulationDiverged
from ..inputs import limits
from ..integrators import INTEGRATORS
from ..integrators.base import unconverged_unreported
from ..runtime import backend
from ..stability import stable_dt
from . import observables, study_report
from .sweep import Failure, as_workers, run_tasks

REFERENCE_TOLERANCE = 1e-9     # halving the reference step changes positions by less than this x size
MAX_REFERENCE_HALVINGS = 8
ENSEMBLE = 2                   # references from perturbed starts, when halving leaves a change
REFERENCE_BUDGET = 1e9         # particle-steps a reference may take in all (rk4 f64 on a Fabric,
                               # 2 cores: 0.13 us each on issue 53's 64² denim sheet, so about 2
                               # minutes at most; within 3e8 that sheet's reference made no
                               # halving, and no error was measured: docs/performance.md)
DEFAULT_INTEGRATORS = ("explicit_euler", "symplectic_euler", "verlet", "rk4", "stabilized_rk2",
                       "implicit_euler", "implicit_midpoint", "tr_bdf2", "pbd", "xpbd")
DEFAULT_ITERATIONS = (4, 16)   # passes per step of the position-based integrators
DEFAULT_SOLVES = ("loose", "bdf2", "tethered")   # presets (Integrator.presets) swept beside
                                     # each one's defaults: the Newton solves' loose, xpbd's
                                     # BDF2 step, and that step with tethers
STABLE_FRACTION = 0.9          # limit_dt: a step-limited integrator's step at most this x its
                               # predicted stable step (0.95 runs in trade_vs_newton.py)
ENERGY_BLOWUP = 1.0            # a run is diverged once its energy is off the reference's by more
                               # than the energy scale (or its guard trips: scene.GUARD_SIZES)


@dataclass(frozen=True)
class Reference:
    """Positions (samples, P, 3) [m] of the scene's own particles and total energies [J] at
    `times` [s], computed with rk4 in f64 at step `dt` on the scene at `resolution` (with
    `particles` in all); `change` is the largest position change (fraction of `size`) of the
    last halving.

    observables: (samples, K) the running means of observables.OBSERVABLES. uncertainty:
    (samples,) the reference's own pointwise uncertainty, a fraction of `size`: the change
    of its last halving, or the spread of references started ENSEMBLE ways at the rounding
    level when that is larger; predictable: how many samples have it within `tolerance`
    (those up to the horizon T*, where pointwise errors are measured); chaotic: whether a
    perturbation at the rounding level grew beyond `tolerance` (else an uncertainty beyond
    it is a halving that did not converge in MAX_REFERENCE_HALVINGS); observable_spread:
    the observables' largest difference across the perturbed starts (0 without them), the
    level below which an observable's error is chaos."""

    times: np.ndarray
    positions: np.ndarray
    energies: np.ndarray
    dt: float
    change: float
    size: float
    energy_scale: float
    resolution: int = 1
    particles: int = 0
    observables: np.ndarray | None = None
    uncertainty: np.ndarray | None = None
    tolerance: float = REFERENCE_TOLERANCE
    chaotic: bool = False
    observable_spread: float = 0.0
    limited: str = ""       # what stopped the halvings short of the tolerance, if not chaos

    @property
    def predictable(self) -> int:
        """How many samples, from the first, lie within the predictability horizon."""
        if self.uncertainty is None:
            return len(self.times)
        return observables.horizon(self.times, self.uncertainty, self.tolerance)

    @property
    def horizon(self) -> float:
        """T* [s]: the last sample time of the predictable ones (0 when none is)."""
        k = self.predictable
        return float(self.times[k - 1]) if k else 0.0

    @property
    def whole_run(self) -> bool:
        """Whether every sample is within the horizon."""
        return self.predictable == len(self.times)


@dataclass(frozen=True)
class Run:
    """One integrator at one dt, precision and iteration count (pbd, xpbd) or solve (None: its
    defaults; else the name of its preset, Integrator.presets), with its metrics.

    max_error / rms_error: particle position error against the reference, max and RMS over all
    particles and the sample times up to the reference's horizon (Reference.predictable; NaN
    when it holds none), as a fraction of the cloth size; observable_error: the largest
    difference of its observables (observables.py: running means of the centre of mass, the
    bounding box and the strain; and energy_drift) from the reference's over the whole run;
    energy_drift: largest
    |E - E_ref| at the sample times as a fraction of the energy scale (total weight x cloth
    size, or the reference's largest kinetic + spring energy without gravity); max_strain:
    largest spring strain (|l - L| / L) at the sample times; cost: wall seconds per simulated
    second, the median of the timings (cost_spread: their half range over the median, NaN
    with one timing). diverged: the divergence guard tripped (NaN, inf, a coordinate beyond scene.GUARD_SIZES
    cloth sizes; metrics NaN) or the energy left the reference's by more than ENERGY_BLOWUP
    energy scales (more than gravity can do across the whole cloth: an explicit integrator
    blowing up more slowly; metrics kept); diverged_step: the step where that was seen (-1: none).
    """

    integrator: str
    precision: str
    iterations: int | None
    dt: float
    steps: int
    wall_seconds: float
    cost: float
    diverged: bool
    diverged_step: int
    max_error: float
    rms_error: float
    energy_drift: float
    max_strain: float
    predicted_stable_dt: float
    resolution: int = 1
    particles: int = 0
    discretisation_error: float = math.nan
    integration_error: float = math.nan
    observable_error: float = math.nan
    cost_spread: float = math.nan
    solve: str | None = None

    @property
    def label(self) -> str:
        name = integrator_label(self.integrator, self.iterations, self.solve)
        return f"{name} {self.precision}" + (f" x{self.resolution}" if self.resolution != 1 else "")

    @property
    def method(self) -> str:
        """The integrator and its passes or preset in words: "xpbd (16 it)",
        "implicit_midpoint (loose solves)", "xpbd (10 it) (bdf2 step)"."""
        noun = INTEGRATORS[self.integrator].preset_noun
        return (self.integrator + ("" if self.iterations is None else f" ({self.iterations} it)")
                + ("" if self.solve is None else f" ({self.solve} {noun})"))


def sample_times(scene, duration: float | None = None) -> np.ndarray:
    """Every frame time of the scene (or of `duration` seconds at its fps)."""
    frames = scene.frames if duration is None else max(1, round(duration * scene.fps))
    return scene.frame_dt * np.arange(1, frames + 1)


def _trajectory(sim, times: np.ndarray, steps_per_frame: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Positions and energies at the sample times, and the wall time spent stepping.

    Python's garbage collector is paused meanwhile, as timeit does: in a process holding many
    objects a full collection takes tens of milliseconds, more than a small run's whole cost,
    and where it falls would decide which of two runs looks cheaper."""
    positions, energies, wall = [], [], 0.0
    frame_steps = np.rint(times / times[0]).astype(int) * steps_per_frame
    done = 0
    collecting = gc.isenabled()
    gc.disable()
    try:
        with unconverged_unreported():
            for target in frame_steps:
                start = time.perf_counter()
                sim.step(int(target - done))
                positions.append(sim.positions())   # also waits for the device: the cost's
                wall += time.perf_counter() - start
                energies.append(sim.energy()["total"])
                done = target
    finally:
        if collecting:
            gc.enable()
    return np.array(positions), np.array(energies), wall


def reference_trajectory(scene, duration: float | None = None, arch: str = "cpu",
                         tolerance: float = REFERENCE_TOLERANCE,
                         budget: float = REFERENCE_BUDGET) -> Reference:
    """rk4 in f64 from the largest frame_dt / 2^k below half its stable step, halved until the
    positions at every sample change by less than tolerance x cloth size, or until a halving
    no longer moves the horizon (the samples, from the first, within it: on a chaotic scene
    the late samples never converge), at most MAX_REFERENCE_HALVINGS times. When a change
    is left, ENSEMBLE more runs at the last step start from positions perturbed at the
    rounding level (observables.perturbed_start): their spread tells chaos from a halving
    that did not converge, and bounds what observables can resolve. The runs take at most
    `budget` particle-steps in all: a halving that would pass it is not made, and a first
    run that would is made with fewer steps (rk4 may then diverge: the reference is then
    unknown, NaN). Never raises on a scene that runs: the Reference says the level it
    reached (uncertainty, predictable) and what limited it. Positions are kept at the
    scene's own particles."""
    backend.ensure(arch=arch, precision="f64")
    times = sample_times(scene, duration)
    size = scene.size
    own = scene.own_particles
    limit = 0.5 * stable_dt(scene.cloth, "rk4", scene.drag)
    substeps = 2 ** max(0, math.ceil(math.log2(scene.frame_dt / limit))) if math.isfinite(limit) else 1
    frame_work = len(times) * scene.cloth.particle_count      # particle-steps per substep
    limited = ""
    if substeps * frame_work > budget:
        substeps = 2 ** max(0, math.floor(math.log2(budget / frame_work)))
        limited = (f"rk4's stable step needs {scene.frame_dt / (2 * limit):.3g} steps per frame, "
                   f"beyond the budget of {budget:.3g} particle-steps: it ran {substeps}")
    sim = scene.build(integrator="rk4", dt=scene.frame_dt / substeps)
    try:
        positions, energies, _ = _trajectory(sim, times, substeps)
    except SimulationDiverged as err:
        return _unknown(scene, times, own, sim.dt, f"{limited}, and diverged at step {err.step}",
                        tolerance)
    spent = substeps * frame_work
    reached, change = -1, np.full(len(times), math.inf)
    for _ in range(MAX_REFERENCE_HALVINGS):
        if spent + 2 * substeps * frame_work > budget:
            limited = limited or (f"the next halving would pass the budget of {budget:.3g} "
                                  "particle-steps")
            break
        substeps *= 2
        spent += substeps * frame_work
        sim.restart(scene.frame_dt / substeps)
        previous, before = positions, (None if reached < 0 else change)
        try:
            positions, energies, _ = _trajectory(sim, times, substeps)
        except SimulationDiverged as err:     # at a smaller step: not a reference to refine
            positions = previous
            limited = f"the halving to {sim.dt:.3g} s diverged at step {err.step}"
            substeps //= 2
            sim.restart(scene.frame_dt / substeps)
            break
        change = np.abs(positions - previous).max(axis=(1, 2)) / size
        within = observables.horizon(times, change, tolerance)
        if within == len(times) or (within <= reached and not _shrinking(change, before, within)):
            break
        reached = within
    else:
        limited = f"{MAX_REFERENCE_HALVINGS} halvings, the most a reference makes"
    values = observables.observables(scene.cloth, positions, size)
    energy_scale = _energy_scale(scene, energies, size)
    spread, observable_spread = np.zeros(len(times)), 0.0
    if change.max() >= tolerance and spent + ENSEMBLE * substeps * frame_work <= budget:
        for seed in range(ENSEMBLE):
            sim.restart()
            observables.perturbed_start(sim, size, seed)
            try:
                other, other_energies, _ = _trajectory(sim, times, substeps)
            except SimulationDiverged:            # a start one rounding away diverges
                spread[:] = math.inf
                break
            spread = np.maximum(spread, np.abs(other - positions).max(axis=(1, 2)) / size)
            observable_spread = max(
                observable_spread, float(np.abs(other_energies - energies).max()) / energy_scale,
                observables.difference(observables.observables(scene.cloth, other, size), values))
    return Reference(times, positions[:, own], energies, sim.dt, float(change.max()), size,
                     energy_scale, scene.resolution,
                     scene.cloth.particle_count, values, np.maximum(change, spread), tolerance,
                     bool(spread.max() >= tolerance), observable_spread,
                     "" if change.max() < tolerance else limited)


def _unknown(scene, times, own, dt: float, why: str, tolerance: float) -> Reference:
    """A reference that could not be computed (why): NaN positions and energies, no sample
    predictable; a study against it measures nothing, and says why."""
    count = scene.cloth.particle_count
    nan = np.full((len(times), count, 3), math.nan)
    return Reference(times, nan[:, own], np.full(len(times), math.nan), dt, math.inf,
                     scene.size, _energy_scale(scene, np.zeros(1), scene.size),
                     scene.resolution, count, np.full((len(times), len(observables.OBSERVABLES)),
                                                      math.nan),
                     np.full(len(times), math.inf), tolerance, False, 0.0, why)


def _shrinking(change: np.ndarray, before: np.ndarray | None, within: int) -> bool:
    """Whether the last halving still shrank the changes beyond the horizon (their median by
    a quarter or more: a first-order scene, whose forcing is held over each step, halves
    them): it converges there, only more slowly; where the motion is chaotic they stay as
    large."""
    if before is None:
        return True
    ratio = change[within:] / np.maximum(before[within:], 1e-300)
    return bool(np.median(ratio) <= 0.75)


def distance(a: Reference, b: Reference) -> tuple[float, float]:
    """(max, RMS) distance between two trajectories of the same scene's own particles, as
    fractions of the cloth size, over the samples both predict (NaN when none)."""
    k = min(a.predictable, b.predictable)
    if k == 0:
        return math.nan, math.nan
    error = np.linalg.norm(a.positions[:k] - b.positions[:k], axis=2) / a.size
    return float(error.max()), rms(error)


def observable_distance(a: Reference, b: Reference) -> float:
    """The largest difference of two trajectories' observables over the whole run."""
    return observables.difference(a.observables, b.observables)


def rms(values: np.ndarray) -> float:
    """Root mean square of `values`, summed exactly (math.fsum): numpy's pairwise sums take
    another order for another memory alignment, and a study's rows must be the same bits in
    every process."""
    return math.sqrt(math.fsum((values ** 2).ravel()) / values.size)


def order_between(a: int, error_a: float, b: int, error_b: float, r: int) -> float:
    """The order p of spatial convergence that resolutions a < b with discretisation errors
    error_a, error_b against a reference at resolution r > b give, when the error at f is
    C (f^-p - r^-p) (the reference's own error C r^-p taken out); NaN when they do not shrink
    (bisection on p in (0, 8])."""
    if not (error_b > 0 and error_a > error_b and math.isfinite(error_a)):
        return math.nan

    def ratio(p):
        return (a ** -p - r ** -p) / (b ** -p - r ** -p)

    if ratio(8.0) < error_a / error_b:
        return 8.0
    lo, hi = 1e-6, 8.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ratio(mid) < error_a / error_b else (lo, mid)
    return 0.5 * (lo + hi)


def _energy_scale(scene, reference_energies: np.ndarray, size: float) -> float:
    weight = float(scene.cloth.particle_mass.sum() * np.linalg.norm(scene.gravity))
    if weight > 0:
        return weight * size
    return max(float(np.abs(reference_energies - reference_energies[0]).max()), 1e-300)


def _max_strain(cloth, positions: np.ndarray) -> float:
    i, j = cloth.spring_indices.T
    rest = cloth.spring_rest_length
    keep = rest > 0
    if not keep.any():
        return 0.0
    lengths = np.linalg.norm(positions[:, i] - positions[:, j], axis=2)
    return float(np.abs(lengths[:, keep] / rest[keep] - 1.0).max())


def default_dts(scene, integrators) -> list[float]:
    """frame_dt / 2^k from one step per frame down to the first step at or below half the
    smallest predicted stable step of the step-limited integrators (at least 6 steps)."""
    stable = [stable_dt(scene.cloth, name, scene.drag) for name in integrators]
    stable = [s for s in stable if 0 < s < math.inf]
    smallest = 0.5 * min(stable) if stable else scene.frame_dt / 32
    count = max(6, math.ceil(math.log2(scene.frame_dt / smallest)) + 1)
    return [scene.frame_dt / 2 ** k for k in range(count)]


def limit_dt(scene, integrator: str) -> float | None:
    """The largest frame_dt / n at most STABLE_FRACTION of `integrator`'s predicted stable
    step on `scene`: the step an explicit method is cheapest at. None for an integrator
    without a limit, or where one step per frame is within it (default_dts has that step)."""
    stable = stable_dt(scene.cloth, integrator, scene.drag)
    if not 0 < stable < math.inf:
        return None
    n = math.ceil(scene.frame_dt / (STABLE_FRACTION * stable) * (1 - 1e-12))
    return scene.frame_dt / n if n > 1 else None


def steps_of(steps: list[float], scene, integrator: str) -> list[float]:
    """The default steps of `integrator` in a study: `steps` (default_dts) and its limit_dt,
    largest first (once)."""
    limit = limit_dt(scene, integrator)
    if limit is None or any(math.isclose(limit, dt, rel_tol=1e-9) for dt in steps):
        return steps
    return sorted([*steps, limit], reverse=True)


@dataclass
class StudyResult:
    """The reference and every run; write() produces the CSV, the markdown table and the plot.
    timing: how the costs were measured ("serial", or what ran at once); failed: the
    configurations whose task did not finish, {label: error}; incidents: those whose worker
    failed once, {label: (error, recovered by the retry)}."""

    scene_name: str
    reference: Reference
    runs: list[Run] = field(default_factory=list)
    timing: str = "serial"
    failed: dict[str, str] = field(default_factory=dict)
    incidents: dict[str, tuple[str, bool]] = field(default_factory=dict)
    converged: dict[int, Reference] = field(default_factory=dict)   # by resolution
    left_out: dict[str, str] = field(default_factory=dict)   # integrators that cannot run it

    @property
    def swept(self) -> bool:
        """Whether resolution was an axis (the reference finer than a swept resolution)."""
        return bool(self.converged) and set(self.converged) != {self.reference.resolution}

    def discretisation(self) -> dict[int, tuple[float, float]]:
        """{resolution: (max, RMS) distance of its converged run from the reference}, for the
        swept resolutions coarser than the reference's."""
        return {f: distance(ref, self.reference) for f, ref in sorted(self.converged.items())
                if f != self.reference.resolution}

    def observable_discretisation(self) -> dict[int, float]:
        """{resolution: its converged run's largest observable difference from the
        reference's, over the whole run} (observables compare across resolutions: where
        folds form changes with the mesh, and under chaos positions do not converge)."""
        return {f: observable_distance(ref, self.reference)
                for f, ref in sorted(self.converged.items()) if f != self.reference.resolution}

    def spatial_orders(self) -> list[tuple[int, int, float]]:
        """(a, b, p) for successive swept resolutions a < b: the observed order of spatial
        convergence of the max error (order_between)."""
        errors = [(f, e[0]) for f, e in self.discretisation().items()]
        return [(a, b, order_between(a, ea, b, eb, self.reference.resolution))
                for (a, ea), (b, eb) in zip(errors, errors[1:])]

    def reference_error(self) -> float:
        """The reference's own max error against the converged cloth, estimated from the
        finest observed order: C r^-p with C from the finest swept resolution (NaN without
        two resolutions that converge)."""
        orders = self.spatial_orders()
        if not orders or not math.isfinite(orders[-1][2]):
            return math.nan
        _, b, p = orders[-1]
        r = self.reference.resolution
        return self.discretisation()[b][0] * r ** -p / (b ** -p - r ** -p)

    def resolution_for(self, error: float) -> float:
        """The resolution whose discretisation error the observed order puts at `error`
        (C f^-p = error; NaN when the order is unknown)."""
        orders = self.spatial_orders()
        if not orders or not math.isfinite(orders[-1][2]):
            return math.nan
        _, b, p = orders[-1]
        r = self.reference.resolution
        constant = self.discretisation()[b][0] / (b ** -p - r ** -p)
        return (constant / error) ** (1.0 / p)

    def largest_stable_dt(self) -> dict[str, float]:
        """Per configuration (label): the largest dt of the sweep such that it and every
        smaller dt ran without diverging (0 if the smallest diverged)."""
        result = {}
        for label in dict.fromkeys(r.label for r in self.runs):
            ok = 0.0
            for run in sorted((r for r in self.runs if r.label == label), key=lambda r: r.dt):
                if run.diverged:
                    break
                ok = run.dt
            result[label] = ok
        return result

    def pareto_front(self) -> list[Run]:
        """The runs that did not diverge and that no other such run beats in both cost and
        max error (pareto_front)."""
        return pareto_front(self.runs)

    def csv_text(self) -> str:
        """Every run, a CSV row each (study_report.py)."""
        return study_report.csv_text(self)

    def markdown(self) -> str:
        """The study's tables (study_report.py)."""
        return study_report.markdown(self)

    def plot(self, path) -> Path:
        """The error-against-cost plot, written to `path` (study_report.py)."""
        return study_report.plot(self, path)

    def write(self, folder, plot: bool = True) -> list[Path]:
        """study.csv, study.md and (plot) study.png in `folder`, each written atomically."""
        return study_report.write(self, folder, plot)


def pareto_front(runs) -> list[Run]:
    """Runs that did not diverge and that no other such run beats in both cost and max error."""
    ok = [r for r in runs if not r.diverged]
    return [r for r in ok if not any(o.cost <= r.cost and o.max_error <= r.max_error
                                     and (o.cost < r.cost or o.max_error < r.max_error) for o in ok)]


def left_out(scene, integrators) -> dict[str, str]:
    """{name: why} of the integrators that cannot run `scene` (pbd on a Fabric)."""
    for name in integrators:
        if name not in INTEGRATORS:
            raise ValueError(f"integrators: {name!r} is not one of {sorted(INTEGRATORS)}")
    if not scene.cloth.fabric:
        return {}
    return {name: "steps springs only, not a Fabric's elements" for name in integrators
            if not INTEGRATORS[name].runs_fabric}


def _configurations(integrators, iterations, solves):
    """(name, iterations or None, solve or None) of every configuration of the sweep, in
    order: each integrator at its defaults, then with each of `solves` that is one of its
    presets, a position-based one at each pass count."""
    for name in integrators:
        counts = iterations if INTEGRATORS[name].position_based else (None,)
        for solve in (None,) + tuple(s for s in solves if s in INTEGRATORS[name].presets):
            for count in counts:
                yield name, count, solve


def _check_solves(solves) -> tuple[str, ...]:
    """`solves` as a tuple, each the name of some integrator's preset."""
    known = sorted({name for cls in INTEGRATORS.values() for name in cls.presets})
    if not isinstance(solves, (str, list, tuple)):
        raise ValueError(f"solves: {solves!r} is not a list of preset names; the presets are "
                         f"{known} (Integrator.presets), or none: ()")
    values = (solves,) if isinstance(solves, str) else tuple(solves)
    for solve in values:
        if solve not in known:
            raise ValueError(f"solves: {solve!r} is not a preset of any integrator; the "
                             f"presets are {known} (Integrator.presets), or none: ()")
    return values


def integrator_options(name: str, iterations: int | None, solve: str | None) -> dict:
    """The options a configuration gives its integrator beyond the defaults: `iterations`
    passes a step (pbd, xpbd) and the preset `solve` (Integrator.presets)."""
    options = {} if iterations is None else {"iterations": iterations}
    return options | (INTEGRATORS[name].presets[solve] if solve is not None else {})


def configured_integrator(name: str, iterations: int | None, solve: str | None):
    """The Integrator of a configuration (integrator_options)."""
    return INTEGRATORS[name](**integrator_options(name, iterations, solve))


def integrator_label(name: str, iterations: int | None, solve: str | None) -> str:
    """xpbd(16) for 16 passes a step, implicit_midpoint[loose] for a preset, else the name."""
    return (name + ("" if iterations is None else f"({iterations})")
            + ("" if solve is None else f"[{solve}]"))


@dataclass(frozen=True)
class Configuration:
    """One task of a study: every dt of one integrator (with `iterations` passes for pbd /
    xpbd, or its preset `solve`) in one precision on `scene` (at one resolution), against
    `reference` and its resolution's `converged` run; `threads`: Taichi's CPU threads (None:
    all)."""

    scene: object
    reference: Reference
    converged: Reference
    precision: str
    integrator: str
    iterations: int | None
    dts: tuple
    substeps: tuple
    arch: str
    threads: int | None
    repeats: int
    solve: str | None = None

    @property
    def label(self) -> str:
        name = integrator_label(self.integrator, self.iterations, self.solve)
        resolution = self.scene.resolution
        return f"{name} {self.precision}" + (f" x{resolution}" if resolution != 1 else "")


_ONE_AT_A_TIME = threading.Lock()    # Taichi runs one task at a time in a process


def measure_configuration(task: Configuration) -> list[Run]:
    """The runs of one configuration (a Simulation built once, restarted for each dt): the
    task a worker process runs. With repeats, every dt is timed once per round, in turn
    with the others (as the benchmarks alternate runs): a slow moment of the machine falls
    on one timing of several runs, not on all timings of one."""
    with _ONE_AT_A_TIME:
        backend.ensure(arch=task.arch, precision=task.precision, threads=task.threads)
        integrator = configured_integrator(task.integrator, task.iterations, task.solve)
        sim = task.scene.build(integrator=integrator, dt=task.dts[-1])
        try:
            with unconverged_unreported():
                sim.step(1)     # compile outside the timing (a step that diverges compiles too)
        except SimulationDiverged:
            pass
        predicted = sim.stable_dt()
        runs, walls = [], []
        for dt, n in zip(task.dts, task.substeps):
            sim.restart(dt)
            runs.append(_measure(task, sim, n, predicted))
            walls.append([runs[-1].wall_seconds])
        for _ in range(task.repeats - 1):
            for k, (dt, n) in enumerate(zip(task.dts, task.substeps)):
                if not runs[k].diverged:
                    sim.restart(dt)
                    walls[k].append(_trajectory(sim, task.reference.times, n)[2])
        return [run if run.diverged else with_timings(run, w) for run, w in zip(runs, walls)]


def with_timings(run: Run, walls) -> Run:
    """`run` with its cost the median of the wall times `walls` [s] and their spread."""
    wall = statistics.median(walls)
    spread = (max(walls) - min(walls)) / (2 * wall) if len(walls) > 1 and wall > 0 else math.nan
    return replace(run, wall_seconds=wall, cost=wall * run.cost / run.wall_seconds
                   if run.wall_seconds > 0 else run.cost, cost_spread=spread)


def retime_in_turn(scene, runs, result: "StudyResult", repeats: int,
                   arch: str = "cpu") -> dict[int, Run]:
    """{id(run): run re-measured}: `runs` of `result` measured again here, `repeats` rounds
    each timing every run once, in turn (their errors come out the same: the same bits), each
    cost the median of its timings, with their spread (with_timings)."""
    walls = {id(run): [] for run in runs}
    for _ in range(repeats):
        for run in runs:
            walls[id(run)].append(retime(scene, run, result, 1, arch).wall_seconds)
    return {id(run): with_timings(run, walls[id(run)]) for run in runs}


def retime(scene, run: Run, result: "StudyResult", repeats: int, arch: str = "cpu") -> Run:
    """`run` of `result` measured again here, its cost the median of `repeats` timings (its
    errors come out the same: the same bits)."""
    refined = scene.refined(run.resolution)
    converged = result.converged.get(run.resolution, result.reference)
    task = Configuration(refined, result.reference, converged, run.precision, run.integrator,
                         run.iterations, (run.dt,), (round(scene.frame_dt / run.dt),), arch, None,
                         repeats, run.solve)
    return measure_configuration(task)[0]


def run_study(scene, *, integrators=DEFAULT_INTEGRATORS, dts=None, precisions=("f64", "f32"),
              iterations=DEFAULT_ITERATIONS, solves=DEFAULT_SOLVES, duration: float | None = None,
              arch: str = "cpu", reference: Reference | None = None, repeats: int = 1,
              resolutions=None, reference_resolution: int | None = None, executor=None,
              progress: bool = True) -> StudyResult:
    """Sweep resolution x integrator x dt x precision (x iterations for pbd/xpbd, x solves
    for the integrators with those presets: Integrator.presets, each beside the integrator's
    defaults; solves=() for the defaults alone) on `scene` (a Scene from load_scene).
    resolutions: the bodies' refinements to sweep (default the scene's own);
    reference_resolution: the reference's (default: twice the finest swept when
    more than the scene's own resolution is swept, else the scene's own). dts: steps [s],
    each frame_dt / an integer (default: default_dts of each resolution and, for a
    step-limited integrator, its limit_dt too: the step it is cheapest at, which the steps
    frame_dt / 2^k may miss by up to half). duration: simulated seconds (default the
    scene's). repeats: timings per run (cost: their median).
    executor: where the configurations run: any concurrent.futures.Executor, or the
    sweep.Workers of sweep.local_jobs / sweep.dask_cluster (default: here, one after the
    other). Rows come in configuration order whichever finishes first. Leaves Taichi
    initialised with the last precision run here.
    """
    from tqdm import tqdm

    for p in precisions:
        if p not in backend.PRECISIONS:
            raise ValueError(f"precisions: {p!r} is not one of {sorted(backend.PRECISIONS)}")
    if not (isinstance(repeats, int) and repeats >= 1):
        raise ValueError(f"repeats must be an integer >= 1, got {repeats!r}")
    resolutions = _resolutions(scene, resolutions)
    if reference_resolution is None:
        reference_resolution = (scene.resolution if resolutions == (scene.resolution,)
                                else 2 * resolutions[-1])
    if reference_resolution > limits.RESOLUTION.high:
        raise ValueError(f"resolutions: the reference is refined {reference_resolution} times "
                         f"(twice the finest swept, {resolutions[-1]}), beyond the limit "
                         f"{limits.RESOLUTION.high}; sweep resolutions up to "
                         f"{limits.RESOLUTION.high // 2}, or give a reference_resolution")
    if not (reference_resolution > resolutions[-1] or resolutions == (reference_resolution,)):
        raise ValueError(f"reference_resolution must be finer than every swept resolution "
                         f"{list(resolutions)} (or the only one), got {reference_resolution!r}")
    skipped = left_out(scene, integrators)
    integrators = tuple(name for name in integrators if name not in skipped)
    if not integrators:
        raise ValueError(f"integrators: none of {sorted(skipped)} can run this scene "
                         f"({'; '.join(f'{n} {why}' for n, why in skipped.items())})")
    configurations = list(_configurations(integrators, iterations, _check_solves(solves)))
    workers = as_workers(executor)
    if reference is None:
        reference = reference_trajectory(scene.refined(reference_resolution), duration, arch)
    converged = {f: reference if f == reference.resolution
                 else reference_trajectory(scene.refined(f), duration, arch) for f in resolutions}
    tasks = []
    for f in resolutions:
        refined = scene.refined(f)
        steps = sorted(default_dts(refined, integrators) if dts is None else dts, reverse=True)
        own = {name: steps if dts is not None else steps_of(steps, refined, name)
               for name in integrators}
        tasks += [Configuration(refined, reference, converged[f], precision, name, count,
                                tuple(own[name]), tuple(_substeps(scene, dt) for dt in own[name]),
                                arch, workers.threads if workers is not None else None, repeats,
                                solve)
                  for precision in precisions for name, count, solve in configurations]
    with tqdm(total=sum(len(t.dts) for t in tasks), unit="run", disable=not progress,
              dynamic_ncols=True) as bar:        # closed on Ctrl-C too
        results, incidents = run_tasks(measure_configuration, tasks, workers,
                                       lambda i: bar.update(len(tasks[i].dts)))
    result = StudyResult(scene.name, reference,
                         timing="serial" if workers is None else workers.timing,
                         converged=converged, left_out=skipped)
    for task, runs in zip(tasks, results):
        if isinstance(runs, Failure):
            result.failed[task.label] = runs.error
        else:
            result.runs += runs
    for incident in incidents:
        result.incidents[tasks[incident.task].label] = (incident.error, incident.recovered)
    return result


def _resolutions(scene, resolutions) -> tuple[int, ...]:
    """The swept resolutions, sorted, each an integer in limits.RESOLUTION."""
    if resolutions is None:
        return (scene.resolution,)
    values = tuple(resolutions) if isinstance(resolutions, (list, tuple)) else (resolutions,)
    for f in values:
        if not (isinstance(f, (int, np.integer)) and not isinstance(f, bool)
                and limits.RESOLUTION.low <= f <= limits.RESOLUTION.high):
            raise ValueError(f"resolutions: {f!r} is not an integer {limits.RESOLUTION.text()}")
    if not values:
        raise ValueError("resolutions: give at least one, e.g. (1, 2, 4)")
    return tuple(sorted({int(f) for f in values}))


def _substeps(scene, dt: float) -> int:
    ratio = scene.frame_dt / dt
    if not (dt > 0 and abs(ratio - round(ratio)) < 1e-6 * ratio):
        raise ValueError(f"dts: {dt!r} does not divide the frame step {scene.frame_dt:.6g} s; "
                         "use frame_dt / n for integers n")
    return round(ratio)


def _measure(task: Configuration, sim, substeps: int, predicted: float) -> Run:
    nan = float("nan")
    reference, converged = task.reference, task.converged
    where = (task.scene.resolution, task.scene.cloth.particle_count)
    try:
        positions, energies, wall = _trajectory(sim, reference.times, substeps)
    except SimulationDiverged as err:
        return Run(task.integrator, task.precision, task.iterations, sim.dt, sim.step_count, nan,
                   nan, True, err.step, nan, nan, nan, nan, predicted, *where, solve=task.solve)
    own = positions[:, task.scene.own_particles]
    k, j = reference.predictable, min(converged.predictable, reference.predictable)
    error = np.linalg.norm(own[:k] - reference.positions[:k], axis=2) / reference.size
    integration = np.linalg.norm(own[:j] - converged.positions[:j], axis=2) / reference.size
    energy_error = np.abs(energies - converged.energies) / converged.energy_scale
    observable_error = max(observables.difference(
        observables.observables(task.scene.cloth, positions, reference.size),
        reference.observables), float(energy_error.max()))
    blown = np.flatnonzero(energy_error > ENERGY_BLOWUP)
    diverged_step = int(round(reference.times[blown[0]] / sim.dt)) if len(blown) else -1
    simulated = reference.times[-1]
    discretisation = (distance(converged, reference)[0] if converged is not reference
                      else nan)
    return Run(task.integrator, task.precision, task.iterations, sim.dt, sim.step_count, wall,
               wall / simulated, len(blown) > 0, diverged_step,
               float(error.max()) if k else nan, rms(error) if k else nan,
               float(energy_error.max()), _max_strain(task.scene.cloth, positions), predicted,
               *where, discretisation, float(integration.max()) if j else nan,
               observable_error, solve=task.solve)
