"""Steps per second of N x N cloths for every integrator, f32 and f64, next to hand-written
baselines of the same step measured in the same run.

The scene: grid_mesh(N, N) with stretch + shear + bend springs of the default Material, 1 m a
side up to N = FINEST and N / FINEST m beyond, its edge kept at about 1 / FINEST m (the
explicit step shrinks as the edge squared: from N = 512 on a 1 m sheet's falls under
Simulation's 1e-7 s floor), two corners pinned, gravity, starting at rest stretched by
STRETCH about its centre; dt = the explicit Euler "auto" step at that N (the smallest of the
integrators' limits, so every integrator runs the same steps without diverging).
ti_cloth runs the full simulator (Simulation.step, divergence guard included). Baselines,
symplectic Euler only:
  numpy   vectorised NumPy written below: per-spring forces, scattered with np.bincount
  warp    NVIDIA Warp kernels written below (--warp; pip install warp-lang): a spring kernel
          scattering with atomic adds, then an integration kernel
  newton  Newton's SolverSemiImplicit on the same particles and springs (--newton; pip install
          newton)
Each baseline is checked against ti_cloth's velocities after CHECK_STEPS steps (spring
forces at work, and no rounding against the positions' size) before it is timed.
Rates are medians of --repeats runs of at least --seconds each; ratios come from this run.

    python benchmarks/throughput.py [--sizes 32 64 128 256 512 1024] [--precisions f32 f64]
        [--integrators ...] [--all-integrators-up-to 512] [--warp] [--newton] [--arch cpu]
        [--csv benchmarks/results/throughput-cpu.csv]
"""

import argparse
import csv
import os
import resource
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import peers
import taichi as ti

import ti_cloth as tc
from ti_cloth.inputs import limits
from ti_cloth.runtime import backend

WARP_CHECKED = ("1.19.",)     # the versions the docs' figures were measured with
NEWTON_CHECKED = ("1.8.",)

CHECK_STEPS = 20
STRETCH = 1.01
FINEST = 128          # particles a side of the finest 1 m sheet (module doc)


def scene(n: int) -> tuple[tc.Cloth, np.ndarray]:
    """The cloth and its start positions (module doc)."""
    side = max(1.0, n / FINEST)
    cloth = tc.Cloth(tc.grid_mesh(n, n, size=(side, side)), tc.Material(),
                     pinned=[n * (n - 1), n * n - 1])
    centre = cloth.particle_position.mean(axis=0)
    return cloth, centre + STRETCH * (cloth.particle_position - centre)


def median_rate(step, sync, seconds: float, repeats: int) -> float:
    """Median steps/s of `repeats` runs, each of enough steps to last about `seconds`, after a
    warm-up that compiles every launch plan (one step, then several)."""
    steps = calibrated_steps(step, sync, seconds)
    return statistics.median(timed_rate(step, sync, steps) for _ in range(repeats))


def interleaved_rates(variants: dict, seconds: float, repeats: int) -> dict[str, list[float]]:
    """{name: steps/s of each of `repeats` rounds} of variants {name: (step, sync)}, each
    round timing every variant once in turn (so a ratio of two variants' rates in one round
    compares runs seconds apart on a machine whose speed drifts)."""
    steps = {name: calibrated_steps(step, sync, seconds) for name, (step, sync) in variants.items()}
    rates = {name: [] for name in variants}
    for _ in range(repeats):
        for name, (step, sync) in variants.items():
            rates[name].append(timed_rate(step, sync, steps[name]))
    return rates


def timed_rate(step, sync, steps: int) -> float:
    start = time.perf_counter()
    step(steps)
    sync()
    return steps / (time.perf_counter() - start)


def calibrated_steps(step, sync, seconds: float) -> int:
    """After a warm-up that compiles every launch plan (one step, then several), the number of
    steps that lasts about `seconds`."""
    step(1)
    step(2)
    sync()
    steps = 2
    while True:
        start = time.perf_counter()
        step(steps)
        sync()
        elapsed = time.perf_counter() - start
        if elapsed >= seconds / 4 or steps >= 1 << 20:
            break
        steps *= 4
    return max(2, int(steps * seconds / elapsed))


