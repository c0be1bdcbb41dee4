"""The advisor: from measuring the speed/accuracy trade to making it.

    advice = advise(scene, tolerance=1e-3)          # a pilot study of the scene (study.py)
    advice.choice                                   # the cheapest run within the tolerance
    advice.write("renders/advise_cloth")            # advise.md, advise.csv

The pilot study sweeps the candidates (integrator x dt x precision x iterations for pbd/xpbd
x solves for the Newton-solved integrators: their loose preset beside their defaults) over the
scene's first `window` seconds against the rk4/f64 reference, at each of `resolutions` (the
scene's bodies refined; the reference then finer than all of them, study.py). A candidate
passes when it did not diverge and its error (`metric`: max or RMS position error over the
cloth size up to the predictability horizon, as the study reports them, plus, when
resolution is swept, the reference's own estimated error: study.StudyResult.reference_error;
or observable_error over the whole run, plus the observables' spread over perturbed
starts: observables.py) is within the tolerance; the choice is the passing one with the
least measured cost (wall seconds per simulated second), costs within TIE (or the timings'
spread) counting as equal, the least error deciding among them (choose). The passing runs
within RETIME_SPAN of the cheapest (at most RETIME_MOST), and each method's cheapest passing
run and its passing run of the largest step within METHOD_SPAN of it, are timed again, here,
`repeats` rounds each timing every one
of them in turn, and compared on the medians: one timing decides nothing on a shared
machine (contenders). Integrators that cannot run the scene (pbd on a
Fabric) are left out, and the advice says so. When none passes, the advice
says so, names the closest and, from the observed order of spatial convergence, the
resolution it estimates would meet the tolerance.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from ..inputs.files import atomic_path
from ..inputs.scene_file import SceneError
from ..saved_state import fingerprint
from .study import (
    DEFAULT_INTEGRATORS,
    DEFAULT_ITERATIONS,
    DEFAULT_SOLVES,
    Run,
    StudyResult,
    configured_integrator,
    integrator_options,
    retime_in_turn,
    run_study,
)

METRICS = ("max_error", "rms_error", "observable_error")
REPEATS = 3          # timings of each contender: the choice rests on costs
RETIME_SPAN = 2.0    # passing runs up to this x the cheapest one's cost are timed again
RETIME_MOST = 6
METHOD_SPAN = 5.0    # and each method's cheapest passing run up to this x (contenders)
TIE = 0.10           # costs within this fraction of the cheapest (or within the timings' spread,
                     # when larger) are equal: then the least error is chosen (choose)
AROUND = 3           # candidates shown either side of the choice


@dataclass(frozen=True)
class Advice:
    """What the advisor found: `choice` (None when no run meets the tolerance), `closest` (the
    run with the least error, for when none does) and the pilot `study`."""

    scene_name: str
    tolerance: float
    metric: str
    window: float
    choice: Run | None
    closest: Run | None
    study: StudyResult

    @property
    def margin(self) -> float:
        """What is added to a run's error before it is compared with the tolerance: the
        reference's own estimated error when resolution is swept (its error against the
        converged cloth, not only against the reference), else 0."""
        return _margin(self.study, self.metric)

    def passes(self, run: Run) -> bool:
        return meets(run, self.metric, self.tolerance - self.margin)

    def ranked(self) -> list[Run]:
        """Every run that did not diverge, cheapest first."""
        return sorted((r for r in self.study.runs if not r.diverged), key=lambda r: r.cost)

    def nearby(self) -> list[Run]:
        """The runs around the choice (or the closest) in cost order."""
        ranked = self.ranked()
        anchor = self.choice or self.closest
        if anchor is None:
            return []
        at = next(k for k, r in enumerate(ranked) if r is anchor)
        return ranked[max(0, at - AROUND):at + AROUND + 1]

    def summary(self) -> str:
        """One sentence: what was chosen and why."""
        passing = sum(self.passes(r) for r in self.study.runs)
        runs = len(self.study.runs)
        what = ("the observables' spread over perturbed starts"
                if self.metric == "observable_error" else "the reference's own estimated error")
        margin = f" (with {what}, {self.margin:.1e})" if self.margin else ""
        if self.choice is None:
            extra = f" + {self.margin:.1e}, {what}" if self.margin else ""
            closest = (f"; the closest is {describe(self.closest)} at {self.metric} "
                       f"{getattr(self.closest, self.metric):.2e}{extra}" if self.closest else "")
            needed = self.study.resolution_for(self.tolerance)
            estimate = (f"; at the observed order of spatial convergence, resolution "
                        f"{math.ceil(needed)} or finer would meet it" if math.isfinite(needed)
                        else "")
            return (f"no candidate meets {self.metric} <= {self.tolerance:g} over the first "
                    f"{self.window:g} s ({runs} runs){closest}{estimate}{self._caveats()}")
        c = self.choice
        return (f"{describe(c)}: {self.metric} {getattr(c, self.metric) + self.margin:.2e}"
                f"{margin} <= {self.tolerance:g} at {c.cost:.3g} s per simulated second, the "
                f"cheapest of {passing} of {runs} runs that meet it over the first "
                f"{self.window:g} s (costs within {TIE:.0%} or their timings' spread count as "
                f"equal: the least error among them){self._caveats()}")

    def _caveats(self) -> str:
        """What the sentence's figures do not cover: pointwise errors cut at the horizon,
        integrators that cannot run the scene."""
        out = ""
        reference = self.study.reference
        if self.metric != "observable_error" and not reference.whole_run:
            why = ("the motion is chaotic" if reference.chaotic else
                   "the reference did not converge"
                   + (f" ({reference.limited})" if reference.limited else ""))
            out += (f"; pointwise errors are measured up to t = {reference.horizon:.3g} s: "
                    f"beyond, {why} (--metric observable_error judges the whole run)")
        for name, why in self.study.left_out.items():
            out += f"; {name} left out: it {why}"
        return out

    def simulation_block(self, frame_dt: float) -> str:
        """A [simulation] table of the choice, ready to paste into the scene file."""
        c = self.choice
        if c is None:
            return ""
        options = integrator_options(c.integrator, c.iterations, c.solve)
        integrator = (f'"{c.integrator}"' if not options else
                      f'{{ name = "{c.integrator}", '
                      + ", ".join(f"{k} = {_toml(v)}" for k, v in options.items()) + " }")
        return ("[simulation]\n"
                f"integrator = {integrator}\n"
                f"substeps = {round(frame_dt / c.dt)}             # dt = {c.dt:.6g} s\n"
                f'precision = "{c.precision}"\n'
                + (f"resolution = {c.resolution}             # {c.particles} particles\n"
                   if self.study.swept or c.resolution != 1 else ""))

    def markdown(self, frame_dt: float) -> str:
        lines = [f"Advice for `{self.scene_name}`: {self.metric} <= {self.tolerance:g} over the "
                 f"first {self.window:g} s.", "", self.summary() + ".", ""]
        block = self.simulation_block(frame_dt)
        if block:
            lines += ["```toml", block.rstrip("\n"), "```", ""]
        lines += ["| resolution | integrator | precision | dt [s] | max error | RMS error | "
                  "cost [s/s] | meets | |", "|---|---|---|---|---|---|---|---|---|"]
        for run in self.nearby():
            mark = "chosen" if run is self.choice else "closest" if run is self.closest else ""
            spread = (f" ± {run.cost_spread:.0%}" if math.isfinite(run.cost_spread) else "")
            lines.append(f"| {run.resolution} | {run.method} | {run.precision} | "
                         f"{run.dt:.3g} | "
                         f"{run.max_error:.2e} | {run.rms_error:.2e} | {run.cost:.3g}{spread} | "
                         f"{'yes' if self.passes(run) else 'no'} | {mark} |")
        size = self.study.reference.size
        lines += ["", f"Errors are fractions of the cloth's size, the diagonal of its rest "
                  f"bounding box ({size:.3g} m, so 1e-3 is {size:.3g} mm). A cost with a "
                  "spread (±) is the median of the rounds that timed it again; the others are "
                  "one timing."]
        if self.study.timing != "serial":
            lines += ["", f"Costs measured with other runs at once ({self.study.timing})."]
        if not self.study.swept:
            lines += ["", "Errors are integration errors on the scene's own mesh (the "
                      "reference is rk4 on it); resolutions (--resolutions 1 2 4) measure "
                      "the mesh's own error too and let the advice refine it."]
        return "\n".join(lines) + "\n"

    def csv_text(self) -> str:
        """Every run of the pilot, in cost order, with whether it meets the tolerance and
        which one was chosen."""
        out = io.StringIO()
        runs = self.ranked() + [r for r in self.study.runs if r.diverged]
        names = list(asdict(runs[0])) + ["meets", "chosen"] if runs else []
        writer = csv.DictWriter(out, fieldnames=names, lineterminator="\n")
        writer.writeheader()
        for run in runs:
            writer.writerow(asdict(run) | {"meets": self.passes(run), "chosen": run is self.choice})
        return out.getvalue()

    def write(self, folder, frame_dt: float) -> list[Path]:
        """advise.md and advise.csv in `folder`, each written atomically."""
        folder = Path(folder)
        written = []
        for name, text in (("advise.md", self.markdown(frame_dt)), ("advise.csv", self.csv_text())):
            with atomic_path(folder / name) as tmp:
                tmp.write_text(text)
            written.append(folder / name)
        return written


def meets(run: Run, metric: str, tolerance: float) -> bool:
    """Whether `run` did not diverge and its `metric` is within `tolerance` (NaN is not)."""
    return not run.diverged and getattr(run, metric) <= tolerance


def describe(run: Run) -> str:
    where = f" at resolution {run.resolution}" if run.resolution != 1 else ""
    return f"{run.method} {run.precision}{where} at dt = {run.dt:.3g} s"


def _margin(study: StudyResult, metric: str = "max_error") -> float:
    """What the reference itself leaves uncertain in `metric`: its estimated error against
    the converged cloth (pointwise metrics, resolution swept), or the observables' spread
    over perturbed starts (the chaos floor)."""
    if metric == "observable_error":
        return study.reference.observable_spread
    estimate = study.reference_error()
    return estimate if math.isfinite(estimate) else 0.0


def tied(a: Run, b: Run) -> bool:
    """Whether b's cost is within the noise of a's (a the cheaper): within TIE, or within
    either's timing spread when larger."""
    spreads = [x for x in (a.cost_spread, b.cost_spread) if math.isfinite(x)]
    return b.cost <= a.cost * (1.0 + max([TIE] + spreads))


