"""What self-collision costs a step: an N x N sheet pinned at two corners, falling and swinging
above a ground plane, with and without SelfCollision, for symplectic Euler (at its automatic
step) and xpbd (1/240 s, 10 iterations). Medians of several runs; the ratio is measured in the
same run.

    python benchmarks/self_collision.py [--sizes 32 64 128] [--arch cpu] [--precision f32]
"""

import argparse
import statistics
import time

import ti_cloth as tc


def simulation(n, integrator, contact):
    cloth = tc.Cloth(tc.grid_mesh(n, n, plane="xz"), tc.Material(), pinned=[0, n - 1])
    return tc.Simulation(cloth, integrator=integrator,
                         dt="auto" if integrator == "symplectic_euler" else 1 / 240,
                         colliders=[tc.Plane(point=(0.0, -2.0, 0.0))],
                         self_collision=tc.SelfCollision(thickness=0.005) if contact else None)


def ms_per_step(sim, steps, repeats):
    sim.step(2)  # compile
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        sim.step(steps)
        sim.positions()
        times.append((time.perf_counter() - start) / steps * 1e3)
    return statistics.median(times)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128])
    parser.add_argument("--arch", default="cpu", choices=["cpu", "cuda", "vulkan", "gpu"])
    parser.add_argument("--precision", default="f32", choices=["f32", "f64"])
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    tc.init(arch=args.arch, precision=args.precision)
    print(f"arch={args.arch} precision={args.precision}, median of {args.repeats} runs x "
          f"{args.steps} steps")
    print(f"{'N':>5} {'integrator':>17} {'free ms/step':>13} {'self-collision ms/step':>23} "
          f"{'ratio':>6}")
    for n in args.sizes:
        for integrator in ("symplectic_euler", "xpbd"):
            free = ms_per_step(simulation(n, integrator, False), args.steps, args.repeats)
            contact = ms_per_step(simulation(n, integrator, True), args.steps, args.repeats)
            print(f"{n:>5} {integrator:>17} {free:>13.3f} {contact:>23.3f} {contact / free:>6.1f}")


if __name__ == "__main__":
    main()
