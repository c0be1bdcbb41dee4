"""The `ti-cloth` command (run, study, info) and the shared entry point of the demo scripts."""

from __future__ import annotations

import argparse
import importlib.util
import math
import os
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

from ..errors import OutputError
from ..inputs import limits
from . import drape

TEST_FRAMES, TEST_SIZE = 4, (160, 96)
OUTPUT_FAILED = 74        # sysexits.h's EX_IOERR: a file could not be written


def _positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text}")
    return value


def _run_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--frames", type=_positive, help="frames to write (default: duration x fps)")
    parser.add_argument("--arch", choices=list(limits.ARCH_NAMES), default="cpu",
                        help="Taichi backend (gpu: the first GPU backend found, else CPU)")
    parser.add_argument("--precision", choices=list(limits.PRECISION_NAMES),
                        help="float precision (default: the scene's, else f32)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--verbose", action="store_true", help="let Taichi print its banner")
    parser.add_argument("--mp4", action="store_true", help="also write an MP4 (needs "
                        "imageio-ffmpeg: pip install \".[video]\" from a clone)")
    parser.add_argument("--export", type=_formats, metavar="FORMATS",
                        help=f"geometry to write with the frames, comma-separated: "
                             f"{','.join(limits.EXPORT_FORMATS)} (default: the scene's [output] formats)")
    parser.add_argument("--resume", action="store_true",
                        help="continue from the state saved in the output folder by an earlier, "
                             "stopped run of the same scene (same frames as a run never stopped)")
    parser.add_argument("--preview", action="store_true",
                        help="run the scene's preview (garment panels cut coarser, xpbd and pbd "
                             "at 1/60 s) into the output folder + _preview")
    parser.add_argument("--checkpoint-every", type=_positive, metavar="K",
                        help="save the state every K frames (default: the scene's, else about "
                             "5 s of work)")


def _fraction(text: str) -> float:
    value = float(text)
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text}")
    return value


_seconds = _fraction


def file_in_the_way(folder) -> Path | None:
    """The file standing where the output `folder` or one of its parents must be a folder,
    or None (the folder exists, or can be made)."""
    if folder is None:
        return None
    for place in (Path(folder), *Path(folder).parents):
        if place.exists():
            return None if place.is_dir() else place
    return None


def video_available() -> bool:
    """Whether imageio-ffmpeg (the [video] extra) is installed; if not, says how to get it."""
    if importlib.util.find_spec("imageio_ffmpeg") is not None:
        return True
    print("error: --mp4 needs imageio-ffmpeg: pip install \".[video]\" from a clone "
          "(pip install 'ti_cloth[video]' otherwise)", file=sys.stderr)
    return False


def refuse_output(folder) -> int | None:
    """OUTPUT_FAILED, said on stderr, when a file stands where `folder` must be (--out)."""
    blocked = file_in_the_way(folder)
    if blocked is None:
        return None
    print(f"error: --out {folder}: {blocked} is a file, not a folder; give a folder",
          file=sys.stderr)
    return OUTPUT_FAILED


def _sweep_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--jobs", type=_positive, metavar="N",
                       help="run the configurations on N local processes (cores / N Taichi "
                            "threads each)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run them on the Dask cluster whose scheduler is at ADDRESS "
                            "(tcp://host:8786; pip install 'ti_cloth[dask]')")


def _formats(text: str) -> tuple[str, ...]:
    formats = tuple(f.strip() for f in text.split(",") if f.strip())
    unknown = [f for f in formats if f not in limits.EXPORT_FORMATS]
    if unknown or not formats:
        raise argparse.ArgumentTypeError(f"must list some of {','.join(limits.EXPORT_FORMATS)}, "
                                         f"got {text!r}")
    return formats