def choose(runs, metric: str, tolerance: float) -> tuple[Run | None, Run | None]:
    """(the run chosen among those meeting the tolerance or None, the run of least error or
    None). The rule: the cheapest by median cost, unless other passing runs cost the same
    within the noise (tied): then, of those, the one of least error (the same cost buys the
    most accuracy), so that which of near-equal candidates wins is not decided by the
    machine's noise."""
    passing = [r for r in runs if meets(r, metric, tolerance)]
    finite = [r for r in runs if not r.diverged and math.isfinite(getattr(r, metric))]
    cheapest = min(passing, key=lambda r: r.cost, default=None)
    choice = None if cheapest is None else min(
        (r for r in passing if tied(cheapest, r)), key=lambda r: (getattr(r, metric), r.cost))
    closest = min(finite, key=lambda r: (getattr(r, metric), r.cost), default=None)
    return choice, closest


def advise(scene, tolerance: float, *, metric: str = "max_error", window: float | None = None,
           precisions=("f64", "f32"), integrators=DEFAULT_INTEGRATORS,
           iterations=DEFAULT_ITERATIONS, solves=DEFAULT_SOLVES, dts=None, arch: str = "cpu",
           repeats: int = REPEATS, resolutions=None, executor=None,
           progress: bool = True) -> Advice:
    """The cheapest (resolution, integrator, dt, precision, iterations or solve) whose
    `metric` stays within `tolerance` (a fraction of the cloth size) over the first `window`
    seconds (default: the scene's duration), from a pilot study (run_study: `dts`,
    `iterations`, `solves`, `resolutions`, `executor` as there)."""
    if metric not in METRICS:
        raise ValueError(f"metric must be one of {METRICS}, got {metric!r}")
    if not (isinstance(tolerance, (int, float)) and not isinstance(tolerance, bool)
            and 0 < tolerance < math.inf):
        raise ValueError(f"tolerance must be a number > 0 (a fraction of the cloth size), "
                         f"got {tolerance!r}")
    duration = scene.frames / scene.fps
    if window is not None and not (isinstance(window, (int, float)) and 0 < window <= duration):
        raise ValueError(f"window must be in (0, {duration:g}] s (the scene's duration), "
                         f"got {window!r}")
    pilot = run_study(scene, integrators=integrators, dts=dts, precisions=precisions,
                      iterations=iterations, solves=solves, duration=window, arch=arch,
                      resolutions=resolutions, executor=executor, progress=progress)
    within = tolerance - _margin(pilot, metric)
    passing = [r for r in pilot.runs if meets(r, metric, within)]
    retimed = retime_in_turn(scene, contenders(passing), pilot, repeats, arch)
    pilot.runs = [retimed.get(id(r), r) for r in pilot.runs]
    choice, closest = choose(pilot.runs, metric, within)
    return Advice(scene.name, float(tolerance), metric, float(pilot.reference.times[-1]),
                  choice, closest, pilot)