class NumpyCloth:
    """Symplectic Euler on the scene, vectorised over springs, forces scattered by bincount."""

    def __init__(self, cloth, start, dt, gravity, dtype):
        self.dt, self.count = dtype(dt), cloth.particle_count
        self.x = start.astype(dtype)
        self.v = np.zeros_like(self.x)
        self.i, self.j = (np.ascontiguousarray(e) for e in cloth.spring_indices.T)
        self.rest = cloth.spring_rest_length.astype(dtype)
        self.k = cloth.spring_stiffness.astype(dtype)
        self.kd = cloth.spring_damping.astype(dtype)
        self.w = np.where(cloth.pinned, 0.0, 1.0 / cloth.particle_mass).astype(dtype)[:, None]
        self.weight = (cloth.particle_mass[:, None] * np.asarray(gravity)).astype(dtype)

    def step(self, steps: int) -> None:
        i, j = self.i, self.j
        for _ in range(steps):
            d = self.x[i] - self.x[j]
            length = np.sqrt(np.einsum("sc,sc->s", d, d))
            n = d / length[:, None]
            closing = np.einsum("sc,sc->s", self.v[i] - self.v[j], n)
            f = (-self.k * (length - self.rest) - self.kd * closing)[:, None] * n
            total = np.stack([np.bincount(i, f[:, c], self.count) - np.bincount(j, f[:, c], self.count)
                              for c in range(3)], axis=1) + self.weight
            self.v += self.dt * self.w * total.astype(self.x.dtype)
            self.x += self.dt * self.v

    def velocities(self):
        return self.v.astype(np.float64)


class WarpCloth:
    """The same step as Warp kernels: per-spring forces with atomic scatter, then integration."""

    def __init__(self, cloth, start, dt, gravity, dtype, device):
        peers.require("warp-lang", WARP_CHECKED, "--warp")
        import warp as wp
        wp.config.quiet = True
        wp.init()
        self.wp, self.device = wp, device
        scalar = wp.float32 if dtype == np.float32 else wp.float64
        vec = wp.types.vector(3, scalar)
        self.kernels = _warp_kernels(wp, scalar, vec)
        pinned = np.where(cloth.pinned, 0.0, 1.0 / cloth.particle_mass)

        def array(values, kind=scalar):
            return wp.array(np.asarray(values), dtype=kind, device=device)

        self.x = array(start.astype(dtype), vec)
        self.v = array(np.zeros_like(cloth.particle_position, dtype), vec)
        self.f = array(np.zeros_like(cloth.particle_position, dtype), vec)
        self.ends = wp.array(cloth.spring_indices.astype(np.int32), dtype=wp.vec2i, device=device)
        self.rest, self.k, self.kd = (array(a.astype(dtype)) for a in (
            cloth.spring_rest_length, cloth.spring_stiffness, cloth.spring_damping))
        self.w = array(pinned.astype(dtype))
        self.weight = array((cloth.particle_mass[:, None] * np.asarray(gravity)).astype(dtype), vec)
        self.dt = scalar(dt)
        self.counts = (cloth.spring_count, cloth.particle_count)

    def step(self, steps: int) -> None:
        wp, springs, integrate = self.wp, *self.kernels
        for _ in range(steps):
            wp.launch(springs, dim=self.counts[0], device=self.device,
                      inputs=[self.x, self.v, self.ends, self.rest, self.k, self.kd, self.f])
            wp.launch(integrate, dim=self.counts[1], device=self.device,
                      inputs=[self.x, self.v, self.f, self.w, self.weight, self.dt])

    def sync(self):
        self.wp.synchronize_device(self.device)

    def velocities(self):
        return self.v.numpy().astype(np.float64)


def _warp_kernels(wp, scalar, vec):
    def springs(x: wp.array(dtype=vec), v: wp.array(dtype=vec), ends: wp.array(dtype=wp.vec2i),
                rest: wp.array(dtype=scalar), k: wp.array(dtype=scalar),
                kd: wp.array(dtype=scalar), f: wp.array(dtype=vec)):
        s = wp.tid()
        i, j = ends[s][0], ends[s][1]
        d = x[i] - x[j]
        length = wp.length(d)
        n = d / length
        fs = (-k[s] * (length - rest[s]) - kd[s] * wp.dot(v[i] - v[j], n)) * n
        wp.atomic_add(f, i, fs)
        wp.atomic_sub(f, j, fs)

    def integrate(x: wp.array(dtype=vec), v: wp.array(dtype=vec), f: wp.array(dtype=vec),
                  w: wp.array(dtype=scalar), weight: wp.array(dtype=vec), dt: scalar):
        p = wp.tid()
        vp = v[p] + dt * w[p] * (f[p] + weight[p])
        v[p] = vp
        x[p] = x[p] + dt * vp
        f[p] = vec()

    suffix = "f64" if scalar == wp.float64 else "f32"
    return tuple(wp.Kernel(fn, key=f"{fn.__name__}_{suffix}") for fn in (springs, integrate))


