"""XPBD at equal accuracy: ti_cloth's Gauss-Seidel XPBD against Newton's SolverXPBD (Jacobi
sweeps) on the same cloth and step, over iteration counts, error against cost.

The scene: an N x N sheet (1 m, stretch + shear + bend springs of the default Material), two
corners pinned, falling from rest in gravity for --duration s at dt = 1/240 s (1/60 s with 4
substeps). After it, each run's positions are compared with a reference (ti_cloth XPBD with
--reference-iterations passes per step: converged, its difference from half as many passes is
printed): the largest position error, and the largest strain of a stretch spring (|l / L - 1|,
the "too stretchy" measure of unconverged position-based solvers). Cost: seconds of wall time
per simulated second, the median of --repeats runs, every solver timed in this process, f32,
CPU (ti_cloth on every Taichi thread; Newton's CPU kernels run on one).

    python benchmarks/position_based.py [--sizes 64 128] [--iterations 1 2 4 8 16 32]
        [--newton] [--plot xpbd-cost.png]
"""

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
import peers

import ti_cloth as tc

NEWTON_CHECKED = ()   # none: the set-up does not match Newton 1.8 (see NewtonXPBD)

DT = 1 / 240
GRAVITY = (0.0, -9.81, 0.0)


def scene(n: int, scale: float = 1.0) -> tc.Cloth:
    """The sheet, its springs' k and kd those of the default Material times `scale`."""
    base = tc.Material()
    springs = {kind: tc.SpringParams(scale * getattr(base, kind).k, scale * getattr(base, kind).kd)
               for kind in ("stretch", "shear", "bend")}
    return tc.Cloth(tc.grid_mesh(n, n, plane="xz"), tc.Material(**springs), pinned=[0, n - 1])


class TiClothXPBD:
    def __init__(self, cloth, iterations):
        self.sim = tc.Simulation(cloth, integrator=tc.XPBD(iterations=iterations), dt=DT,
                                 gravity=GRAVITY)

    def run(self, steps):
        self.sim.restart()
        self.sim.step(steps)
        return self.sim.positions()


class NewtonXPBD:
    """Newton's SolverXPBD on the same particles and springs (no contacts)."""

    def __init__(self, cloth, iterations):
        # newton 1.8.0 reported errors of 4e2 m and strains of 2.4e4 at every pass count with
        # this set-up: it no longer matches Newton's SolverXPBD, and no version is checked
        peers.require("newton", NEWTON_CHECKED, "--newton (Newton's SolverXPBD)")
        import newton
        import warp as wp
        wp.config.quiet = True
        self.wp = wp
        builder = newton.ModelBuilder(up_axis=newton.Axis.Y, gravity=GRAVITY)
        mass = np.where(cloth.pinned, 0.0, cloth.particle_mass)
        for x, m in zip(cloth.particle_position, mass):
            builder.add_particle(tuple(map(float, x)), (0.0, 0.0, 0.0), float(m), radius=0.0)
        for (i, j), k, kd in zip(cloth.spring_indices, cloth.spring_stiffness,
                                 cloth.spring_damping):
            builder.add_spring(int(i), int(j), float(k), float(kd), control=0.0)
        self.model = builder.finalize(device="cpu")
        self.model.spring_rest_length.assign(cloth.spring_rest_length.astype(np.float32))
        self.solver = newton.solvers.SolverXPBD(self.model, iterations=iterations)
        self.control = self.model.control()

    def run(self, steps):
        states = [self.model.state(), self.model.state()]
        for _ in range(steps):
            states[0].clear_forces()
            self.solver.step(states[0], states[1], self.control, None, DT)
            states.reverse()
        self.wp.synchronize_device("cpu")
        return states[0].particle_q.numpy().astype(np.float64)


def max_strain(cloth, x):
    stretch = cloth.spring_kind == tc.SpringKind.STRETCH
    i, j = cloth.spring_indices[stretch].T
    length = np.linalg.norm(x[i] - x[j], axis=1)
    return float(np.abs(length / cloth.spring_rest_length[stretch] - 1.0).max())