def contenders(passing) -> list[Run]:
    """The passing runs timed again: each method's cheapest (integrator with its passes or
    solves, precision, resolution) and its run of the largest step, within METHOD_SPAN of the
    cheapest run's cost, then the other runs within RETIME_SPAN (at most RETIME_MOST of
    them), cheapest first. A pilot's one timing can be several times too slow on a shared
    machine (a denim sheet's symplectic Euler once timed at 3.2x its cost): RETIME_SPAN
    alone kept such a method out of the rounds, and its one slow timing decided against it.
    Within a method the largest step takes the fewest steps, yet its one timing can come out
    dearer than a smaller step's (issue 53's 64² sheet: symplectic Euler at 1.18e-5 s timed
    18.2 s/s, at 8.14e-6 s 16.0), which left the method's cheapest run out of the rounds."""
    ranked = sorted(passing, key=lambda r: r.cost)
    if not ranked:
        return []
    cheapest = ranked[0].cost
    best, largest = {}, {}
    for r in ranked:
        key = (r.method, r.precision, r.resolution)
        best.setdefault(key, r)
        if key not in largest or r.dt > largest[key].dt:
            largest[key] = r
    chosen = [r for r in best.values() if r.cost <= METHOD_SPAN * cheapest]
    chosen += [r for key, r in largest.items()
               if r is not best[key] and r.cost <= METHOD_SPAN * cheapest]
    others = [r for r in ranked if r.cost <= RETIME_SPAN * cheapest
              and not any(r is c for c in chosen)]
    return sorted(chosen + others[:RETIME_MOST], key=lambda r: r.cost)


