"""What a Fabric's step costs against a step of Stuyck's springs on the same mesh.

The scene: grid_mesh(N, N), two corners pinned, gravity, at rest, stepped by symplectic Euler
with one dt for both bodies (half the smaller of their stable steps): the default Material
(stretch, shear and bend springs: about 6 per particle) and Fabric.preset("denim")
(a membrane per triangle, 2 per particle, and a hinge per interior edge, about 3 per
particle). Both run the full simulator (Simulation.step, many steps per launch, divergence
guard included). Rates are medians of --repeats runs of at least --seconds each, measured in
the same process, and the ratio comes from this run.

    python benchmarks/fabric_step.py [--sizes 32 64 128] [--precision f32] [--arch cpu]
"""

import argparse

from throughput import median_rate

import ti_cloth as tc


def bodies(n: int) -> dict[str, tc.Cloth]:
    mesh = tc.grid_mesh(n, n, (1.0, 1.0))
    pinned = [n * (n - 1), n * n - 1]
    return {"springs": tc.Cloth(mesh, tc.Material(), pinned=pinned),
            "fabric": tc.Cloth(mesh, tc.Fabric.preset("denim"), pinned=pinned)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128])
    parser.add_argument("--precision", default="f32", choices=("f32", "f64"))
    parser.add_argument("--arch", default="cpu")
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    tc.init(arch=args.arch, precision=args.precision)
    print(f"symplectic Euler, {args.precision}, {args.arch}, medians of {args.repeats} runs")
    print(f"{'N':>5} {'particles':>9} {'springs steps/s':>16} {'fabric steps/s':>15} "
          f"{'fabric cost / springs':>22}")
    for n in args.sizes:
        cloths = bodies(n)
        dt = 0.5 * min(tc.stable_dt(c, "symplectic_euler") for c in cloths.values())
        rates = {}
        for name, cloth in cloths.items():
            sim = tc.Simulation(cloth, integrator="symplectic_euler", dt=dt)
            rates[name] = median_rate(sim.step, sim.velocities, args.seconds, args.repeats)
        print(f"{n:>5} {n * n:>9} {rates['springs']:>16.1f} {rates['fabric']:>15.1f} "
              f"{rates['springs'] / rates['fabric']:>22.2f}")


if __name__ == "__main__":
    main()
