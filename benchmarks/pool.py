"""What the pool of kernel arguments (ti_cloth/runtime/pool.py) buys: seconds to build and step
simulations of structures a process has seen before, with the pool and without it.

A study or an advisor builds a simulation per integrator x step x precision, most of them of
a structure built before; Taichi compiles a kernel once per set of template arguments, so a
simulation on new Model/State objects compiles its kernels again, while one lent a pooled set
finds them compiled. Each round builds one simulation per size (--sizes), steps it --steps
times and drops it; the first round compiles, the second is timed: with the pool, and with an
empty pool for every simulation (what the process would pay without it).

    python benchmarks/pool.py [--sizes 6 7 8 9 10] [--integrator xpbd] [--steps 20]
"""

import argparse
import gc
import time

import ti_cloth as tc
from ti_cloth import simulation
from ti_cloth.runtime.pool import Pool


def round_seconds(sizes, integrator: str, steps: int, fresh_pool: bool) -> float:
    """Seconds to build, step and drop one simulation per size."""
    began = time.perf_counter()
    for n in sizes:
        if fresh_pool:
            simulation.POOL = Pool()
        cloth = tc.Cloth(tc.grid_mesh(n, n), tc.Material(), pinned=[0, n - 1])
        sim = tc.Simulation(cloth, integrator=integrator, dt=1e-4)
        sim.step(steps)
        del sim
        gc.collect()
    return time.perf_counter() - began


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[6, 7, 8, 9, 10])
    parser.add_argument("--integrator", default="xpbd")
    parser.add_argument("--steps", type=int, default=20)
    args = parser.parse_args(argv)
    tc.init(arch="cpu", precision="f32")
    first = round_seconds(args.sizes, args.integrator, args.steps, False)
    pooled = round_seconds(args.sizes, args.integrator, args.steps, False)
    unpooled = round_seconds(args.sizes, args.integrator, args.steps, True)
    print(f"{len(args.sizes)} sizes of {args.integrator}, {args.steps} steps each: first round "
          f"{first:.2f} s; again with the pool {pooled:.2f} s, without it {unpooled:.2f} s "
          f"({unpooled / pooled:.1f}x)")


if __name__ == "__main__":
    main()