# What decides a scene's motion besides its integrator, step and precision (the advice's key)
MOTION_FIELDS = ("cloth", "fps", "gravity", "drag", "wind", "tearing", "strain_limit",
                 "self_collision", "handles", "colliders")


def resolve(scene, folder, *, arch: str = "cpu", progress: bool = True):
    """(the scene with integrator = "auto" made concrete, at the resolution chosen, a
    sentence saying what was chosen and why). The choice comes from `<name>.advice.json` in `folder` when that was made for
    this scene and request (a hash of both), else from advise() and is cached there.
    SceneError when no candidate meets the tolerance."""
    request = scene.advice
    key = fingerprint(FORMAT, request, *(getattr(scene, name) for name in MOTION_FIELDS))
    path = Path(folder) / f"{scene.name}.advice.json"
    cached = _read_cache(path, key)
    if cached is None:
        advice = advise(scene, request.tolerance, metric=request.metric, window=request.window,
                        precisions=request.precisions,
                        integrators=request.integrators or DEFAULT_INTEGRATORS, arch=arch,
                        resolutions=request.resolutions, progress=progress)
        if advice.choice is None:
            raise SceneError(f"{scene.source}: integrator = \"auto\": {advice.summary()}; accept "
                             "a larger tolerance or other integrators")
        c = advice.choice
        cached = {"key": key, "integrator": c.integrator, "iterations": c.iterations,
                  "solve": c.solve, "substeps": round(scene.frame_dt / c.dt),
                  "precision": c.precision, "resolution": c.resolution, "why": advice.summary()}
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(cached, indent=1))
        note = cached["why"]
    else:
        note = f"{cached['why']} (cached in {path})"
    integrator = configured_integrator(cached["integrator"], cached["iterations"],
                                       cached["solve"])
    resolved = replace(scene.refined(cached["resolution"]), integrator=integrator,
                       substeps=cached["substeps"], precision=cached["precision"], advice=None)
    return resolved, note


FORMAT = 3     # of the cached advice: bump when its meaning changes


def _read_cache(path: Path, key: str) -> dict | None:
    try:
        cached = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return cached if isinstance(cached, dict) and cached.get("key") == key else None


def _toml(value) -> str:
    """A scalar option as the scene file writes it: a string in double quotes, a number as
    Python's repr (which TOML reads)."""
    return f'"{value}"' if isinstance(value, str) else repr(value)
