"""The implicit solvers on compressed cloth: where their Newton solves stall.

Issue 53's denim sheet (0.5 m, N x N, pinned at two adjacent corners) is started at rest
with its particles pulled towards its middle by a factor --scales (1: at rest length; 0.97:
every triangle 3 % shorter each way) and rippled 1 mm out of its plane, then stepped for
--duration by symplectic Euler at 0.9 of its stable step and by implicit midpoint and
TR-BDF2 with the loose solves at --dts. Printed for each run: the share of Newton solves that
stopped at their cap (most_newton = 8), Newton iterations a solve, and at the end the sheet's
roughness (the mean length of the second difference of positions along the grid's rows:
the mesh-scale crumpling) and its extent. --compressions runs the sheet for each
Fabric.compression given (1: as stiff pushed as pulled; 0.05: a yarn gives way).

A compressed sheet is a buckling problem: a triangle under a compressive stress sigma has a
negative geometric stiffness of about sigma A |grad lambda|^2, which on the denim at 3 %
outweighs the inertia M / s^2 of a sub-step s above about 0.5 ms. So the incremental
potential each implicit step minimises is not convex, and Newton with the stress projected
onto its non-negative part (energies/membrane.py) stalls; implicit midpoint's step doubles
the stalled half step. The explicit step, stable and small, lets the sheet expand back
before the mesh-scale buckles grow (docs/integrators.md, "Compressed cloth").

    python benchmarks/compressed_cloth.py [--size 32] [--scales 1 0.97 0.9]
        [--dts 0.008333 0.001042] [--duration 0.2] [--compressions 1 0.05]
"""

import argparse
import warnings

import numpy as np

import ti_cloth as tc

DENIM = dict(density=0.324, stretch=5e3, shear=1e3, bending=1e-4)
RIPPLE = 1e-3       # [m] out of the plane, so that buckling has a direction to start in


def started(sim: tc.Simulation, n: int, scale: float) -> None:
    """The sheet pulled towards its middle by `scale`, rippled, at rest."""
    x0 = sim.positions()
    middle = x0.mean(axis=0)
    x = middle + scale * (x0 - middle)
    x[:, 1] += RIPPLE * np.sin(7 * x0[:, 0] / 0.5 * np.pi) * np.sin(5 * x0[:, 2] / 0.5 * np.pi)
    sim.set_positions(x)


def roughness(x: np.ndarray, n: int) -> float:
    """Mean |x[i, j+1] - 2 x[i, j] + x[i, j-1]| over the grid's rows [m]."""
    grid = x.reshape(n, n, 3)
    return float(np.linalg.norm(grid[:, 2:] - 2 * grid[:, 1:-1] + grid[:, :-2], axis=2).mean())


def run(cloth: tc.Cloth, n: int, scale: float, integrator, dt: float, duration: float) -> str:
    sim = tc.Simulation(cloth, integrator=integrator, dt=dt)
    started(sim, n, scale)
    steps = max(1, round(duration / dt))
    newton = []
    for _ in range(steps):
        sim.step(1)
        newton.append(getattr(sim.integrator, "last_newton", 0))
    solves = steps * getattr(sim.integrator, "solves", 0)
    stalled = (f"{sim.integrator.unconverged_solves / solves:6.0%}" if solves else "     -")
    mean = f"{np.mean(newton):5.1f}" if solves else "    -"
    x = sim.positions()
    return (f"{stalled} | {mean} | {roughness(x, n) * 1e3:7.2f} | "
            f"{' x '.join(f'{e:.2f}' for e in np.ptp(x, axis=0))}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=32)
    parser.add_argument("--scales", type=float, nargs="+", default=[1.0, 0.97, 0.9])
    parser.add_argument("--dts", type=float, nargs="+", default=[1 / 120, 1 / 960])
    parser.add_argument("--duration", type=float, default=0.2)
    parser.add_argument("--precision", choices=("f32", "f64"), default="f32")
    parser.add_argument("--compressions", type=float, nargs="+", default=[1.0])
    args = parser.parse_args()
    tc.init(arch="cpu", precision=args.precision)
    n = args.size
    mesh = tc.grid_mesh(rows=n, cols=n, size=(0.5, 0.5), plane="xz")
    print(f"{n} x {n} denim sheet, {args.precision}, after {args.duration} s; Newton solves "
          "stopped at their cap (8), Newton iterations a solve, roughness (mm), extent (m)\n")
    print("| compression | scale | run | step [s] | stalled | Newton | roughness [mm] | "
          "extent [m] |")
    print("|---|---|---|---|---|---|---|---|")
    for compression in args.compressions:
        cloth = tc.Cloth(mesh, tc.Fabric(**DENIM, compression=compression), pinned=[0, n - 1])
        explicit = 0.9 * tc.stable_dt(cloth, "symplectic_euler")
        for scale in args.scales:
            runs = [("symplectic_euler", "symplectic_euler", explicit)]
            for dt in args.dts:
                for make in (tc.ImplicitMidpoint, tc.TRBDF2):
                    runs.append((f"{make.name} loose", make(**make.presets["loose"]), dt))
            for label, integrator, dt in runs:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)
                    row = run(cloth, n, scale, integrator, dt, args.duration)
                print(f"| {compression:g} | {scale:g} | {label} | {dt:.3g} | {row} |", flush=True)


if __name__ == "__main__":
    main()