class NewtonCloth:
    """Newton's semi-implicit solver on the same particles and springs (no contacts)."""

    def __init__(self, cloth, start, dt, gravity, dtype, device):
        peers.require("newton", NEWTON_CHECKED, "--newton")
        import newton
        import warp as wp
        wp.config.quiet = True
        if dtype != np.float32:
            raise ValueError("Newton runs in float32 only")
        self.wp, self.device, self.dt = wp, device, dt
        builder = newton.ModelBuilder(up_axis=newton.Axis.Y, gravity=tuple(gravity))
        builder.add_particles([tuple(x) for x in start],
                              [(0.0, 0.0, 0.0)] * cloth.particle_count,
                              np.where(cloth.pinned, 0.0, cloth.particle_mass).tolist(),
                              [0.0] * cloth.particle_count)
        for (i, j), k, kd in zip(cloth.spring_indices, cloth.spring_stiffness, cloth.spring_damping):
            builder.add_spring(int(i), int(j), float(k), float(kd), control=0.0)
        self.model = builder.finalize(device=device)
        self.model.spring_rest_length.assign(cloth.spring_rest_length.astype(np.float32))
        self.solver = newton.solvers.SolverSemiImplicit(self.model)
        self.states = [self.model.state(), self.model.state()]
        self.control = self.model.control()

    def step(self, steps: int) -> None:
        for _ in range(steps):
            a, b = self.states
            a.clear_forces()
            self.solver.step(a, b, self.control, None, self.dt)
            self.states.reverse()

    def sync(self):
        self.wp.synchronize_device(self.device)

    def velocities(self):
        return self.states[0].particle_qd.numpy().astype(np.float64)


def field_bytes(objects, particles: int, springs: int) -> tuple[float, float]:
    """Bytes per particle and per spring of the Taichi fields held by `objects`, a field counted
    per particle when its length is particles (+1) and per spring otherwise (springs, adjacency,
    colours)."""
    per_particle = per_spring = 0
    for obj in objects:
        for value in vars(obj).values():
            if isinstance(value, ti.Field) and value.shape:
                size = int(np.prod(value.shape)) * np.dtype(backend.numpy_dtype(value.dtype)).itemsize
                size *= value.n * value.m if isinstance(value, ti.MatrixField) else 1
                if value.shape[0] in (particles, particles + 1):
                    per_particle += size
                else:
                    per_spring += size
    return per_particle / particles, per_spring / springs


def check(baseline, reference, tolerance):
    """Both ran CHECK_STEPS steps from the same start: their velocities must agree."""
    error = np.abs(baseline.velocities() - reference).max()
    speed = np.abs(reference).max()
    if not error <= tolerance * speed:
        raise AssertionError(f"{type(baseline).__name__} disagrees with ti_cloth after {CHECK_STEPS} "
                             f"steps: max |dv| {error:.3g} m/s, max |v| {speed:.3g} m/s")


def measure_size(n, precision, args, baselines):
    """Rows for one N and precision."""
    cloth, start = scene(n)
    dt = tc.auto_dt(cloth, "explicit_euler")
    gravity = (0.0, -9.81, 0.0)
    rows = []

    def row(impl, rate, **extra):
        rows.append(dict(arch=args.arch, precision=precision, N=n, particles=cloth.particle_count,
                         springs=cloth.spring_count, implementation=impl, dt=dt,
                         steps_per_s=rate, spring_steps_per_s=rate * cloth.spring_count, **extra))

    integrators = args.integrators if n <= args.all_integrators_up_to else ["symplectic_euler"]
    reference = None
    for name in integrators:
        sim = tc.Simulation(cloth, integrator=name, dt=dt, gravity=gravity)
        sim.set_positions(start)
        if name == "symplectic_euler":
            sim.step(CHECK_STEPS)
            reference = sim.velocities()
        per_particle, per_spring = field_bytes([sim.model, sim.state], cloth.particle_count,
                                               cloth.spring_count)
        rate = median_rate(sim.step, sim.velocities, args.seconds, args.repeats)
        row(f"ti_cloth {name}", rate, bytes_per_particle=per_particle, bytes_per_spring=per_spring)
    dtype = np.float32 if precision == "f32" else np.float64
    tolerance = 1e-3 if precision == "f32" else 1e-9
    for impl, make in baselines.items():
        if impl == "newton" and precision != "f32":
            continue
        baseline = make(cloth, start, dt, gravity, dtype)
        if reference is not None:
            baseline.step(CHECK_STEPS)
            check(baseline, reference, tolerance)
        rate = median_rate(baseline.step, getattr(baseline, "sync", lambda: None), args.seconds,
                           args.repeats)
        row(impl, rate)
    return rows