def measure(solver, steps, repeats):
    """(positions, median seconds of `repeats` runs) after a warm-up run of the same length
    (it compiles every launch plan the runs take)."""
    solver.run(steps)
    times, x = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        x = solver.run(steps)
        times.append(time.perf_counter() - start)
    return x, statistics.median(times)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 128])
    parser.add_argument("--iterations", type=int, nargs="+", default=[1, 2, 4, 8, 16, 32])
    parser.add_argument("--reference-iterations", type=int, default=256)
    parser.add_argument("--duration", type=float, default=1.0)
    parser.add_argument("--stiffness-scale", type=float, default=1.0,
                        help="scale the default Material's spring constants (k and kd)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--newton", action="store_true", help="also run Newton's SolverXPBD")
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--plot", type=Path, default=None, help="write error against cost here")
    args = parser.parse_args(argv)
    tc.init(arch="cpu", precision="f32", threads=args.threads)
    steps = round(args.duration / DT)
    rows = []
    for n in args.sizes:
        cloth = scene(n, args.stiffness_scale)
        reference = TiClothXPBD(cloth, args.reference_iterations).run(steps)
        half = TiClothXPBD(cloth, args.reference_iterations // 2).run(steps)
        print(f"{n}²: reference xpbd {args.reference_iterations} passes; its difference from "
              f"{args.reference_iterations // 2} passes {np.abs(reference - half).max():.2e} m, "
              f"its max strain {max_strain(cloth, reference):.4f}")
        solvers = [("ti_cloth", TiClothXPBD)] + ([("newton", NewtonXPBD)] if args.newton else [])
        for name, make in solvers:
            for iterations in args.iterations:
                x, seconds = measure(make(cloth, iterations), steps, args.repeats)
                finite = bool(np.isfinite(x).all()) and np.abs(x).max() < 1e3
                rows.append(dict(n=n, solver=name, iterations=iterations,
                                 cost=seconds / args.duration,
                                 error=float(np.abs(x - reference).max()) if finite else np.inf,
                                 strain=max_strain(cloth, x) if finite else np.inf))
                r = rows[-1]
                print(f"  {name:>8} {iterations:>3} it: {r['cost']:8.3f} s/s  error "
                      f"{r['error']:.3e} m  max strain {r['strain']:.4f}", flush=True)
    print()
    print("| N | solver | iterations | s per simulated s | steps/s | position error [m] | max strain |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['n']}² | {r['solver']} | {r['iterations']} | {r['cost']:.3f} | "
              f"{1 / (r['cost'] * DT):,.0f} | {r['error']:.2e} | {r['strain']:.4f} |")
    if args.plot:
        plot(rows, args.plot)


def plot(rows, path: Path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    sizes = sorted({r["n"] for r in rows})
    figure, axes = plt.subplots(1, len(sizes), figsize=(5 * len(sizes), 4), squeeze=False)
    for ax, n in zip(axes[0], sizes):
        for solver, style in (("ti_cloth", "o-"), ("newton", "s--")):
            own = [r for r in rows if r["n"] == n and r["solver"] == solver]
            own = [r for r in own if np.isfinite(r["error"])]
            if own:
                ax.loglog([r["cost"] for r in own], [r["error"] for r in own], style, label=solver)
                for r in own:
                    ax.annotate(str(r["iterations"]), (r["cost"], r["error"]), fontsize=7)
        ax.set_title(f"XPBD, {n} x {n} cloth, dt = 1/240 s, 1 s")
        ax.set_xlabel("wall seconds per simulated second (CPU, f32)")
        ax.set_ylabel("max position error vs the many-pass reference [m]")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + ".tmp" + path.suffix)
    figure.savefig(tmp, dpi=90)
    tmp.replace(path)


if __name__ == "__main__":
    main()
