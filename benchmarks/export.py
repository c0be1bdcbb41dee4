"""What exporting geometry costs a frame, per format, next to stepping the frame.

An N x N sheet (xpbd, 1/240 s, 4 steps a frame): ms per frame of Exporter.write for each
format alone, with its close() (median of several rounds of frames), of the frame's steps, and
of one saved state (Simulation.save_state: a run checkpoints every few seconds of work).

    python benchmarks/export.py [--sizes 64 128] [--frames 20] [--repeats 5]   # usd: pip install ".[usd]"
"""

import argparse
import statistics
import tempfile
import time

import ti_cloth as tc
from ti_cloth.export import FORMATS


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 128])
    parser.add_argument("--frames", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    tc.init()
    print(f"ms per frame, median of {args.repeats} rounds x {args.frames} frames")
    print(f"{'N':>5} {'4 xpbd steps':>13} " + " ".join(f"{f:>8}" for f in FORMATS)
          + f" {'state':>8}")
    for n in args.sizes:
        cloth = tc.Cloth(tc.grid_mesh(n, n), tc.Material(), pinned=[n * n - n, n * n - 1])
        sim = tc.Simulation(cloth, integrator="xpbd", dt=1 / 240)
        sim.step(4)
        times = {key: [] for key in ("step", *FORMATS, "state")}
        for _ in range(args.repeats):
            start = time.perf_counter()
            for _ in range(args.frames):
                sim.step(4)
            sim.positions()
            times["step"].append((time.perf_counter() - start) / args.frames * 1e3)
            for fmt in FORMATS:
                with tempfile.TemporaryDirectory() as folder:
                    export = tc.Exporter(folder, [fmt], name="sheet", cloth=cloth, fps=30)
                    start = time.perf_counter()
                    for _ in range(args.frames):
                        export.write(sim)
                    export.close()
                    times[fmt].append((time.perf_counter() - start) / args.frames * 1e3)
            with tempfile.TemporaryDirectory() as folder:
                start = time.perf_counter()
                sim.save_state(f"{folder}/state.npz")
                times["state"].append((time.perf_counter() - start) * 1e3)
        print(f"{n:>5} {statistics.median(times['step']):>13.2f} "
              + " ".join(f"{statistics.median(times[f]):>8.2f}" for f in (*FORMATS, "state")))


if __name__ == "__main__":
    main()
