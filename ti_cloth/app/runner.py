"""Run a Scene: step it frame by frame, render each frame, write numbered PNGs (and a GIF/MP4).

Frame 0 is the initial state; frame k is the state after k x substeps steps. Every frame is
written atomically as soon as it is rendered, so a run stopped by Ctrl-C, SIGTERM (signals.py)
or a divergence keeps every finished frame; the GIF/MP4 are assembled from whatever frames
exist, with stop signals held until they are written.

Every `checkpoint_every` frames (and at the last) the simulation's state is saved beside the
frames (`<name>.state.npz`, Simulation.save_state, atomically), after that frame's image and
geometry. A run resumed from it (resume=True) loads the state, keeps the frames before it and
the geometry journal's records of them, and writes the rest: the same bytes as a run never
stopped (rendering and export are functions of the state).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import OutputError, SimulationDiverged, StateMismatch
from ..export import Exporter
from ..inputs import limits
from ..contact.colliders.shapes import Plane
from ..render import Camera, FrameSequence, Renderer
from ..render.springs2d import FRONT, SpringView
from ..runtime import backend
from . import signals


@dataclass
class RunResult:
    """What a run wrote and why it stopped."""

    frames: list[Path]
    outputs: list[Path]               # GIF, MP4
    steps: int
    dt: float
    wall_seconds: float
    interrupted: bool = False
    diverged: SimulationDiverged | None = None
    stop_signal: int | None = None   # the signal that interrupted the run (SIGINT, SIGTERM)
    exports: list[Path] = field(default_factory=list)   # geometry files (export.Exporter)
    resumed_from: int | None = None   # the first frame this run wrote, when it was resumed
    unwritten: OutputError | None = None   # a file the run could not write, which stopped it
    checkpoint: Path | None = None   # the last state saved (Simulation.save_state), if any

    @property
    def complete(self) -> bool:
        return not self.interrupted and self.diverged is None and self.unwritten is None


class Watch:
    """What a run says once when its frames go wrong without diverging (issue 40): a frame
    that tears more than LOST of the body's springs (or a Fabric's triangles), naming the
    tearing setting; the particles leaving the camera's view, more than LOST of them off the
    image when most were on it in the first frame, naming the camera."""

    LOST = 0.5

    def __init__(self, scene, sim, camera, width: int, height: int):
        self.scene, self.sim, self.camera, self.size = scene, sim, camera, (width, height)
        self.total = sim.cloth.spring_count + sim.cloth.face_count
        self.intact = self._intact()
        self.seen = self._off_view() <= self.LOST
        self.said = set()

    def _intact(self) -> int:
        return int(self.sim.spring_alive().sum()) + int(self.sim.face_alive().sum())

    def _off_view(self) -> float:
        """The fraction of the drawn particles off the image or behind the camera."""
        if self.camera is None:
            return 0.0
        drawn = ~self.sim.cloth.ghost
        screen, depth = self.camera.project(self.sim.positions()[drawn], *self.size)
        inside = ((depth > self.camera.near) & (screen[:, 0] >= 0) & (screen[:, 1] >= 0)
                  & (screen[:, 0] <= self.size[0]) & (screen[:, 1] <= self.size[1]))
        return 1.0 - float(inside.mean()) if len(inside) else 0.0

    def frame(self, index: int) -> None:
        """Check the frame just stepped to (index >= 1); warn once per kind."""
        if self.scene.tearing is not None and self.total:
            intact = self._intact()
            torn, self.intact = self.intact - intact, intact
            if torn > self.LOST * self.total and "tearing" not in self.said:
                self.said.add("tearing")
                warnings.warn(
                    f"'{self.scene.name}' frame {index}: {torn} of {self.total} springs and "
                    f"triangles tore in one frame (tearing = {self.scene.tearing:g}): the cloth "
                    "is shredding. tearing is the strain a spring tears at (0.3 = 30 % "
                    "stretch); raise it, or leave it out", RuntimeWarning, stacklevel=3)
        if self.seen and "camera" not in self.said and self._off_view() > self.LOST:
            self.said.add("camera")
            warnings.warn(
                f"'{self.scene.name}' frame {index}: most particles have left the camera's "
                "view (the frames show little of the body): set [camera] position and "
                "target, or give none and let it fit the body", RuntimeWarning, stacklevel=3)


def _frame_painter(scene, sim, out):
    """(a function () -> (H, W, 3) uint8 image of the simulation now, per the output settings;
    the camera, None for the 2-D view)."""
    if out.view == "2d":
        x = scene.cloth.particle_position @ np.asarray(FRONT).T
        lo, hi = x.min(axis=0), x.max(axis=0)
        reach = max(float(np.max(hi - lo)), 1e-3)   # a pinned body can swing this far
        view = SpringView((lo - reach, hi + reach), FRONT, res=(out.width, out.height))
        cloth = scene.cloth
        return (lambda: view.render(sim.positions(), cloth.spring_indices, cloth.spring_kind,
                                    sim.pinned(), sim.spring_alive(), cloth.ghost)), None
    camera = scene.camera or Camera.fit(scene.motion_bounds(), aspect=out.width / out.height,
                                        **scene.camera_fit)
    renderer = Renderer(out.width, out.height, camera, supersample=out.supersample)

    shaded = out.ground is not None or any(isinstance(c, Plane) for c in scene.colliders)

    def paint():
        renderer.begin()
        if shaded:
            renderer.cast_shadows(sim)
        if out.ground is not None:
            renderer.draw_plane(point=(0.0, out.ground, 0.0), checker=0.5)
        renderer.draw_colliders(sim)
        renderer.draw_simulation(sim, out.style)
        return renderer.end()
    return paint, camera


def state_path(folder, name: str) -> Path:
    """Where a run of scene `name` into `folder` saves its state."""
    return Path(folder) / f"{name}.state.npz"


def checkpoint_interval(scene, output) -> int:
    """Frames between saved states: the output's checkpoint_every, else about
    limits.CHECKPOINT_SECONDS of estimated work."""
    if output.checkpoint_every is not None:
        return output.checkpoint_every
    return max(1, round(limits.CHECKPOINT_SECONDS / max(scene.work(1).seconds, 1e-9)))


class Pace:
    """How long the rest of a run will take, measured on its own frames: the median of the
    MEASURED frames after the first stepped one (which holds the compile), said once when
    the frames still to come need more than limits.LONG_RUN_SECONDS at that pace."""

    MEASURED = 3

    def __init__(self, name: str, frames: int):
        self.name, self.frames, self.times, self.said = name, frames, [], False

    def frame(self, index: int, seconds: float) -> str | None:
        """The note to give after frame `index` took `seconds` (stepping, drawing, writing),
        or None."""
        self.times.append(seconds)
        if self.said or len(self.times) < self.MEASURED + 1:
            return None
        self.said = True
        each = float(np.median(self.times[1:]))
        left = self.frames - 1 - index
        if each * left <= limits.LONG_RUN_SECONDS:
            return None
        return (f"'{self.name}' is a long run: {left} frames to go at {each:.3g} s a frame "
                f"(measured on the last {len(self.times) - 1}), about "
                f"{limits.describe_duration(each * left)} more")


def run_scene(scene, *, folder=None, frames: int | None = None, progress: bool = True,
              output=None, export=None, resume: bool = False, note=None) -> RunResult:
    """Simulate and render `frames` frames (default: the scene's duration x fps) into `folder`
    (default: the output's folder). output: an app.scene.Output replacing the scene's (size,
    formats, style, checkpoint_every). export: geometry formats (ti_cloth.export.FORMATS)
    written with each frame (default: the output's). A scene with integrator = "auto" is
    resolved first (advisor.resolve: its cached advice, or a pilot study), and run in the
    precision it chose. resume: continue from the state saved in `folder`
    (FileNotFoundError without one, errors.StateMismatch for another scene's). Call
    ti_cloth.init first. Returns a RunResult; Ctrl-C, SIGTERM (in the main thread) or a
    SimulationDiverged end the run early, in any phase, with every finished frame kept and the
    GIF/MP4 and point caches assembled from them; so does a file that cannot be written
    (errors.OutputError: a full disk, a folder without permission), in RunResult.unwritten,
    the last checkpoint left as it was. note: called with a line when the frames measured
    say the run is long (Pace)."""
    from tqdm import tqdm

    if scene.automatic:
        from .advisor import resolve

        arch = backend.config().arch
        scene, _ = resolve(scene, folder or scene.output.folder, arch=arch, progress=progress)
        backend.ensure(arch=arch, precision=scene.precision)
    substeps = scene.resolved_substeps()
    frames = scene.frames if frames is None else frames
    out = scene.output if output is None else output
    folder = Path(folder or out.folder)
    saved = state_path(folder, scene.name)
    every = checkpoint_interval(scene, out)
    start = time.perf_counter()
    sim, sequence, exporter, first = None, None, None, 0
    stop, diverged, unwritten, checkpoint = None, None, None, None
    with signals.stop_signals_raise():
        try:
            sim = scene.build(dt=scene.frame_dt / substeps)
            if resume:
                first = _resume(sim, saved, substeps)
                if first >= frames:      # it had finished: only the GIF/MP4 may be missing
                    return _finished(scene, out, folder, sim, frames, start)
            sequence = FrameSequence(folder, fps=scene.fps, gif=out.gif, mp4=out.mp4,
                                     name=scene.name, gif_width=min(out.gif_width, out.width),
                                     first=first)
            exporter = Exporter(folder, out.export if export is None else export,
                                name=scene.name, cloth=scene.cloth, fps=scene.fps,
                                first_frame=first, colliders=scene.colliders)
            paint, camera = _frame_painter(scene, sim, out)
            watch = Watch(scene, sim, camera, out.width, out.height)
            bar = tqdm(total=frames, initial=min(first, frames), unit="frame",
                       disable=not progress, dynamic_ncols=True)
            pace = Pace(scene.name, frames)
            try:
                for frame in range(first, frames):
                    began = time.perf_counter()
                    if frame:
                        sim.step(substeps)
                        watch.frame(frame)
                    sequence.write(paint())
                    exporter.write(sim)
                    if (frame and frame % every == 0) or frame == frames - 1:
                        sim.save_state(saved)
                        checkpoint = saved
                    elapsed = time.perf_counter() - start
                    bar.set_postfix_str(f"t={sim.time:.3f} s, "
                                        f"{sim.step_count / max(elapsed, 1e-9):,.0f} steps/s")
                    bar.update()
                    said = pace.frame(frame, time.perf_counter() - began)
                    if said and note is not None:
                        bar.clear()
                        note(said)
                        bar.refresh()
            finally:
                bar.close()
        except KeyboardInterrupt as err:
            stop = err
        except SimulationDiverged as err:
            diverged = err
        except OutputError as err:
            unwritten = err
    with signals.stop_signals_held() as held:
        outputs, exports = [], []
        complete = stop is None and diverged is None and unwritten is None and not held
        try:
            outputs = sequence.close() if sequence is not None else []
        except OutputError as err:
            unwritten = unwritten or err
        try:
            exports = exporter.close(keep_journal=not complete) if exporter is not None else []
        except OutputError as err:
            unwritten = unwritten or err
    if stop is None and held:
        stop = signals.Stopped(held[0])
    return RunResult(frames=sequence.paths if sequence is not None else [], outputs=outputs,
                     exports=exports, steps=sim.step_count if sim is not None else 0,
                     dt=sim.dt if sim is not None else scene.frame_dt / substeps,
                     wall_seconds=time.perf_counter() - start, interrupted=stop is not None,
                     diverged=diverged, resumed_from=first if resume else None,
                     stop_signal=None if stop is None else signals.signal_number(stop),
                     unwritten=unwritten, checkpoint=checkpoint or (saved if resume else None))


def _finished(scene, out, folder: Path, sim, frames: int, start: float) -> RunResult:
    """A resumed run that had written every frame: the GIF/MP4 assembled from them again (a
    run stopped by a file it could not write may have lost only those)."""
    sequence = FrameSequence(folder, fps=scene.fps, gif=out.gif, mp4=out.mp4, name=scene.name,
                             gif_width=min(out.gif_width, out.width), first=frames)
    with signals.stop_signals_held():
        outputs = sequence.close()
    return RunResult(frames=sequence.paths, outputs=outputs, steps=sim.step_count, dt=sim.dt,
                     wall_seconds=time.perf_counter() - start, resumed_from=frames)


def _resume(sim, saved: Path, substeps: int) -> int:
    """Load the state saved at `saved` into `sim`; returns the next frame to write."""
    if not saved.is_file():
        raise FileNotFoundError(f"no saved state to resume from: {saved} (a run saves one every "
                                "checkpoint_every frames; run without resuming)")
    sim.load_state(saved)
    if sim.step_count % substeps:
        raise StateMismatch(f"{saved} was saved at step {sim.step_count}, not at the end of a "
                            f"frame of {substeps} steps; run without resuming")
    return sim.step_count // substeps + 1
