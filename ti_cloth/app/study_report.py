"""The study's report: a StudyResult (study.py) as a CSV of its runs, markdown tables (the
Pareto-optimal runs, the resolution axis, each configuration's largest stable step) and a
log-log plot of error against cost (matplotlib, the [study] extra, imported when plotting).
The functions read the result and compute nothing of the study."""

from __future__ import annotations

import csv
import io
import math
from dataclasses import asdict
from pathlib import Path

from ..inputs.files import atomic_path


def csv_text(result) -> str:
    """Every run of `result` (a StudyResult), a CSV row each."""
    out = io.StringIO()
    names = list(asdict(result.runs[0])) if result.runs else []
    writer = csv.DictWriter(out, fieldnames=names, lineterminator="\n")
    writer.writeheader()
    for run in result.runs:
        writer.writerow(asdict(run))
    return out.getvalue()


def markdown(result) -> str:
    """Pareto-optimal runs first (no other run is both cheaper and more accurate), then the
    largest stable step of each configuration."""
    ref = result.reference
    lines = [f"Scene `{result.scene_name}`: error against rk4/f64 at dt = {ref.dt:.3g} s "
             f"(halving changed positions by {ref.change:.1e} of the {ref.size:.3g} m cloth), "
             f"{len(ref.times)} samples over {ref.times[-1]:.3g} s."
             + ("" if result.timing == "serial" else
                f" Costs measured with other runs at once ({result.timing}): compare them "
                "with each other, not with a serial study."), "",
             horizon_sentence(ref), "",
             "| integrator | precision | dt [s] | max error | RMS error | energy drift | "
             "max strain | observables | cost [s/s] | Pareto |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    swept = result.swept
    if not swept:
        lines[0] += (" Integration error only: the reference is this same mesh's; "
                     "resolutions (--resolutions 1 2 4) measure the mesh's own error too.")
    if swept:
        lines[4:4] = resolution_lines(result)
        lines[-2] = ("| resolution | particles | integrator | precision | dt [s] | max error | "
                     "discretisation | integration | RMS error | energy drift | max strain | "
                     "observables | cost [s/s] | Pareto |")
        lines[-1] = "|---" * 14 + "|"
    front = {id(r) for r in result.pareto_front()}
    for run in sorted(result.runs, key=lambda r: (r.resolution, r.label, -r.dt)):
        split = (f"{run.discretisation_error:.2e} | {run.integration_error:.2e} | " if swept
                 else "")
        if run.diverged:
            metrics = (f"diverged at step {run.diverged_step} | {'| | ' if swept else ''}"
                       f"| | | | {run.cost:.3g} |")
        else:
            spread = f" ± {run.cost_spread:.0%}" if math.isfinite(run.cost_spread) else ""
            metrics = (f"{run.max_error:.2e} | {split}{run.rms_error:.2e} | "
                       f"{run.energy_drift:.2e} | {run.max_strain:.3f} | "
                       f"{run.observable_error:.2e} | {run.cost:.3g}{spread} |")
        where = f"{run.resolution} | {run.particles} | " if swept else ""
        lines.append(f"| {where}{run.method} | {run.precision} | {run.dt:.3g} | {metrics} "
                     f"{'yes' if id(run) in front else ''} |")
    for label, error in result.failed.items():
        lines.append(f"| {label} | failed: {error} | | | | | | | | |")
    if result.incidents:
        lines.append("")
    lines += [f"{label}: its worker failed ({error}); "
              + ("the retry finished." if recovered else "the retry failed too.")
              for label, (error, recovered) in result.incidents.items()]
    lines += ["", "| configuration | largest stable dt in the sweep [s] | predicted [s] |", "|---|---|---|"]
    predicted = {r.label: r.predicted_stable_dt for r in result.runs}
    for label, dt in result.largest_stable_dt().items():
        lines.append(f"| {label} | {dt:.3g} | {predicted[label]:.3g} |")
    return "\n".join(lines) + "\n"


def horizon_sentence(ref) -> str:
    """What the pointwise errors cover: the whole run, or up to the horizon T* and why."""
    observables = ("Observables (running means of the centre of mass, bounding box and strain: "
                   "observables.py) are compared over the whole run")
    if ref.whole_run:
        return (f"Pointwise errors cover the whole run (the reference converged at every "
                f"sample). {observables}.")
    why = (f"the motion is chaotic: a start perturbed at the rounding level parts from the "
           f"reference by more than {ref.tolerance:g} of the cloth size" if ref.chaotic else
           f"the reference's halvings still change positions by up to {ref.change:.1e} of the "
           "cloth size there")
    if ref.limited:
        why += f" ({ref.limited})"
    chaos = (f"below {ref.observable_spread:.1e} their differences are the chaos of the motion "
             "(the spread over perturbed starts), not error" if ref.observable_spread > 0 else
             "no perturbed starts were run within the reference's budget, so their chaos is "
             "not measured")
    return (f"Pointwise errors are measured up to t = {ref.horizon:.3g} s "
            f"({ref.predictable} of {len(ref.times)} samples); beyond, {why}. {observables}; "
            f"{chaos}.")


def resolution_lines(result) -> list[str]:
    """The resolution axis of `result`: each resolution's discretisation error, the observed orders,
    the reference's estimated own error."""
    ref = result.reference
    lines = [f"Resolution: the reference is the scene refined {ref.resolution} times "
             f"({ref.particles} particles); errors are at the scene file's own particles.", "",
             "| resolution | particles | discretisation: max error | RMS error | "
             "observables | converged step [s] |", "|---|---|---|---|---|---|"]
    observed = result.observable_discretisation()
    for f, (worst, rms) in result.discretisation().items():
        converged = result.converged[f]
        lines.append(f"| {f} | {converged.particles} | {worst:.2e} | {rms:.2e} | "
                     f"{observed[f]:.2e} | {converged.dt:.3g} |")
    orders = ", ".join(f"{p:.2f} from {a} to {b}" for a, b, p in result.spatial_orders())
    estimate = result.reference_error()
    lines += ["", f"Observed order of spatial convergence (max error): {orders or 'n/a'}."
              + (f" At that order the reference itself is about {estimate:.1e} of the cloth "
                 "size from the converged cloth: add it to an error below for the error "
                 "against the continuum." if math.isfinite(estimate) else ""), ""]
    return lines


def plot(result, path) -> Path:
    """Log-log max error against cost, one line per configuration (colour: integrator;
    dashed: f32; marker: resolution, o ^ v D ... from the coarsest, or squares for the most
    pbd/xpbd iterations, hollow for an integrator's preset solves; the label ends in xN at
    resolution N), the Pareto front outlined;
    when the reference's horizon is short of the run, beside it the observable error over the
    whole run against cost (needs matplotlib: pip install "ti_cloth[study]")."""
    try:
        import matplotlib
    except ImportError as err:
        raise ImportError('the study plot needs matplotlib: pip install "ti_cloth[study]" '
                          "(or pip install matplotlib)") from err
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    markers = dict(zip(sorted({r.resolution for r in result.runs}), "o^vDPX*"))
    ref = result.reference
    panels = [("max_error", "max position error / cloth size"
               + ("" if ref.whole_run else f"\nup to the horizon t = {ref.horizon:.3g} s"))]
    if not ref.whole_run:      # beyond the horizon only observables compare
        panels.append(("observable_error", "observable error over the whole run"))
    width = (9.5 if len(markers) > 1 else 8) + 5 * (len(panels) - 1)
    fig, axes = plt.subplots(1, len(panels), figsize=(width, 5.5), dpi=100, squeeze=False)
    colours = {name: f"C{i}" for i, name in enumerate(dict.fromkeys(r.integrator for r in result.runs))}
    counts = {name: sorted({r.iterations or 0 for r in result.runs if r.integrator == name}) for name in colours}
    for ax, (metric, ylabel) in zip(axes[0], panels):
        for label in dict.fromkeys(r.label for r in result.runs):
            runs = sorted((r for r in result.runs if r.label == label and not r.diverged),
                          key=lambda r: r.cost)
            if runs:
                first = runs[0]
                most = (len(counts[first.integrator]) > 1
                        and first.iterations == counts[first.integrator][-1])
                ax.plot([r.cost for r in runs], [max(getattr(r, metric), 1e-16) for r in runs],
                        label=label, color=colours[first.integrator],
                        ls="--" if first.precision == "f32" else "-",
                        marker="s" if most else markers[first.resolution], ms=4, lw=1,
                        mfc="none" if first.solve is not None else None)
        if metric == "max_error":
            front = sorted(result.pareto_front(), key=lambda r: r.cost)
            if front:
                ax.plot([r.cost for r in front], [max(r.max_error, 1e-16) for r in front], "k-",
                        lw=3, alpha=0.25, label="Pareto front")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("cost: wall seconds per simulated second")
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.3)
    ax = axes[0][0]
    ax.set_title(f"{result.scene_name}: error against cost (diverged runs left out)"
                 + ("" if result.timing == "serial" else f"\ncosts timed with {result.timing}"),
                 fontsize=10 if result.timing != "serial" else None)
    ax = axes[0][-1]
    if len(markers) > 1:          # one entry per colour, marker and line style
        from matplotlib.lines import Line2D
        keys = ([Line2D([], [], color=c, label=name) for name, c in colours.items()]
                + [Line2D([], [], color="grey", ls="", marker=m, label=f"resolution {f}")
                   for f, m in markers.items()]
                + [Line2D([], [], color="grey", ls=ls, label=p)
                   for p, ls in (("f64", "-"), ("f32", "--"))]
                + [Line2D([], [], color="k", lw=3, alpha=0.25, label="Pareto front")])
        ax.legend(handles=keys, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1))
    else:
        ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)
    return path


def write(result, folder, with_plot: bool = True) -> list[Path]:
    """study.csv, study.md and (with_plot) study.png in `folder`, each written atomically."""
    folder = Path(folder)
    written = []
    for name, text in (("study.csv", csv_text(result)), ("study.md", markdown(result))):
        with atomic_path(folder / name) as tmp:
            tmp.write_text(text)
        written.append(folder / name)
    if with_plot:
        written.append(plot(result, folder / "study.png"))
    return written
