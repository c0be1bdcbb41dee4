"""Hanging cloth: a horizontal sheet pinned at two corners falls and swings (Stuyck ch. 4),
rendered headlessly (shaded, chequered on its rest coordinates, over a ground plane).

    python demos/hanging_cloth.py            # renders/hanging_cloth/frame_00000.png ... + .gif
    python demos/hanging_cloth.py --mp4      # also hanging_cloth.mp4 (needs imageio-ffmpeg)
    python demos/hanging_cloth.py --test     # tiny and fast
"""

import argparse
import time
from pathlib import Path

import numpy as np

import ti_cloth as tc
from ti_cloth.render import Camera, FrameSequence, Renderer, SurfaceStyle


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=90, help="frames to render (default 90)")
    parser.add_argument("--resolution", type=int, default=20, help="particles per side (default 20)")
    parser.add_argument("--integrator", default="symplectic_euler", choices=sorted(tc.INTEGRATORS))
    parser.add_argument("--out-dir", type=Path, default=Path("renders/hanging_cloth"))
    parser.add_argument("--arch", default="cpu", choices=["cpu", "cuda", "vulkan", "gpu"])
    parser.add_argument("--width", type=int, default=640, help="image width in pixels (default 640)")
    parser.add_argument("--height", type=int, default=360, help="image height in pixels (default 360)")
    parser.add_argument("--mp4", action="store_true", help="also write an MP4 (needs imageio-ffmpeg)")
    parser.add_argument("--test", action="store_true", help="tiny and fast: 8x8 cloth, 4 frames")
    args = parser.parse_args(argv)
    if args.frames < 1 or args.resolution < 2 or args.width < 16 or args.height < 16:
        parser.error("--frames must be >= 1, --resolution >= 2, --width and --height >= 16")
    if args.test:
        args.frames, args.resolution, args.width, args.height = min(args.frames, 4), 8, 160, 90
    return args


def main(argv=None):
    args = parse_args(argv)
    tc.init(arch=args.arch, precision="f32")
    n, size, fps = args.resolution, 1.0, 30
    mesh = tc.grid_mesh(n, n, size=(size, size), plane="xz")
    material = tc.Material(density=0.15, stretch=tc.SpringParams(800.0, 0.4),
                           shear=tc.SpringParams(80.0, 0.04), bend=tc.SpringParams(1.0, 0.001))
    cloth = tc.Cloth(mesh, material, pinned=[0, n - 1])   # the two corners of row 0
    dt = 0.5 * tc.stable_dt(cloth, args.integrator)
    substeps = int(np.ceil(1.0 / fps / min(dt, 1e-3)))
    sim = tc.Simulation(cloth, integrator=args.integrator, dt=1.0 / fps / substeps, drag=0.2)
    ground = -1.3
    camera = Camera(position=(1.4 * size, 0.15 * size, 1.6 * size),
                    target=(0.5 * size, -0.6 * size, 0.0), fov=45.0)
    renderer = Renderer(args.width, args.height, camera, supersample=2)
    style = SurfaceStyle(checker=size / 8)
    frames = FrameSequence(args.out_dir, fps=fps, mp4=args.mp4, gif_width=min(args.width, 480))

    start = time.perf_counter()
    for frame in range(args.frames):
        if frame:
            sim.step(substeps)
        renderer.begin()
        renderer.draw_plane(point=(0.0, ground, 0.0), checker=0.5)
        renderer.draw_simulation(sim, style)
        frames.write(renderer.end())
    outputs = frames.close()
    print(f"{len(frames.paths)} frames ({n}x{n} cloth, {args.integrator}, dt={sim.dt:.3g} s x "
          f"{substeps} substeps) in {time.perf_counter() - start:.1f} s -> {args.out_dir}/, "
          f"{', '.join(p.name for p in outputs)}")
    return frames.paths


if __name__ == "__main__":
    main()
