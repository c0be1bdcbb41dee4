"""`ti-cloth view SCENE.toml` and `ti_cloth.view(scene_or_simulation)`: a scene running live in
a window (ti.GUI: X11, no OpenGL or Vulkan), drawn by ti_cloth's own renderer, with the mouse
and keys of render/viewer.py. The window shows simulated time, the real-time ratio and steps/s;
`record` writes what it shows as PNG frames (and a GIF, and with `mp4` an MP4, when it
closes) into the folder.
"""

from __future__ import annotations

import os
import socket
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..inputs.validation import integer, require
from ..render import Camera, FrameSequence, Renderer, SurfaceStyle
from ..render.viewer import CATCH_UP, Event, Viewer

BUTTONS = {"LMB": "left", "RMB": "right"}
KEYS = {"Escape": "escape"}
WIRE = 1.0           # wireframe width [pixels] ("w")


class NoDisplay(RuntimeError):
    """No X11 display to open a window on (DISPLAY unset)."""


def require_display() -> None:
    """NoDisplay, naming DISPLAY, when there is no X11 display to open a window on: where X11
    is the window system (Linux and the BSDs; ti.GUI opens native windows on Windows and
    macOS), DISPLAY unset, or naming a server that does not answer."""
    if sys.platform in ("win32", "darwin"):
        return
    display = os.environ.get("DISPLAY")
    if not display:
        raise NoDisplay("no display to open a window on: DISPLAY is not set (run under X11, "
                        "or headless with Xvfb: xvfb-run ti-cloth view scene.toml)")
    if not _x_server_answers(display):
        raise NoDisplay(f"DISPLAY={display} names an X server that does not answer (start it, "
                        "or run headless with Xvfb: xvfb-run ti-cloth view scene.toml)")


def _x_server_answers(display: str) -> bool:
    """Whether the X server of `display` ("[host]:number[.screen]") takes a connection: its
    socket /tmp/.X11-unix/X<number> (or the abstract one of that name) for a local one, TCP
    port 6000 + number for a remote one (a display this cannot parse is left to the window
    to try)."""
    host, _, rest = display.rpartition(":")
    try:
        number = int(rest.split(".")[0])
    except ValueError:
        return True
    if host in ("", "unix", "localhost") and os.path.exists(f"/tmp/.X11-unix/X{number}"):
        return True
    if host in ("", "unix"):           # Linux servers also listen on an abstract socket
        for address in (f"/tmp/.X11-unix/X{number}", f"\0/tmp/.X11-unix/X{number}"):
            try:
                with socket.socket(socket.AF_UNIX) as local:
                    local.settimeout(1.0)
                    local.connect(address)
                return True
            except OSError:
                continue
        return False
    try:
        with socket.create_connection((host, 6000 + number), timeout=1.0):
            return True
    except OSError:
        return False


def viewer_for(subject, *, width: int = 960, height: int = 540, folder=None) -> Viewer:
    """A Viewer of a Scene (app.scene.Scene: its simulation, camera, frame rate and ground) or
    of a Simulation (the camera fitted to its cloth, 60 frames a second of dt steps)."""
    from .scene import Scene

    integer("width", width, 16, 4096)
    integer("height", height, 16, 4096)
    note = tip = ""
    if isinstance(subject, Scene):
        substeps = subject.resolved_substeps()
        sim = subject.build(dt=subject.frame_dt / substeps)
        name, frame_dt = subject.name, subject.frame_dt
        if subject.preview:
            note = "preview: " + "; ".join(subject.preview)
        else:
            tip = preview_tip(subject.source)
        camera = subject.camera or Camera.fit(subject.motion_bounds(), aspect=width / height,
                                              **subject.camera_fit)
        ground, style = subject.output.ground, subject.output.style
        folder = Path(folder or subject.output.folder)
    else:
        from ..simulation import Simulation

        require(isinstance(subject, Simulation), "scene_or_simulation", subject,
                "a Scene (load_scene) or a Simulation")
        sim, name = subject, "simulation"
        substeps = max(1, round(1 / 60 / sim.dt))
        frame_dt = substeps * sim.dt
        camera = Camera.fit(sim.cloth, aspect=width / height)
        ground, style = None, None
        folder = Path(folder or Path("renders") / name)
    style = style or SurfaceStyle()

    def paint(renderer, sim, wireframe):        # no shadows: the live view keeps its frame rate
        if ground is not None:
            renderer.draw_plane(point=(0.0, ground, 0.0), checker=0.5)
        renderer.draw_colliders(sim)
        renderer.draw_simulation(sim, replace(style, wireframe=WIRE) if wireframe else style)

    return Viewer(sim, Renderer(width, height, camera, supersample=1), camera, name=name,
                  frame_dt=frame_dt, substeps=substeps, folder=folder, paint=paint, note=note,
                  tip=tip)


