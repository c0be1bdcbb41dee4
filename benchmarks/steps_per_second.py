"""Steps per second of every integrator on an N x N cloth (stretch + shear + bend springs, two
corners pinned), median of several runs, with the ratio to symplectic Euler measured in the
same run.

    python benchmarks/steps_per_second.py [--sizes 32 64 128] [--arch cpu] [--precision f32]
"""

import argparse
import statistics
import time

import ti_cloth as tc


def measure(cloth, integrator, steps, repeats):
    sim = tc.Simulation(cloth, integrator=integrator, dt=1e-6, gravity=(0.0, -9.81, 0.0))
    sim.step(2)  # compile
    rates = []
    for _ in range(repeats):
        start = time.perf_counter()
        sim.step(steps)
        sim.positions()  # wait for the device
        rates.append(steps / (time.perf_counter() - start))
    return statistics.median(rates)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128])
    parser.add_argument("--arch", default="cpu", choices=["cpu", "cuda", "vulkan", "gpu"])
    parser.add_argument("--precision", default="f32", choices=["f32", "f64"])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    tc.init(arch=args.arch, precision=args.precision)
    print(f"arch={args.arch} precision={args.precision}, median of {args.repeats} runs x {args.steps} steps")
    print(f"{'N':>5} {'springs':>9} {'integrator':>17} {'steps/s':>10} {'Mspring-steps/s':>16} {'vs symplectic':>14}")
    for n in args.sizes:
        cloth = tc.Cloth(tc.grid_mesh(n, n), tc.Material(), pinned=[n * (n - 1), n * n - 1])
        rates = {name: measure(cloth, name, args.steps, args.repeats) for name in tc.INTEGRATORS}
        for name, rate in rates.items():
            print(f"{n:>5} {cloth.spring_count:>9} {name:>17} {rate:>10.0f} "
                  f"{rate * cloth.spring_count / 1e6:>16.1f} {rate / rates['symplectic_euler']:>14.2f}")


if __name__ == "__main__":
    main()