def run(scene_path, *, out=None, frames=None, arch="cpu", precision=None, progress=True,
        test=False, mp4=None, export=None, resume=False,
        checkpoint_every=None, preview=False) -> tuple[int, list[Path]]:
    """Load (the scene's preview with `preview`: app/scene_preview.py), initialise, run and
    report; returns (exit code, frame paths). Exit codes: 0 done,
    1 diverged, 2 a scene the run refuses (the message names the key) or a state it cannot
    resume from, 74 (sysexits' EX_IOERR) a file it could not write (disk full, no permission,
    read-only), 128 + signal when stopped by Ctrl-C (130) or SIGTERM (143)."""
    from ..errors import StateMismatch
    from ..inputs.limits import LONG_RUN_SECONDS
    from ..runtime import backend
    from ..inputs.scene_file import SceneError
    from . import signals
    from .runner import run_scene
    from .scene import load_scene

    if mp4 and not video_available():
        return 2, []
    try:
        with signals.stop_signals_raise():
            scene = load_scene(scene_path, preview=preview,
                               note=lambda message: print(f"note: {message}", file=sys.stderr))
            for change in scene.preview:
                print(f"preview: {change}", file=sys.stderr)
            output = scene.output
            if test:
                frames = min(frames or TEST_FRAMES, TEST_FRAMES)
                output = replace(output, width=TEST_SIZE[0], height=TEST_SIZE[1], supersample=1)
            if mp4 is not None:
                output = replace(output, mp4=mp4)
            if export is not None:
                output = replace(output, export=export)
            if checkpoint_every is not None:
                output = replace(output, checkpoint_every=checkpoint_every)
            if scene.automatic:
                from .advisor import resolve

                scene, why = resolve(scene, out or output.folder, arch=arch, progress=progress)
                print(f"integrator auto: {why}", file=sys.stderr)
            if frames is not None and not scene.automatic:
                steps = frames * scene.resolved_substeps()
                if steps > limits.STEPS.high:
                    raise SceneError(f"--frames {frames:_}: {steps:_} steps, more than the "
                                     f"{limits.STEPS.high:_} a simulation can count "
                                     f"({limits.FRAMES.high:_} frames at most)")
            work = scene.work(frames)
            if work.seconds > 10 * LONG_RUN_SECONDS:      # a rough bound; Pace measures
                print(f"note: '{scene.name}' is a long run: {work.describe()}", file=sys.stderr)
            backend.ensure(arch=arch, precision=precision or scene.precision)
    except (SceneError, FileNotFoundError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2, []
    except OutputError as err:                  # the advice of integrator = "auto"
        print(f"error: {err}", file=sys.stderr)
        return OUTPUT_FAILED, []
    except KeyboardInterrupt as stop:
        print("interrupted before the first frame", file=sys.stderr)
        return signals.exit_code(stop), []
    try:
        result = run_scene(scene, folder=out, frames=frames, progress=progress, output=output,
                           resume=resume, note=lambda message: print(f"note: {message}",
                                                                     file=sys.stderr))
    except (FileNotFoundError, StateMismatch) as err:
        way_out = ("\nto start again from the first frame, run it without --resume"
                   if resume else "")
        print(f"error: {err}{way_out}", file=sys.stderr)
        return 2, []
    folder = result.frames[0].parent if result.frames else (out or scene.output.folder)
    resumed = ("" if result.resumed_from is None
               else f"resumed at frame {result.resumed_from}: ")
    summary = (f"{resumed}{len(result.frames)} frames of '{scene.name}' in "
               f"{result.wall_seconds:.1f} s "
               f"({result.steps} steps, dt = {result.dt:.3g} s) -> "
               f"{folder}/ {' '.join(p.name for p in result.outputs)}"
               + (f" + {len(result.exports)} geometry files" if result.exports else ""))
    if result.interrupted:
        print(f"interrupted: {summary}", file=sys.stderr)
        return 128 + result.stop_signal, result.frames
    if result.unwritten is not None:
        kept = (f"the last checkpoint is {result.checkpoint} (--resume continues from it)"
                if result.checkpoint is not None else "no checkpoint was saved")
        print(f"error: {result.unwritten}\n{summary}\n{len(result.frames)} finished frames "
              f"kept; {kept}", file=sys.stderr)
        return OUTPUT_FAILED, result.frames
    if result.diverged is not None:
        print(f"error: {result.diverged}\n{summary}", file=sys.stderr)
        return 1, result.frames
    print(summary)
    return 0, result.frames


def _workers(jobs: int | None, scheduler: str | None):
    """Where a study's configurations run: here (None), `jobs` local processes, or the Dask
    cluster at `scheduler`."""
    from contextlib import nullcontext

    from . import sweep

    if scheduler is not None:
        return sweep.dask_cluster(scheduler)
    if jobs is not None and jobs > 1:
        return sweep.local_jobs(jobs)
    return nullcontext(None)


def _report_failures(result) -> None:
    for label, (error, recovered) in result.incidents.items():
        print(f"warning: {label}: its worker failed ({error}); the retry "
              f"{'finished' if recovered else 'failed too'}", file=sys.stderr)
    for label, error in result.failed.items():
        print(f"warning: {label} is missing: {error}", file=sys.stderr)


def _sweep(scene_path, jobs, scheduler, compute, write, lost: str):
    """Load a scene, compute(scene, workers) on the workers of --jobs / --scheduler, then
    write(scene, result) with stop signals held. Returns (exit code to stop with or None,
    scene, result, written paths)."""
    from ..inputs.scene_file import SceneError
    from . import signals
    from .scene import load_scene

    try:
        scene = load_scene(scene_path)
    except (SceneError, FileNotFoundError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2, None, None, []
    try:
        with signals.stop_signals_raise(), _workers(jobs, scheduler) as workers:
            result = compute(scene, workers)
        with signals.stop_signals_held():
            written = write(scene, result)
    except OutputError as err:
        print(f"error: {err}", file=sys.stderr)
        return OUTPUT_FAILED, None, None, []
    except (ValueError, RuntimeError, ImportError, ConnectionError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2, None, None, []
    except KeyboardInterrupt as stop:
        print(f"interrupted: {lost}", file=sys.stderr)
        return signals.exit_code(stop), None, None, []
    _report_failures(getattr(result, "study", result))
    return None, scene, result, written


def study(scene_path, *, out=None, integrators=None, dts=None, precisions=("f64", "f32"),
          iterations=None, solves=None, duration=None, arch="cpu", plot=True, progress=True,
          jobs=None, scheduler=None, resolutions=None) -> int:
    """Run the speed/accuracy study of a scene and write study.csv, study.md, study.png."""
    from . import study as study_module

    options = {"integrators": integrators, "dts": dts, "iterations": iterations,
               "solves": solves, "resolutions": resolutions}
    options = {k: v for k, v in options.items() if v is not None}
    start = time.perf_counter()
    code, _, result, written = _sweep(
        scene_path, jobs, scheduler,
        lambda scene, workers: study_module.run_study(
            scene, precisions=tuple(precisions), duration=duration, arch=arch,
            progress=progress, executor=workers, **options),
        lambda scene, result: result.write(out or Path("renders") / f"study_{scene.name}",
                                           plot=plot),
        "the study wrote nothing (its table needs every run)")
    if code is not None:
        return code
    print(result.markdown())
    print(f"{len(result.runs)} runs in {time.perf_counter() - start:.0f} s -> "
          f"{' '.join(str(p) for p in written)}")
    return 0


def advise(scene_path, *, tolerance: float, metric="max_error", window=None, out=None,
           integrators=None, precisions=("f64", "f32"), iterations=None, solves=None, arch="cpu",
           progress=True, jobs=None, scheduler=None, resolutions=None) -> int:
    """Pick the cheapest integrator, step and precision for a tolerance; write advise.md and
    advise.csv; print the candidates and a [simulation] block. Exit code 1 when no candidate
    meets the tolerance."""
    from . import advisor

    options = {"integrators": integrators, "iterations": iterations, "solves": solves,
               "resolutions": resolutions}
    options = {k: v for k, v in options.items() if v is not None}
    code, scene, advice, written = _sweep(
        scene_path, jobs, scheduler,
        lambda scene, workers: advisor.advise(
            scene, tolerance, metric=metric, window=window, precisions=tuple(precisions),
            arch=arch, progress=progress, executor=workers, **options),
        lambda scene, advice: advice.write(out or Path("renders") / f"advise_{scene.name}",
                                           scene.frame_dt),
        "no advice (it needs every pilot run)")
    if code is not None:
        return code
    print(advice.markdown(scene.frame_dt))
    print(f"-> {' '.join(str(p) for p in written)}")
    return 0 if advice.choice is not None else 1


EXTRAS = {"video": "imageio-ffmpeg", "study": "matplotlib", "usd": "usd-core",
          "dask": "distributed"}     # pyproject.toml's optional extras and what each installs


def info() -> int:
    """Print versions, the architecture Taichi starts on, the CPU thread count and which
    optional extras are installed."""
    from importlib.metadata import PackageNotFoundError, version

    import numpy
    import taichi as ti

    from ..runtime import backend

    config = backend.init(arch="cpu")
    print(f"ti_cloth {package_version()}\n"
          f"python   {platform.python_version()} ({platform.platform()})\n"
          f"taichi   {'.'.join(map(str, ti.__version__))}\n"
          f"numpy    {numpy.__version__}\n"
          f"arch     {config.arch} (a GPU with --arch gpu: Taichi falls back to the CPU "
          "without one)\n"
          f"threads  {backend.cpu_threads()} Taichi CPU threads, {backend.cpu_cores()} cores")
    for extra, package in EXTRAS.items():
        try:
            found = version(package)
        except PackageNotFoundError:
            found = f"not installed (pip install \".[{extra}]\" from a clone)"
        print(f"{extra:8} {package} {found}")
    return 0


def view(scene_path, *, out=None, width=960, height=540, arch="cpu", record=False,
         mp4=False, preview=False) -> int:
    """Open a window on the scene (app/view.py), or on its preview (app/scene_preview.py);
    exit code 0 when it closes, 2 for a scene it refuses (the message names the key) or no
    display, 74 for a file it cannot write."""
    from ..inputs.scene_file import SceneError
    from .scene import load_scene
    from ..runtime import backend
    from .view import NoDisplay, require_display
    from .view import view as open_view

    if mp4 and not video_available():
        return 2
    try:
        require_display()
        scene = load_scene(scene_path, preview=preview)
        if scene.automatic:
            from .advisor import resolve

            scene, why = resolve(scene, out or scene.output.folder, arch=arch)
            print(f"integrator auto: {why}", file=sys.stderr)
        for change in scene.preview:
            print(f"preview: {change}", file=sys.stderr)
        backend.ensure(arch=arch, precision=scene.precision)
        open_view(scene, width=width, height=height, folder=out, record=record, mp4=mp4)
    except OutputError as err:                  # a recorded frame, a snapshot, advice
        print(f"error: {err}", file=sys.stderr)
        return OUTPUT_FAILED
    except (SceneError, FileNotFoundError, NoDisplay, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


def quiet_taichi(verbose: bool) -> None:
    """Unless verbose, Taichi prints no banner when it is imported nor its "Starting on arch"
    line (backend.init), the commands' output being theirs alone; Taichi's own switch, so a
    user's ENABLE_TAICHI_HEADER_PRINT is kept unless --verbose asks for the banner."""
    if verbose:
        os.environ["ENABLE_TAICHI_HEADER_PRINT"] = "True"
    else:
        os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "False")


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    quiet_taichi(args.verbose)
    refused = refuse_output(getattr(args, "out", None))
    if refused is not None:
        return refused
    if args.command == "info":
        return info()
    if args.command == "fit":
        return fit(args)
    if args.command == "view":
        return view(args.scene, out=args.out, width=args.width, height=args.height,
                    arch=args.arch, record=args.record, mp4=args.mp4, preview=args.preview)
    if args.command == "study":
        return study(args.scene, out=args.out, integrators=args.integrators, dts=args.dts,
                     precisions=args.precisions, iterations=args.iterations, solves=args.solves,
                     duration=args.duration, arch=args.arch, plot=not args.no_plot,
                     progress=not args.no_progress,
                     jobs=args.jobs, scheduler=args.scheduler, resolutions=args.resolutions)
    if args.command == "advise":
        return advise(args.scene, tolerance=args.tolerance, metric=args.metric, window=args.window,
                      out=args.out, integrators=args.integrators, precisions=args.precisions,
                      iterations=args.iterations, solves=args.solves, arch=args.arch,
                      progress=not args.no_progress, jobs=args.jobs, scheduler=args.scheduler,
                      resolutions=args.resolutions)
    code, _ = run(args.scene, out=args.out, frames=args.frames, arch=args.arch,
                  precision=args.precision, progress=not args.no_progress, export=args.export,
                  mp4=args.mp4 or None, resume=args.resume,
                  checkpoint_every=args.checkpoint_every, preview=args.preview)
    return code


def _solves_argument(parser) -> None:
    parser.add_argument("--solves", nargs="*", metavar="PRESET",
                        help="presets of the solvers to sweep beside each one's defaults "
                             "(default: loose, the Newton-solved integrators' 0.1 mm and a "
                             "tenth of CG's residual, and bdf2, xpbd's second-order step); "
                             "none: --solves alone")


def _resolution_argument(parser) -> None:
    parser.add_argument("--resolutions", nargs="+", type=_resolution, metavar="F",
                        help="also sweep the bodies' resolution: each refined F times (e.g. "
                             "1 2 4); the reference is then twice the finest")


def _resolution(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or not limits.RESOLUTION.low <= value <= limits.RESOLUTION.high:
        raise argparse.ArgumentTypeError(f"a resolution is an integer "
                                         f"{limits.RESOLUTION.text()}, got {text!r}")
    return value


def package_version() -> str:
    """ti_cloth's installed version; run from a source tree that pip never installed (the
    package on PYTHONPATH, a machine without an index), a note saying so instead of an error."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("ti_cloth")
    except PackageNotFoundError:
        return "(not installed: run from a source tree)"


def build_parser() -> argparse.ArgumentParser:
    """The `ti-cloth` command's argument parser (its subcommands run, study, advise, view,
    info, fit); building it imports no Taichi, so --help and --version answer at once."""
    parser = argparse.ArgumentParser(prog="ti-cloth", description="Mass-spring cloth, strings, "
                                     "hair and soft bodies in Taichi, rendered headlessly.")
    parser.add_argument("--version", action="version", version=f"ti-cloth {package_version()}")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--verbose", action="store_true", help="let Taichi print its banner")
    commands = parser.add_subparsers(dest="command", required=True)
    run_parser = commands.add_parser("run", help="simulate a scene file and write its frames")
    run_parser.add_argument("scene", type=Path, help="scene file (TOML)")
    run_parser.add_argument("--out", type=Path, help="output folder (default: the scene's)")
    _run_arguments(run_parser)
    study_parser = commands.add_parser("study", parents=[common],
                                       help="speed/accuracy study: integrator x dt "
                                       "against an rk4/f64 reference -> CSV, table, plot")
    study_parser.add_argument("scene", type=Path, help="scene file (TOML)")
    study_parser.add_argument("--out", type=Path, help="output folder (default renders/study_<name>)")
    study_parser.add_argument("--integrators", nargs="+", metavar="NAME",
                              help="integrators to sweep (default: all)")
    study_parser.add_argument("--dt", nargs="+", type=_seconds, dest="dts", metavar="DT",
                              help="steps [s], each frame_dt / an integer (default: frame_dt / 2^k "
                                   "down to half the smallest stable step, and each explicit "
                                   "integrator at 0.9 of its stable step)")
    study_parser.add_argument("--precisions", nargs="+", choices=list(limits.PRECISION_NAMES),
                              default=["f64", "f32"])
    study_parser.add_argument("--iterations", nargs="+", type=_positive, metavar="N",
                              help="pbd/xpbd passes per step to sweep (default 4 16)")
    _solves_argument(study_parser)
    study_parser.add_argument("--duration", type=_seconds,
                              help="simulated seconds (default: the scene's)")
    study_parser.add_argument("--arch", choices=list(limits.ARCH_NAMES), default="cpu")
    study_parser.add_argument("--no-plot", action="store_true", help="skip study.png (no matplotlib)")
    _resolution_argument(study_parser)
    _sweep_arguments(study_parser)
    advise_parser = commands.add_parser("advise", parents=[common],
                                        help="the cheapest integrator, step and "
                                        "precision whose error meets a tolerance (a pilot study)")
    advise_parser.add_argument("scene", type=Path, help="scene file (TOML)")
    advise_parser.add_argument("--tolerance", type=_fraction, required=True,
                               help="largest error accepted, a fraction of the cloth size")
    advise_parser.add_argument("--metric", choices=("max_error", "rms_error", "observable_error"),
                               default="max_error",
                               help="max (default) or RMS position error over the cloth size, up "
                               "to the predictability horizon; or observable_error, the "
                               "running means of the centre of mass, bounding box and strain "
                               "over the whole run (for cloth that moves chaotically)")
    advise_parser.add_argument("--window", type=_seconds, metavar="S",
                               help="advise on the first S seconds (default: the whole scene)")
    advise_parser.add_argument("--out", type=Path, help="output folder (default renders/advise_<name>)")
    advise_parser.add_argument("--integrators", nargs="+", metavar="NAME",
                               help="candidates (default: all)")
    advise_parser.add_argument("--precisions", nargs="+", choices=list(limits.PRECISION_NAMES),
                               default=["f64", "f32"])
    advise_parser.add_argument("--iterations", nargs="+", type=_positive, metavar="N",
                               help="pbd/xpbd passes per step to try (default 4 16)")
    _solves_argument(advise_parser)
    advise_parser.add_argument("--arch", choices=list(limits.ARCH_NAMES), default="cpu")
    _resolution_argument(advise_parser)
    _sweep_arguments(advise_parser)
    view_parser = commands.add_parser("view", parents=[common],
                                      help="run a scene live in a window: drag the "
                                      "cloth with the left button, orbit with the right")
    view_parser.add_argument("scene", type=Path, help="scene file (TOML)")
    view_parser.add_argument("--out", type=Path, help="folder for saved states and --record "
                             "(default: the scene's)")
    view_parser.add_argument("--width", type=_positive, default=960)
    view_parser.add_argument("--height", type=_positive, default=540)
    view_parser.add_argument("--arch", choices=list(limits.ARCH_NAMES), default="cpu")
    view_parser.add_argument("--record", action="store_true",
                             help="write what the window shows as PNG frames and a GIF")
    view_parser.add_argument("--mp4", action="store_true",
                             help="record an MP4 too (implies --record; needs imageio-ffmpeg)")
    view_parser.add_argument("--preview", action="store_true",
                             help="run the scene's preview: garment panels cut coarser, to "
                                  "about 500 particles, xpbd and pbd stepping at most 1/60 s (a "
                                  "real-time view of the cape and the skirt on two cores)")
    commands.add_parser("info", parents=[common],
                        help="versions, architecture, threads and the extras installed")
    fit_parser = commands.add_parser(
        "fit", parents=[common], help="a [bodies.fabric] table from a swatch's lab numbers "
        "or a scanned Cusick drape",
        description="Prints the [bodies.fabric] table of a swatch's measurements "
                    "(tc.Fabric.from_measurements: each by its closed form), or with a scan "
                    "and --cusick the Fabric whose simulated drape matches the scanned one "
                    "(ti_cloth.app.drape).")
    fit_parser.add_argument("scan", type=Path, nargs="?",
                            help="a Cusick drape scan (OBJ, PLY, ... in metres) or a top-view "
                                 "silhouette image (PNG, JPEG, ...: with --pixel), with --cusick")
    fit_parser.add_argument("--seconds", type=float, default=drape.MOST_SECONDS,
                            help="the longest each simulated drape may take to settle (no "
                                 "point faster than 0.1 mm/s) [s] (default "
                                 f"{drape.MOST_SECONDS:g})")
    fit_parser.add_argument("--pixel", type=float,
                            help="a silhouette image's pixel side [m]")
    fit_parser.add_argument("--cusick", action="store_true",
                            help="fit the scan's drape (bending warp and weft)")
    fit_parser.add_argument("--disc", type=float, default=0.30,
                            help="the specimen's diameter [m] (default 0.30)")
    fit_parser.add_argument("--support", type=float, default=0.18,
                            help="the clamping discs' diameter [m] (default 0.18)")
    fit_parser.add_argument("--rings", type=_positive, default=16,
                            help="rings of the simulated disc (default 16: 9.4 mm edges)")
    fit_parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    fit_parser.add_argument("--weight", type=float, required=True, help="g/m^2")
    bending = fit_parser.add_mutually_exclusive_group()
    bending.add_argument("--bending-length", type=float, nargs="+", metavar="C",
                         help="ASTM D1388 cantilever bending lengths [m]: warp weft [bias]")
    bending.add_argument("--rigidity", type=float, nargs="+", metavar="G",
                         help="flexural rigidities [N m]: warp weft [bias]")
    stretch = fit_parser.add_mutually_exclusive_group()
    stretch.add_argument("--stretch", type=float, nargs="+", metavar="E",
                         help="2-D moduli [N/m]: one, or warp weft")
    stretch.add_argument("--strip-test", type=float, nargs=3,
                         metavar=("TENSION", "WARP_STRAIN", "WEFT_STRAIN"),
                         help="a strip test's tension per width [N/m] and the strains it gave")
    fit_parser.add_argument("--shear", type=float, default=50.0, help="N/m (default 50)")
    fit_parser.add_argument("--poisson", type=float, default=0.0)
    fit_parser.add_argument("--damping", type=float, default=1e-4, help="s (default 1e-4)")
    return parser


def fit(args) -> int:
    """`ti-cloth fit`: print the Fabric of the measurements as a [bodies.fabric] table; exit 2
    naming the measurement when one cannot be."""
    from ..body.fabric import Fabric

    if args.scan is not None or args.cusick:
        return fit_drape(args)
    missing = [name for name, given in (("--bending-length or --rigidity",
                                         args.bending_length or args.rigidity),
                                        ("--stretch or --strip-test",
                                         args.stretch or args.strip_test)) if not given]
    if missing:
        print(f"error: ti-cloth fit needs {' and '.join(missing)} (or a scan with --cusick)",
              file=sys.stderr)
        return 2
    stretch = args.stretch
    if stretch is not None:
        stretch = stretch[0] if len(stretch) == 1 else tuple(stretch)
    try:
        fabric = Fabric.from_measurements(
            weight=args.weight, strip_test=args.strip_test, stretch=stretch, shear=args.shear,
            bending_length=None if args.bending_length is None else tuple(args.bending_length),
            rigidity=None if args.rigidity is None else tuple(args.rigidity),
            poisson=args.poisson, damping=args.damping)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(fabric.table())
    return 0


IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".gif")


def fit_drape(args) -> int:
    """`ti-cloth fit SCAN --cusick`: the Fabric whose drape matches the scan's (app/drape.py),
    its table and the fit's figures as comments; exit 2 naming what is wrong with the input."""
    from tqdm import tqdm

    from ..runtime import backend

    if args.scan is None or not args.cusick:
        print("error: a drape fit needs a scan and --cusick (ti-cloth fit SCAN --cusick "
              "--weight G)", file=sys.stderr)
        return 2
    unused = [flag for flag, value in (("--bending-length", args.bending_length),
                                       ("--rigidity", args.rigidity),
                                       ("--strip-test", args.strip_test)) if value]
    if unused:
        print(f"error: {', '.join(unused)} cannot be given with a drape fit (it fits the "
              "bending; --stretch sets the moduli it keeps)", file=sys.stderr)
        return 2
    stretch = 1e3 if not args.stretch else (args.stretch[0] if len(args.stretch) == 1
                                            else tuple(args.stretch))
    image = args.scan.suffix.lower() in IMAGE_SUFFIXES
    if image and args.pixel is None:
        print(f"error: a silhouette image ({args.scan.name}) needs --pixel, its pixels' side "
              "in metres", file=sys.stderr)
        return 2
    try:
        if image:
            scan = drape.read_silhouette(args.scan, args.pixel, args.disc, args.support)
        else:
            vertices, triangles = drape.read_scan(args.scan, args.disc, args.support)
            scan = drape.measure(vertices, triangles, args.disc, args.support)
        backend.init(arch="cpu", precision="f64")
        with tqdm(total=drape.ITERATIONS + 3, unit="drape", disable=args.no_progress,
                  file=sys.stderr) as bar:
            result = drape.fit_cusick(scan, args.weight, args.disc, args.support,
                                      stretch=stretch, shear=args.shear, rings=args.rings,
                                      seconds=args.seconds, progress=lambda _: bar.update())
    except (ValueError, FileNotFoundError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    fitted = result.fitted
    print(result.fabric.table())
    measures = (f"silhouette anisotropy {scan.anisotropy:.4f} / {fitted.anisotropy:.4f}"
                if image else f"drop {1e3 * scan.drop:.2f} / {1e3 * fitted.drop:.2f} mm, drop "
                f"anisotropy {scan.drop_anisotropy:.4f} / {fitted.drop_anisotropy:.4f}")
    print(f"# Cusick fit of {args.scan.name}, scan / fit: drape coefficient "
          f"{scan.coefficient:.3f} / {fitted.coefficient:.3f}, folds {scan.folds} / "
          f"{fitted.folds}, {measures}")
    fitted_pair = "drape coefficient, anisotropy" if image else "log drop, anisotropy"
    print(f"# residual ({fitted_pair}) {result.residual[0]:.2g}, "
          f"{result.residual[1]:.2g}; bending uncertain by {100 * result.uncertainty[0]:.2g} %; "
          f"the warp along the scan's stiffer direction, "
          f"{math.degrees(result.warp_angle):.1f} deg from its first axis; "
          f"{result.evaluations} drapes simulated")
    return 0


def demo_main(scene_path, argv=None, description: str | None = None) -> list[Path]:
    """Entry point of a demo script: run its scene file with the demo flags; returns the frame
    paths (exits with the run's code when it fails)."""
    scene_path = Path(scene_path)
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--out-dir", type=Path,
                        help=f"output folder (default renders/{scene_path.stem}, with --preview "
                             f"renders/{scene_path.stem}_preview)")
    parser.add_argument("--test", action="store_true",
                        help=f"tiny and fast: {TEST_FRAMES} frames at {TEST_SIZE[0]}x{TEST_SIZE[1]}")
    _run_arguments(parser)
    args = parser.parse_args(argv)
    quiet_taichi(args.verbose)
    out = args.out_dir or Path("renders") / (scene_path.stem + "_preview" * args.preview)
    refused = refuse_output(out)
    if refused is not None:
        raise SystemExit(refused)
    code, frames = run(scene_path, out=out, frames=args.frames, arch=args.arch,
                       precision=args.precision, progress=not args.no_progress, test=args.test,
                       mp4=args.mp4 or None, export=args.export, resume=args.resume,
                       checkpoint_every=args.checkpoint_every, preview=args.preview)
    if code:
        raise SystemExit(code)
    return frames


if __name__ == "__main__":
    raise SystemExit(main())