def preview_tip(source) -> str:
    """What the window suggests to a scene slower than real time: its preview, where the
    preview would change something ("" where not, or where its file cannot be read again)."""
    from ..inputs.scene_file import SceneError, load_toml
    from .scene_preview import previewed

    try:
        changes = previewed(load_toml(source))[1]
    except (OSError, SceneError):
        return ""
    return "tip: --preview: " + "; ".join(changes) if changes else ""


def events_of(gui) -> list[Event]:
    """The window's pending events as Events (cursor in pixels, bottom-left origin)."""
    import taichi as ti

    found = []
    width, height = gui.res
    for e in gui.get_events():
        x, y = e.pos[0] * width, e.pos[1] * height
        if e.key in BUTTONS and e.type in (ti.GUI.PRESS, ti.GUI.RELEASE):
            found.append(Event("press" if e.type == ti.GUI.PRESS else "release", x, y,
                               button=BUTTONS[e.key]))
        elif e.type == ti.GUI.MOTION and e.key == ti.GUI.WHEEL:
            found.append(Event("wheel", x, y, delta=float(np.sign(e.delta[1]))))
        elif e.type == ti.GUI.MOTION:
            found.append(Event("motion", x, y))
        elif e.type == ti.GUI.PRESS:
            found.append(Event("key", x, y, key=KEYS.get(e.key, e.key)))
    return found


def view(subject, *, width: int = 960, height: int = 540, folder=None,
         record: bool = False, mp4: bool = False) -> Viewer:
    """Open a window on `subject` (a Scene or a Simulation) and run it until "q", Escape or
    the window is closed, its simulated time on the wall clock (real time: a slow frame made
    up by the next ones, Viewer.frames_due), or as fast as it can; returns the Viewer.
    NoDisplay without an X11 display."""
    import taichi as ti

    require_display()
    viewer = viewer_for(subject, width=width, height=height, folder=folder)
    gui = ti.GUI(f"ti_cloth: {viewer.name}", res=(width, height), fast_gui=False)
    frames = (FrameSequence(viewer.folder, fps=1 / viewer.frame_dt, name=viewer.name, mp4=mp4)
              if record or mp4 else None)
    first, step_cost = True, 0.0
    try:
        while gui.running and not viewer.quit:
            for event in events_of(gui):
                viewer.handle(event)
            now = time.perf_counter()
            viewer.tick(now)
            # a slow frame made up by the next; a recording draws every frame
            due = viewer.frames_due(now, most=1 if frames is not None else CATCH_UP,
                                    step_cost=step_cost)
            for _ in range(due):
                viewer.advance()
            step_cost = (time.perf_counter() - now) / due
            if frames is not None:
                image = viewer.image()
                frames.write(image)
                gui.set_image(np.ascontiguousarray(image[::-1].transpose(1, 0, 2)))
            else:
                gui.set_image(viewer.window_image())
            for row, line in enumerate(viewer.status()):
                alert = row >= 2 and not line.startswith(("saved", "preview", "tip"))
                gui.text(line, (0.01, 0.98 - 0.04 * row), font_size=14 if row else 16,
                         color=0xA01010 if alert else 0x202020)
            gui.show()
            if first:                   # its build and compile are not running time
                viewer.started(time.perf_counter())
                first = False
            time.sleep(viewer.wait(time.perf_counter()))
    finally:
        if frames is not None:
            frames.close()
        gui.close()
    return viewer
