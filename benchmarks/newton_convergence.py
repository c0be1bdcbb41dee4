"""How fast Newton's method converges in the implicit stage of the second-order solvers
(integrators/newton.py) on issue 53's denim sheet, and what sets that rate.

From the state of the 32 x 32 sheet (0.5 m, pinned at two adjacent corners, falling from rest)
at t = --at, one implicit midpoint step of --dt is taken with Newton stopped after k
iterations (k = 1 .. 8, each linear solve to a relative residual of 1e-8, f64), and compared
with the same step after 30 iterations: the largest particle distance. Printed per fabric
(the denim and variants of its bending rigidity and its stretch and shear moduli), with the
mean ratio of successive errors over iterations 3 to 8 (a quadratic method's would grow
without bound; a linear one's stays flat).

    python benchmarks/newton_convergence.py [--dt 0.008333] [--at 0.15] [--size 32]
"""

import argparse

import numpy as np

import ti_cloth as tc

DENIM = dict(density=0.324, stretch=5e3, shear=1e3, bending=1e-4)
VARIANTS = (("denim", {}), ("bending 1e-6", dict(bending=1e-6)),
            ("bending 1e-5", dict(bending=1e-5)), ("bending 1e-3", dict(bending=1e-3)),
            ("stretch, shear / 10", dict(stretch=5e2, shear=1e2)),
            ("no damping", dict(damping=0.0)))
ITERATIONS = range(1, 9)
CONVERGED = 30


def cloth(n: int, fabric: dict) -> tc.Cloth:
    mesh = tc.grid_mesh(rows=n, cols=n, size=(0.5, 0.5), plane="xz")
    return tc.Cloth(mesh, tc.Fabric(**fabric), pinned=[0, n - 1])


def errors(n: int, fabric: dict, dt: float, at: float) -> list[float]:
    """The error after each of ITERATIONS Newton iterations of one step from the state at `at`."""
    start = tc.Simulation(cloth(n, fabric), dt=dt,
                          integrator=tc.ImplicitMidpoint(tolerance=1e-7, cg_tolerance=1e-4))
    start.step(round(at / dt))
    x, v = start.positions(), start.velocities()
    ends = {}
    for k in (*ITERATIONS, CONVERGED):
        sim = tc.Simulation(cloth(n, fabric), dt=dt, integrator=tc.ImplicitMidpoint(
            tolerance=1e-12, most_newton=k, cg_tolerance=1e-8, most_cg=5000))
        sim.set_positions(x)
        sim.set_velocities(v)
        sim.step(1)
        ends[k] = sim.positions()
    return [float(np.abs(ends[k] - ends[CONVERGED]).max()) for k in ITERATIONS]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dt", type=float, default=1 / 120)
    parser.add_argument("--at", type=float, default=0.15)
    parser.add_argument("--size", type=int, default=32)
    args = parser.parse_args()
    tc.init(arch="cpu", precision="f64")
    print(f"{args.size}² sheet, implicit midpoint, dt {args.dt:.4g} s from t = {args.at} s: "
          f"largest particle error [m] after k Newton iterations, against {CONVERGED}")
    print(f"| fabric | {' | '.join(f'k={k}' for k in ITERATIONS)} | ratio (3-8) |")
    print("|---|" + "---|" * (len(ITERATIONS) + 1))
    for label, change in VARIANTS:
        e = errors(args.size, {**DENIM, **change}, args.dt, args.at)
        ratios = [a / b for a, b in zip(e[2:], e[3:]) if b > 0]
        print(f"| {label} | {' | '.join(f'{x:.2e}' for x in e)} | "
              f"{np.exp(np.mean(np.log(ratios))):.1f} |", flush=True)


if __name__ == "__main__":
    main()
