"""Milliseconds per rendered frame (1280 x 720 by default) of an N x N hanging cloth over a ground
plane, with and without supersampling, next to the simulation's own time per frame measured in
the same run: symplectic Euler, f32, at half its predicted stable step, 30 frames per second.

    python benchmarks/render_ms_per_frame.py [--sizes 32 128 512] [--arch cpu] [--frames 7]
    python benchmarks/render_ms_per_frame.py --sizes --scenes demos/cape.toml --width 960 \
        --height 540

Render time covers everything a demo pays per frame: reading positions back, the vertex and
raster kernels, the resolve and the layout conversion to a numpy image (not the PNG write);
"window ms" the same frame ended as the live viewer's window takes it (Renderer.end_window,
no layout conversion). The camera stands still, so the ground of every frame after the first
is the last frame's, copied ("turning": the camera moved a little every frame, the ground
ray-cast anew).

`--scenes`: each scene file as `ti-cloth view` runs it without its window (app.view.viewer_for,
960 x 540 by default there too, no supersampling): a frame's steps and its drawing, the
camera still and turning, the real-time ratio and frames per second they allow. `--preview`
times each scene's preview after it (`ti-cloth view --preview`: app/scene_preview.py);
`--frames 0` every frame of the scene after the first 5, where the ratio over the whole run
(its mean frame) and the frames over their budget (a frame's simulated time) show the dear
stretches a median hides; "window" is the ratio the window holds over them (its loop replayed
with the measured costs: a slow frame made up by the next ones, never ahead of real time).

    python benchmarks/render_ms_per_frame.py --sizes --scenes demos/cape.toml \
        demos/skirt_walk.toml --preview --frames 0 --width 960 --height 540
"""

import argparse
import statistics
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import ti_cloth as tc
from ti_cloth.app.scene import load_scene
from ti_cloth.app.view import viewer_for
from ti_cloth.inputs import limits
from ti_cloth.render import Camera, Renderer, SurfaceStyle

FPS = 30.0


def hanging_cloth(n):
    mesh = tc.grid_mesh(n, n, size=(1.0, 1.0), plane="xz")
    material = tc.Material(density=0.15, stretch=tc.SpringParams(800.0, 0.4),
                           shear=tc.SpringParams(80.0, 0.04), bend=tc.SpringParams(1.0, 0.001))
    return tc.Cloth(mesh, material, pinned=[0, n - 1])


def sim_ms_per_step(sim, repeats):
    """Median wall time of one step [ms] (batches of at most 200 steps) and steps per frame."""
    substeps = int(np.ceil(1.0 / FPS / sim.dt))
    batch = min(substeps, 200)
    sim.step(2)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        sim.step(batch)
        sim.positions()                       # wait for the device
        times.append((time.perf_counter() - start) / batch)
    return 1e3 * statistics.median(times), substeps


def turned(camera, k):
    """`camera` turned k * 0.2 degrees about the vertical through its target."""
    angle = np.radians(0.2 * k)
    c, s = np.cos(angle), np.sin(angle)
    offset = np.subtract(camera.position, camera.target)
    offset = (c * offset[0] + s * offset[2], offset[1], -s * offset[0] + c * offset[2])
    return replace(camera, position=tuple(np.add(camera.target, offset)))


def render_ms_per_frame(renderer, sim, frames, window=False, turning=False):
    """Median ms of a frame ending as an image (Renderer.end: (H, W, 3), top row first) or,
    with `window`, as a window takes it (Renderer.end_window: the live viewer's); `turning`:
    the camera turned a little every frame."""
    style = SurfaceStyle(checker=0.1)
    times = []
    camera = renderer.camera
    for k in range(frames + 2):               # two warm-up frames compile the kernels
        start = time.perf_counter()
        renderer.begin(turned(camera, k) if turning else camera)
        renderer.draw_plane(point=(0.0, -1.1, 0.0))
        renderer.draw_simulation(sim, style)
        renderer.end_window() if window else renderer.end()
        if k >= 2:
            times.append(time.perf_counter() - start)
    renderer.camera = camera
    return 1e3 * statistics.median(times)


def viewer_ms_per_frame(path, frames, width, height, preview=False):
    """A scene's frame as the live viewer runs it (or its preview's): (ms of its steps: the
    median and the 90th percentile, ms of its drawing with the camera still, the same
    turning, the real-time ratio of the mean frame, the share of frames over frame_dt, the
    ratio the window holds, frame_dt, steps a frame), medians of `frames` frames after 5
    (0: every frame left)."""
    scene = load_scene(path, preview=preview)
    viewer = viewer_for(scene, width=width, height=height)
    camera = viewer.camera
    for _ in range(5):
        viewer.advance()
        viewer.window_image()
    steps, still, turning = [], [], []
    for k in range(frames or max(scene.frames - 5, 1)):
        start = time.perf_counter()
        viewer.advance()
        steps.append(time.perf_counter() - start)
        start = time.perf_counter()
        viewer.window_image()
        still.append(time.perf_counter() - start)
    for k in range(min(len(steps), 15)):
        viewer.camera = turned(camera, k + 1)
        start = time.perf_counter()
        viewer.window_image()
        turning.append(time.perf_counter() - start)
    viewer.camera = camera
    frame = np.add(steps, still)
    return (1e3 * statistics.median(steps), 1e3 * np.percentile(steps, 90),
            1e3 * statistics.median(still), 1e3 * statistics.median(turning),
            viewer.frame_dt / frame.mean(), float((frame > viewer.frame_dt).mean()),
            in_the_window(viewer, steps, still), viewer.frame_dt, viewer.substeps)


