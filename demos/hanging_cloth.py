"""Hanging cloth: a horizontal sheet pinned at two corners falls and swings (Stuyck ch. 4),
drawn as the lecture's dots and lines in an oblique view.

    python demos/hanging_cloth.py            # renders/hanging_cloth/frame_00000.png ... + .gif
    python demos/hanging_cloth.py --test     # tiny and fast
"""

import argparse
import time
from pathlib import Path

import numpy as np

import ti_cloth as tc
from ti_cloth.render import OBLIQUE, SpringView, frame_path, write_gif, write_png


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=90, help="frames to render (default 90)")
    parser.add_argument("--resolution", type=int, default=20, help="particles per side (default 20)")
    parser.add_argument("--integrator", default="symplectic_euler", choices=sorted(tc.INTEGRATORS))
    parser.add_argument("--out-dir", type=Path, default=Path("renders/hanging_cloth"))
    parser.add_argument("--arch", default="cpu", choices=["cpu", "cuda", "vulkan", "gpu"])
    parser.add_argument("--test", action="store_true", help="tiny and fast: 8x8 cloth, 4 frames")
    args = parser.parse_args(argv)
    if args.frames < 1 or args.resolution < 2:
        parser.error("--frames must be >= 1 and --resolution >= 2")
    if args.test:
        args.frames, args.resolution = min(args.frames, 4), 8
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
    view = SpringView(bounds=((-0.3, -1.2), (1.5, 0.4)), projection=OBLIQUE, res=(400, 400))

    args.out_dir.mkdir(parents=True, exist_ok=True)
    frames, start = [], time.perf_counter()
    for frame in range(args.frames):
        if frame:
            sim.step(substeps)
        image = view.render(sim.positions(), cloth.spring_indices, cloth.spring_kind, sim.model.pinned)
        frames.append(write_png(frame_path(args.out_dir, frame), image))
    gif = write_gif(frames, args.out_dir / "hanging_cloth.gif", fps=fps)
    print(f"{len(frames)} frames ({n}x{n} cloth, {args.integrator}, dt={sim.dt:.3g} s x {substeps} "
          f"substeps) in {time.perf_counter() - start:.1f} s -> {args.out_dir}/, {gif.name}")
    return frames


if __name__ == "__main__":
    main()
