"""The implicit_euler linear solve: matrix-free conjugate gradients (what ti_cloth uses) against
Taichi's sparse Cholesky (ti.linalg.SparseSolver, LLT) on the same Baraff-Witkin system, per
step of an N x N cloth at a step 10x beyond the explicit limit. Medians of several steps;
the sparse solver's pattern analysis is done once, outside the timing.

    python benchmarks/implicit_solver.py [--sizes 16 32 64 96] [--precision f64]
"""

import argparse
import statistics
import time

import numpy as np
import taichi as ti

import ti_cloth as tc
from ti_cloth.runtime import plan


@ti.kernel
def _assemble(model: ti.template(), ws: ti.template(), dt: float, builder: ti.types.sparse_matrix_builder()):
    """The same A as implicit_euler applies matrix-free, as triplets (pinned rows: identity)."""
    for i in range(model.particle_count):
        free = model.particle_inv_mass[i] > 0
        for d in ti.static(range(3)):
            builder[3 * i + d, 3 * i + d] += model.particle_mass[i] if free else 1.0
        if free:
            for a in range(model.particle_spring_start[i], model.particle_spring_start[i + 1]):
                s = model.adjacency_spring[a]
                j = model.adjacency_other[a]
                n, c = ws.spring_normal[s], ws.spring_lateral[s]
                k, kd = model.spring_stiffness[s], model.spring_damping[s]
                block = (dt * dt * k * (n.outer_product(n) + c * (ti.Matrix.identity(float, 3) - n.outer_product(n)))
                         + dt * kd * n.outer_product(n))
                for r, q in ti.static(ti.ndrange(3, 3)):
                    builder[3 * i + r, 3 * i + q] += block[r, q]
                    if model.particle_inv_mass[j] > 0:
                        builder[3 * i + r, 3 * j + q] -= block[r, q]


def median_time(fn, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[16, 32, 64, 96])
    parser.add_argument("--precision", default="f64", choices=["f32", "f64"])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args(argv)
    tc.init(arch="cpu", precision=args.precision)
    real = ti.f64 if args.precision == "f64" else ti.f32
    print(f"precision={args.precision}, CPU, median of {args.repeats} steps; dt = 10 x stable_dt(symplectic_euler)")
    print(f"{'N':>4} {'dofs':>7} {'CG ms/step':>11} {'CG iters':>9} {'LLT ms/step':>12} "
          f"{'(build':>7} {'factor':>7} {'solve)':>7} {'LLT/CG':>7} {'LLT resid':>10}")
    for n in args.sizes:
        cloth = tc.Cloth(tc.grid_mesh(n, n), tc.Material(), pinned=[n * (n - 1), n * n - 1])
        dt = 10 * tc.stable_dt(cloth, "symplectic_euler")
        integrator = tc.ImplicitEuler(tolerance=1e-6, max_iterations=2000)
        sim = tc.Simulation(cloth, integrator=integrator, dt=dt)
        sim.step(5)
        cg_time = median_time(lambda: (sim.step(1), sim.positions()), args.repeats)
        iterations = integrator.last_iterations
        model, state = sim.model, sim.state
        ws = integrator.buffers(state, None)   # made by the steps above
        dofs = 3 * cloth.particle_count
        builder_size = 36 * cloth.spring_count + dofs   # 2 x 9 entries per spring end, + the diagonal
        solver = ti.linalg.SparseSolver(dtype=real, solver_type="LLT")
        timing = {}

        def build():
            builder = ti.linalg.SparseMatrixBuilder(dofs, dofs, max_num_triplets=builder_size, dtype=real)
            _assemble(model, ws, dt, builder)
            return builder.build()

        # ws.r = b of the next step: the first part of implicit Euler's phases
        plan.run(sim.integrator, model, state, sim.forces, ws, dt, sim.step_count, False,
                 "linearisation")
        b = ws.r.to_numpy().reshape(-1)
        matrix = build()
        solver.analyze_pattern(matrix)
        rhs = ti.ndarray(real, dofs)
        rhs.from_numpy(b)
        timing["build"] = median_time(build, args.repeats)
        timing["factor"] = median_time(lambda: solver.factorize(matrix), args.repeats)
        timing["solve"] = median_time(lambda: solver.solve(rhs).to_numpy(), args.repeats)
        llt = sum(timing.values())
        # the LLT answer checked against the matrix-free product: relative residual |A dv - b| / |b|
        ws.p.from_numpy(solver.solve(rhs).to_numpy().reshape(-1, 3))
        plan.run(sim.integrator, model, state, sim.forces, ws, dt, sim.step_count, False,
                 "system_product")
        residual = float(np.linalg.norm(ws.ap.to_numpy().reshape(-1) - b) / np.linalg.norm(b))
        print(f"{n:>4} {dofs:>7} {cg_time * 1e3:>11.2f} {iterations:>9} {llt * 1e3:>12.2f} "
              f"{timing['build'] * 1e3:>7.2f} {timing['factor'] * 1e3:>7.2f} {timing['solve'] * 1e3:>7.2f} "
              f"{llt / cg_time:>7.1f} {residual:>10.2g}")


if __name__ == "__main__":
    main()
