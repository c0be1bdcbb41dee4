"""What a scene pays for the features it uses: the same N x N cloth with gravity and stretch
springs only (minimal) against stretch + shear + bend springs, drag, turbulent wind, tearing,
strain limiting, a sphere collider and a scripted handle (full), symplectic Euler. Medians of
several runs, ratio measured in the same run.

    python benchmarks/feature_cost.py [--sizes 32 64] [--arch cpu] [--precision f32]
"""

import argparse
import statistics
import time

import ti_cloth as tc
from ti_cloth.inputs import limits


def minimal(n):
    full = tc.Cloth(tc.grid_mesh(n, n, plane="xz"), tc.Material())
    stretch = full.spring_indices[full.spring_kind == tc.SpringKind.STRETCH]
    cloth = tc.Cloth(tc.grid_mesh(n, n, plane="xz"), tc.Material(), pinned=[0, n - 1],
                     springs={tc.SpringKind.STRETCH: stretch})
    return tc.Simulation(cloth, integrator="symplectic_euler", dt=1e-5)


def everything(n):
    cloth = tc.Cloth(tc.grid_mesh(n, n, plane="xz"), tc.Material(), pinned=[0, n - 1])
    return tc.Simulation(
        cloth, integrator="symplectic_euler", dt=1e-5, drag=0.2, tearing=0.5,
        wind=tc.Wind(velocity=(1.0, 0.0, 0.5), turbulence=0.5),
        handles=[tc.Handle([n * n - 1], tc.Oscillation(amplitude=(0.0, 0.05, 0.0), frequency=1.0))],
        colliders=[tc.Sphere(centre=(0.5, -0.3, 0.5), radius=0.2)], strain_limit=tc.StrainLimit(max_strain=0.1))


def steps_per_second(sim, steps, repeats):
    sim.step(2)  # compile
    rates = []
    for _ in range(repeats):
        start = time.perf_counter()
        sim.step(steps)
        sim.positions()
        rates.append(steps / (time.perf_counter() - start))
    return statistics.median(rates)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    parser.add_argument("--arch", default="cpu", choices=limits.ARCH_NAMES)
    parser.add_argument("--precision", default="f32", choices=["f32", "f64"])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    tc.init(arch=args.arch, precision=args.precision)
    print(f"arch={args.arch} precision={args.precision}, symplectic Euler, median of {args.repeats} "
          f"runs x {args.steps} steps")
    print(f"{'N':>5} {'minimal steps/s':>16} {'full steps/s':>13} {'minimal / full':>15}")
    for n in args.sizes:
        lean = steps_per_second(minimal(n), args.steps, args.repeats)
        full = steps_per_second(everything(n), args.steps, args.repeats)
        print(f"{n:>5} {lean:>16.0f} {full:>13.0f} {lean / full:>15.2f}")


if __name__ == "__main__":
    main()