def add_ratios(rows):
    """Each row's rate over the numpy and warp rows of the same N and precision."""
    for r in rows:
        for base in ("numpy", "warp"):
            same = [b for b in rows if b["implementation"] == base and b["N"] == r["N"]
                    and b["precision"] == r["precision"]]
            r[f"vs_{base}"] = r["steps_per_s"] / same[0]["steps_per_s"] if same else float("nan")


def print_table(rows):
    print(f"{'prec':>4} {'N':>5} {'springs':>9} {'implementation':>27} {'steps/s':>10} "
          f"{'Mspring-steps/s':>16} {'vs numpy':>9} {'vs warp':>8} {'B/particle':>10} {'B/spring':>9}")
    for r in rows:
        memory = (f"{r['bytes_per_particle']:>10.0f} {r['bytes_per_spring']:>9.1f}"
                  if "bytes_per_particle" in r else f"{'':>10} {'':>9}")
        print(f"{r['precision']:>4} {r['N']:>5} {r['springs']:>9} {r['implementation']:>27} "
              f"{r['steps_per_s']:>10.1f} {r['spring_steps_per_s'] / 1e6:>16.1f} "
              f"{r['vs_numpy']:>9.2f} {r['vs_warp']:>8.2f} {memory}")


def write_csv(rows, path: Path):
    """Atomically: a temporary file beside the target, then a rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fields = sorted({k for r in rows for k in r}, key=lambda k: list(rows[0]).index(k)
                    if k in rows[0] else len(rows[0]))
    with tempfile.NamedTemporaryFile("w", newline="", dir=path.parent, delete=False,
                                     suffix=".tmp") as handle:
        writer = csv.DictWriter(handle, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    os.replace(handle.name, path)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128, 256, 512, 1024])
    parser.add_argument("--precisions", nargs="+", default=["f32", "f64"], choices=["f32", "f64"])
    parser.add_argument("--integrators", nargs="+", default=list(tc.INTEGRATORS),
                        choices=list(tc.INTEGRATORS))
    parser.add_argument("--all-integrators-up-to", type=int, default=512,
                        help="larger N run symplectic Euler only")
    parser.add_argument("--arch", default="cpu", choices=limits.ARCH_NAMES)
    parser.add_argument("--threads", type=int, default=None, help="CPU threads (default: all)")
    parser.add_argument("--warp", action="store_true", help="also time hand-written Warp kernels")
    parser.add_argument("--newton", action="store_true", help="also time Newton's semi-implicit solver")
    parser.add_argument("--no-numpy", action="store_true", help="skip the NumPy baseline")
    parser.add_argument("--seconds", type=float, default=0.3, help="length of one timed run")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--csv", type=Path, default=None,
                        help="default: benchmarks/results/throughput-ARCH.csv")
    args = parser.parse_args(argv)
    device = "cpu" if args.arch == "cpu" else "cuda:0"
    baselines = {}
    if not args.no_numpy:
        baselines["numpy"] = NumpyCloth
    if args.warp:
        baselines["warp"] = lambda *a: WarpCloth(*a, device)
    if args.newton:
        baselines["newton"] = lambda *a: NewtonCloth(*a, device)

    rows = []
    for precision in args.precisions:
        config = tc.init(arch=args.arch, precision=precision, threads=args.threads)
        print(f"arch={config.arch} precision={precision} threads={args.threads or os.cpu_count()}: "
              f"median of {args.repeats} runs of >= {args.seconds} s", flush=True)
        for n in args.sizes:
            rows += measure_size(n, precision, args, baselines)
            print(f"  N={n} done (peak memory {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6:.2f} GB)",
                  flush=True)
    add_ratios(rows)
    print_table(rows)
    path = args.csv or Path(__file__).parent / "results" / f"throughput-{args.arch}.csv"
    write_csv(rows, path)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
