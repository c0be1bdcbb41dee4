"""A running simulation seen through a camera and driven by input events: the lecture's "click
one of the particles and pull it around", live (issue 39).

The window (app/view.py) turns its ti.GUI events into `Event`s and shows `Viewer.image()`;
tests send the same events without a window. A left-button press picks the particle whose
image is nearest the cursor (within PICK_PIXELS) and holds it: while the button is down the
particle is pinned (inverse mass 0: the integrator leaves it, its neighbours follow through
their springs or elements, as Verlet's pins in the lecture) and put, before each frame's steps,
where the ray through the cursor meets the plane through its grab point that faces the camera,
with the velocity of that move. Releasing the button gives its mass back (a particle the scene
pins keeps its pin where it was dragged) and it goes on with that velocity. A drag is never
lost to a slow frame: a release that comes before any frame has shown the particle's last
target (a press, moves and release all in one batch of a busy window) runs that frame first,
so a slow machine drops frames, not input. A right-button
drag orbits the camera about its target, the wheel or +/- zooms.

A step that diverges pauses the viewer with the error on screen until "r".

Keys: space pause and resume, "." one frame, "r" back to the rest state, "s" save the state to
`<folder>/<name>.view.npz` (Simulation.load_state of the same scene reads it; a disk that
refuses it is said on screen and the session goes on), "w" wireframe, "q" or Escape quit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import OutputError, SimulationDiverged
from .camera import Camera

PICK_PIXELS = 30.0      # a press this far from every particle's image picks none
HELD_RADIUS = 6.0       # [pixels] of the disc marking the held particle
HELD_COLOUR = (0.95, 0.45, 0.05)
KEYS_HELP = ("drag: pull a particle   right drag: orbit   wheel, + -: zoom   space: pause   "
             ".: one frame   r: reset   s: save   w: wireframe   q: quit")
ORBIT = math.pi         # radians of turn for a drag across the whole window
ZOOM = 1.15             # distance factor per wheel notch or +/- press
ZOOM_RANGE = (1e-3, 1e3)   # the camera's distance to its target, over its first distance
ZOOM_NOTCHES = 100         # wheel notches one event counts at most (1.15^100 = 1.2e6)
CATCH_UP = 3        # frames of simulated time one drawn frame advances at most (frames_due)
CATCH_UP_BELOW = 0.5   # nor more than one where a frame's steps take over this x frame_dt
MOST_BEHIND = 1.0   # s: a lag behind the wall clock beyond this is given up (frames_due)
TIP_AFTER = 2.0     # s of running below TIP_BELOW x real time before the tip is shown
TIP_BELOW = 0.9
KINDS = ("press", "release", "motion", "key", "wheel")


@dataclass(frozen=True)
class Event:
    """One input event: kind "press" / "release" (button "left" or "right"), "motion", "key"
    (key: a character, "escape", ...) or "wheel" (delta: notches, positive away from the
    user); x, y: the cursor [pixels, bottom-left origin]."""

    kind: str
    x: float = 0.0
    y: float = 0.0
    button: str = ""
    key: str = ""
    delta: float = 0.0

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"Event.kind must be one of {list(KINDS)}, got {self.kind!r}")


class Viewer:
    """sim seen by `camera` in width x height pixels through `renderer` (a Renderer of that
    size); `frame_dt` [s] of simulated time and `substeps` steps a frame; `folder` where "s"
    saves `<name>.view.npz`; `note`: a line the window always shows (a scene's preview);
    `tip`: a line it shows once the run has kept below TIP_BELOW x real time for TIP_AFTER
    seconds of running (what would run faster)."""

    def __init__(self, sim, renderer, camera: Camera, *, name: str, frame_dt: float,
                 substeps: int, folder, paint, note: str = "", tip: str = ""):
        self.sim, self.renderer, self.camera = sim, renderer, camera
        self.first_distance = max(float(np.linalg.norm(np.subtract(camera.position,
                                                                    camera.target))), 1e-6)
        self.name, self.frame_dt, self.substeps = name, frame_dt, substeps
        self.folder = Path(folder)
        self.paint = paint                     # paint(renderer, sim, wireframe): the scene
        self.note, self.tip = note, tip
        self.width, self.height = renderer.width, renderer.height
        self.paused = self.wireframe = self.quit = False
        self.held = None                       # (particle, depth, scene pinned it, target)
        self.unshown = False                   # the held particle's target not yet stepped to
        self.velocity = np.zeros(3)
        self.orbiting = None                   # the cursor where a right drag is now
        self.saved = self.unsaved = None       # the last state saved; why the last "s" failed
        self.diverged = None                   # the SimulationDiverged that paused it
        self.rest_pinned = sim.pinned()
        self.running = 0.0          # wall seconds spent running (not paused): tick()
        self.simulated = 0.0        # simulated seconds advanced while running
        self.steps_run = 0          # steps taken while running
        self._ticked = None
        self._clock = None          # wall time [s] the simulated time advanced so far is due

    # -- events -------------------------------------------------------------------------------

    def handle(self, event: Event) -> None:
        """Act on one event (module doc). An event the session cannot act on (a save the disk
        refuses, a state that cannot be saved) never ends the session: the window says why
        (status) and goes on."""
        try:
            self._handle(event)
        except Exception as err:   # noqa: BLE001 (the window must outlive any event)
            self.unsaved = err

    def _handle(self, event: Event) -> None:
        if event.kind == "press" and event.button == "left":
            self.grab(event.x, event.y)
        elif event.kind == "release" and event.button == "left":
            if self.held is not None and self.unshown:
                self.advance()                 # the drag's last target shows (module doc)
            self.let_go()
        elif event.kind == "press" and event.button == "right":
            self.orbiting = (event.x, event.y)
        elif event.kind == "release" and event.button == "right":
            self.orbiting = None
        elif event.kind == "motion":
            if self.orbiting is not None:
                self.orbit(event.x - self.orbiting[0], event.y - self.orbiting[1])
                self.orbiting = (event.x, event.y)
            if self.held is not None:
                particle, depth, pinned, _ = self.held
                self.held = (particle, depth, pinned, self.unproject(event.x, event.y, depth))
                self.unshown = True
        elif event.kind == "wheel":
            notches = max(-ZOOM_NOTCHES, min(ZOOM_NOTCHES, float(event.delta)))
            self.zoom(ZOOM ** -notches)
        elif event.kind == "key":
            self.key(event.key)

    def key(self, key: str) -> None:
        if key == " ":
            self.paused = not self.paused
        elif key == ".":
            self.advance(force=True)
        elif key == "r":
            self.reset()
        elif key == "s":
            self.save()
        elif key == "w":
            self.wireframe = not self.wireframe
        elif key in ("+", "="):
            self.zoom(1 / ZOOM)
        elif key == "-":
            self.zoom(ZOOM)
        elif key in ("q", "escape"):
            self.quit = True

    # -- picking and dragging -----------------------------------------------------------------

    def pick(self, x: float, y: float) -> int | None:
        """The particle whose image is nearest (x, y) [pixels], in front of the camera and
        within PICK_PIXELS of it, else None (ghost particles are never picked)."""
        screen, depth = self.camera.project(self.sim.positions(), self.width, self.height)
        distance = np.hypot(screen[:, 0] - x, screen[:, 1] - y)
        distance[(depth <= self.camera.near) | self.sim.cloth.ghost] = np.inf
        nearest = int(np.argmin(distance))
        return nearest if distance[nearest] <= PICK_PIXELS else None

    def unproject(self, x: float, y: float, depth: float) -> np.ndarray:
        """The point [m] at `depth` along the view direction whose image is (x, y)."""
        right, up, forward = self.camera.basis()
        scale = self.camera.scale(self.height)
        across = (x - self.width / 2) / scale, (y - self.height / 2) / scale
        if not self.camera.orthographic:
            across = across[0] * depth, across[1] * depth
        return (np.asarray(self.camera.position) + depth * forward + across[0] * right
                + across[1] * up)

    def grab(self, x: float, y: float) -> int | None:
        """Hold the particle picked at (x, y), pinned where it is; returns it (or None)."""
        particle = self.pick(x, y)
        if particle is None:
            return None
        position = self.sim.positions()[particle]
        _, depth = self.camera.project(position, self.width, self.height)
        pinned = self.sim.pinned()
        self.held = (particle, float(depth[0]), bool(pinned[particle]), position)
        self.unshown = True
        pinned[particle] = True
        self.sim.model.set_pinned(pinned)
        self.velocity = np.zeros(3)
        return particle

    def let_go(self) -> None:
        """Release the held particle with the velocity of its last move (a particle the scene
        pins stays pinned where it is)."""
        if self.held is None:
            return
        particle, _, pinned_by_scene, _ = self.held
        self.held = None
        if not pinned_by_scene:
            pinned = self.sim.pinned()
            pinned[particle] = False
            self.sim.model.set_pinned(pinned)
        velocities = self.sim.velocities()
        velocities[particle] = 0.0 if pinned_by_scene else self.velocity
        self.sim.set_velocities(velocities)

    def _hold(self) -> None:
        """Put the held particle at its target, at rest there for the frame (a pinned
        particle still moves with its velocity), remembering the velocity of getting there
        over one frame for its release."""
        particle, _, _, target = self.held
        positions = self.sim.positions()
        self.velocity = (target - positions[particle]) / self.frame_dt
        positions[particle] = target
        velocities = self.sim.velocities()
        velocities[particle] = 0.0
        self.sim.set_positions(positions)
        self.sim.set_velocities(velocities)

    # -- camera -------------------------------------------------------------------------------

    def orbit(self, dx: float, dy: float) -> None:
        """Turn the camera about its target: dx pixels about the world's up axis (y), dy
        pixels about the camera's right axis, stopping short of looking straight down/up."""
        target = np.asarray(self.camera.target)
        offset = np.asarray(self.camera.position) - target
        yaw, pitch = -ORBIT * dx / self.width, -ORBIT * dy / self.height
        c, s = math.cos(yaw), math.sin(yaw)
        offset = np.array([c * offset[0] + s * offset[2], offset[1],
                           -s * offset[0] + c * offset[2]])
        radius = np.linalg.norm(offset)
        elevation = math.asin(np.clip(offset[1] / radius, -1, 1))
        elevation = float(np.clip(elevation + pitch, -1.5, 1.5))
        flat = np.hypot(offset[0], offset[2])
        heading = offset[[0, 2]] / flat if flat > 0 else np.array([0.0, 1.0])
        offset = radius * np.array([math.cos(elevation) * heading[0], math.sin(elevation),
                                    math.cos(elevation) * heading[1]])
        self.camera = replace(self.camera, position=tuple(target + offset), up=(0.0, 1.0, 0.0))

    def zoom(self, factor: float) -> None:
        """Move the camera towards (factor < 1) or away from its target (an orthographic one
        shows factor x the height), its distance kept within ZOOM_RANGE of the first one (a
        million wheel notches at once stop at the range's end)."""
        target = np.asarray(self.camera.target)
        away = np.asarray(self.camera.position) - target
        distance = float(np.linalg.norm(away))
        low, high = (ZOOM_RANGE[0] * self.first_distance, ZOOM_RANGE[1] * self.first_distance)
        factor = min(max(factor, low / distance), high / distance)
        self.camera = replace(self.camera, position=tuple(target + factor * away),
                              height=self.camera.height * factor)

    # -- time ---------------------------------------------------------------------------------

    def advance(self, force: bool = False) -> None:
        """One frame of simulated time (unless paused, or `force`): the held particle put at
        its target, then the frame's steps. A simulation that diverges (pulled too hard for
        its integrator and step) pauses, keeping the error in `diverged` until "r"."""
        if (self.paused and not force) or self.diverged is not None:
            return
        if self.held is not None:
            self._hold()
            self.unshown = False
        try:
            self.sim.step(self.substeps)
        except SimulationDiverged as err:
            self.diverged, self.paused, self.held = err, True, None
            return
        if not self.paused:
            self.simulated += self.frame_dt
            self.steps_run += self.substeps

    def frames_due(self, now: float, most: int = CATCH_UP, step_cost: float = 0.0) -> int:
        """How many frames to advance before the next drawing, at wall time `now` [s] (a
        monotonic clock): those whose time on the wall clock has come, at least one and at
        most `most` (1 where every frame is drawn: a recording). A slow frame (a burst of
        contacts) is made up by the next ones: a drawn frame then advances two or three
        frames of simulated time (frames drawn are dropped, not simulated time nor input),
        so a scene whose mean frame fits frame_dt keeps real time over the run. Only one
        where the last frame's steps took `step_cost` [s] over CATCH_UP_BELOW x frame_dt:
        stepping such frames twice a drawing would not catch up, only answer a drag later.
        A lag past MOST_BEHIND (a machine that cannot keep up) is given up rather than made
        up in a burst later; paused or stopped, the clock starts again when the run does.
        `wait(now)` says how long to wait before the next."""
        if self._clock is None or self.paused or self.diverged is not None:
            self._clock = now
        lag = now - self._clock
        if lag > MOST_BEHIND:
            self._clock, lag = now, 0.0
        if step_cost > CATCH_UP_BELOW * self.frame_dt:
            most = 1
        due = min(most, 1 + int(max(lag, 0.0) / self.frame_dt))
        self._clock += due * self.frame_dt
        return due

    def started(self, now: float) -> None:
        """The run's clocks start at wall time `now` [s], after its first frame is shown: the
        time that frame took (the scene's kernels compiled, seconds for a garment) counts
        neither in the real-time ratio nor as a lag to make up."""
        self.running = self.simulated = 0.0
        self.steps_run = 0
        self._ticked = self._clock = now

    def wait(self, now: float) -> float:
        """Seconds from `now` until the frames advanced are due on the wall clock (0 when
        late): how long the window waits before the next frame (real time, not faster)."""
        return max(0.0, self._clock - now) if self._clock is not None else 0.0

    def tick(self, now: float) -> None:
        """Count the wall time since the last tick (`now` [s], a monotonic clock) as running
        unless paused or stopped by a divergence: the real-time ratio of status() is frozen
        while paused."""
        if self._ticked is not None and not self.paused and self.diverged is None:
            self.running += now - self._ticked
        self._ticked = now

    def status(self) -> list[str]:
        """The lines the window shows: time, real-time ratio and steps per second of the
        running time, "paused"; the keys; the note, and the tip where the run is slow, if
        any; the last save ("saved <path>"), a refused one, or the divergence that stopped
        the run."""
        rate = (f"{self.simulated / self.running:.2f} x real time   "
                f"{self.steps_run / self.running:,.0f} steps/s") if self.running > 0 else ""
        lines = [f"t = {self.sim.time:.3f} s   {rate}" + ("   paused" if self.paused else ""),
                 KEYS_HELP] + ([self.note] if self.note else [])
        if (self.tip and self.running >= TIP_AFTER
                and self.simulated < TIP_BELOW * self.running):
            lines.append(self.tip)
        if self.diverged is not None:
            lines.append(f"{self.diverged}"[:110] + ": press r to start again")
        elif self.unsaved is not None:
            lines.append(f"{self.unsaved}"[:130])
        elif self.saved is not None:
            lines.append(f"saved {self.saved}")
        return lines

    def reset(self) -> None:
        """Back to the rest state at time 0, nothing held."""
        self.held = self.diverged = None
        self.paused = False
        self.sim.model.set_pinned(self.rest_pinned)
        self.sim.restart()

    def save(self) -> Path | None:
        """The state now, in `<folder>/<name>.view.npz` (Simulation.save_state); a state the
        disk refuses (errors.OutputError: full, not writable) is kept in `unsaved` for the
        window to say, and the session goes on."""
        try:
            self.saved = self.sim.save_state(self.folder / f"{self.name}.view.npz")
            self.unsaved = None
        except (OutputError, OSError, ValueError) as err:   # disk, folder, a diverged state
            self.unsaved = err
        return self.saved

    def image(self) -> np.ndarray:
        """What the camera sees now, (height, width, 3) uint8, the held particle marked by a
        disc of HELD_COLOUR."""
        self._draw()
        return self.renderer.end()

    def window_image(self) -> np.ndarray:
        """image() as a window takes it: (width, height, 3), origin bottom-left, the
        renderer's buffer (Renderer.end_window)."""
        self._draw()
        return self.renderer.end_window()

    def _draw(self) -> None:
        self.renderer.begin(self.camera)
        self.paint(self.renderer, self.sim, self.wireframe)
        if self.held is not None:
            self.renderer.draw_points(self.sim.positions()[[self.held[0]]], radius=HELD_RADIUS,
                                      colour=HELD_COLOUR)

