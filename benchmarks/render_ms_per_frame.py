"""Milliseconds per rendered frame (1280 x 720 by default) of an N x N hanging cloth over a ground
plane, with and without supersampling, next to the simulation's own time per frame measured in
the same run: symplectic Euler, f32, at half its predicted stable step, 30 frames per second.

    python benchmarks/render_ms_per_frame.py [--sizes 32 128 512] [--arch cpu] [--frames 7]

Render time covers everything a demo pays per frame: reading positions back, the vertex and
raster kernels, the resolve and the layout conversion to a numpy image (not the PNG write);
"window ms" the same frame ended as the live viewer's window takes it (Renderer.end_window,
no layout conversion).
"""

import argparse
import statistics
import time

import numpy as np

import ti_cloth as tc
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


def render_ms_per_frame(renderer, sim, frames, window=False):
    """Median ms of a frame ending as an image (Renderer.end: (H, W, 3), top row first) or,
    with `window`, as a window takes it (Renderer.end_window: the live viewer's)."""
    style = SurfaceStyle(checker=0.1)
    times = []
    for k in range(frames + 2):               # two warm-up frames compile the kernels
        start = time.perf_counter()
        renderer.begin()
        renderer.draw_plane(point=(0.0, -1.1, 0.0))
        renderer.draw_simulation(sim, style)
        renderer.end_window() if window else renderer.end()
        if k >= 2:
            times.append(time.perf_counter() - start)
    return 1e3 * statistics.median(times)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 128, 512])
    parser.add_argument("--arch", default="cpu", choices=limits.ARCH_NAMES)
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=720)
    parser.add_argument("--frames", type=int, default=7, help="timed frames per case (median)")
    args = parser.parse_args(argv)
    tc.init(arch=args.arch, precision="f32")
    print(f"arch={args.arch}, {args.width}x{args.height}, median of {args.frames} frames; "
          f"simulation: symplectic Euler f32 at 0.5 x stable dt, {FPS:.0f} fps")
    print(f"{'N':>5} {'triangles':>10} {'SSAA':>5} {'render ms':>10} {'sim ms/step':>12} "
          f"{'substeps':>9} {'sim ms/frame':>13} {'render/sim':>11} {'render = steps':>15} "
          f"{'window ms':>10}")
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
            print(f"{n:>5} {len(cloth.mesh.triangles):>10} {ss:>4}x {ms:>10.1f} {step_ms:>12.3f} "
                  f"{substeps:>9} {sim_ms:>13.0f} {ms / sim_ms:>11.4f} {ms / step_ms:>15.0f} "
                  f"{window:>10.1f}")


if __name__ == "__main__":
    main()