def in_the_window(viewer, steps, draws):
    """The real-time ratio the window (app/view.py) holds over the frames timed: its loop
    replayed on a clock of its own with the measured costs, `steps` [s] of each frame and
    `draws` [s] of each drawing (Viewer.frames_due: a slow frame made up by the next ones,
    at most CATCH_UP frames a drawing; Viewer.wait: never ahead of real time)."""
    now, k, drawn, cost = 0.0, 0, 0, 0.0
    while k < len(steps):
        due = viewer.frames_due(now, step_cost=cost)
        taken = steps[k:k + due]
        cost = sum(taken) / len(taken)
        now += sum(taken) + draws[min(drawn, len(draws) - 1)]
        k, drawn = k + len(taken), drawn + 1
        now += viewer.wait(now)
    return len(steps) * viewer.frame_dt / now


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[32, 128, 512])
    parser.add_argument("--scenes", nargs="*", default=[],
                        help="scene files to time as the live viewer runs them")
    parser.add_argument("--arch", default="cpu", choices=limits.ARCH_NAMES)
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=720)
    parser.add_argument("--frames", type=int, default=7, help="timed frames per case (median); "
                        "0: every frame of a --scenes scene")
    parser.add_argument("--preview", action="store_true",
                        help="time each of --scenes' preview too (ti-cloth view --preview)")
    args = parser.parse_args(argv)
    if args.frames < 0 or (args.frames == 0 and args.sizes):
        parser.error(f"--frames must be >= 1 (0: every frame, with --scenes only), "
                     f"got {args.frames}")
    tc.init(arch=args.arch, precision="f32")
    if args.sizes:
        print(f"arch={args.arch}, {args.width}x{args.height}, median of {args.frames} frames; "
              f"simulation: symplectic Euler f32 at 0.5 x stable dt, {FPS:.0f} fps")
        print(f"{'N':>5} {'triangles':>10} {'SSAA':>5} {'render ms':>10} {'sim ms/step':>12} "
              f"{'substeps':>9} {'sim ms/frame':>13} {'render/sim':>11} {'render = steps':>15} "
              f"{'window ms':>10} {'turning':>8}")
    for n in args.sizes:
        cloth = hanging_cloth(n)
        dt = 0.5 * tc.stable_dt(cloth, "symplectic_euler")
        sim = tc.Simulation(cloth, dt=1.0 / FPS / np.ceil(1.0 / FPS / dt), drag=0.2)
        step_ms, substeps = sim_ms_per_step(sim, repeats=5)
        sim_ms = step_ms * substeps
        camera = Camera.fit([[0.0, -1.1, -0.1], [1.0, 0.05, 1.1]], aspect=args.width / args.height)
        for ss in (1, 2):
            with Renderer(args.width, args.height, camera, supersample=ss) as renderer:
                ms = render_ms_per_frame(renderer, sim, args.frames)
                window = render_ms_per_frame(renderer, sim, args.frames, window=True)
                turning = render_ms_per_frame(renderer, sim, args.frames, window=True,
                                              turning=True)
            print(f"{n:>5} {len(cloth.mesh.triangles):>10} {ss:>4}x {ms:>10.1f} {step_ms:>12.3f} "
                  f"{substeps:>9} {sim_ms:>13.0f} {ms / sim_ms:>11.4f} {ms / step_ms:>15.0f} "
                  f"{window:>10.1f} {turning:>8.1f}")
    if args.scenes:
        told = f"{args.frames} frames" if args.frames else "every frame"
        print(f"\nthe live viewer, {args.width}x{args.height}, no supersampling, medians of "
              f"{told} after 5")
        print(f"{'scene':>24} {'steps a frame':>14} {'steps ms':>9} {'90 %':>6} "
              f"{'drawing ms':>11} {'turning':>8} {'real time':>10} {'whole run':>10} "
              f"{'over budget':>12} {'frames/s':>9}")
    for path in args.scenes:
        for preview in (False, True) if args.preview else (False,):
            (steps, tail, still, turning, whole, over, window, frame_dt,
             substeps) = viewer_ms_per_frame(path, args.frames, args.width, args.height, preview)
            name = Path(path).stem + (" preview" if preview else "")
            print(f"{name:>24} {substeps:>14} {steps:>9.1f} {tail:>6.1f} {still:>11.1f} "
                  f"{turning:>8.1f} {1e3 * frame_dt / (steps + still):>9.2f}x {whole:>9.2f}x "
                  f"{over:>11.0%} {window:>6.2f}x {1e3 / (steps + still):>9.0f}", flush=True)


if __name__ == "__main__":
    main()
