"""Error against cost on one fabric scene: every ti_cloth solver beside Newton's
SolverSemiImplicit, SolverVBD and SolverXPBD, each against its own converged reference.

The scene (issue 53): a 0.5 m x 0.5 m sheet, N x N particles (grid_mesh, plane "xz"), of
tc.Fabric(density=0.324, stretch=5e3, shear=1e3, bending=1e-4), pinned at two adjacent corners
(particles 0 and N - 1), falling under gravity from rest, compared at t = 0.3 s (before it
snaps taut and turns chaotic: ../shared/notes/newton-1.8-cloth.md). Each run's error is the
largest and the root-mean-square particle distance from its simulator's reference at t = 0.3 s;
its cost is wall seconds per simulated second, the median of --repeats runs alternated with
every other run in this process (f32, CPU, compiled before timing).

References (printed with their own check, the same run at twice the step):
  ti_cloth   RK4 in f64 at half the symplectic stable step;
  Newton     SolverSemiImplicit at a quarter of that stable step (Newton has f32 only), on its
             FEM sheet (which SemiImplicit and VBD share) and on SolverXPBD's spring sheet.

Newton's sheet, converted (written down in ../shared/notes/newton-1.8-cloth.md): the same
vertices, triangles, lumped masses and pins (add_cloth_mesh); its triangle FEM is a stable
Neo-Hookean law whose linearisation C11 = mu + lambda_NH, C33 = mu matches the Fabric's stretch
(C11) and shear (C33) moduli with mu = tri_ke = shear and lambda_NH = stretch - shear, which
SemiImplicit reads as tri_ka = stretch - shear and VBD as tri_ka + tri_ke (tri_ka = stretch -
2 shear); its dihedral bending of rigidity D = 1e-4 N m on a grid of spacing h is edge_ke = D /
h^3 for SemiImplicit and D / h for VBD. SolverXPBD has no triangle constraint: its sheet is
add_cloth_mesh's springs on every edge (spring_ke = stretch), without bending (XPBD's and
SemiImplicit's dihedral constants mean different energies, so the reference would not be
XPBD's own sheet). Newton runs undamped (its tri_kd resists rigid rotation); ti_cloth keeps the
Fabric's default Rayleigh damping. The laws differ, so only each simulator's errors against its
own reference are compared, and their costs.

Prints, per size, every run, the Pareto front (cost against max error) of each simulator, and
the cheapest run under 1 cm, 1 mm and 0.1 mm with the ratio Newton / ti_cloth.

    python benchmarks/trade_vs_newton.py [--sizes 32 64] [--repeats 3] [--no-newton]
        [--only symplectic implicit_midpoint]

Needs newton 1.8 and warp-lang 1.19 beside ti_cloth (pip install "newton==1.8.0"
"warp-lang==1.19.*"), unless --no-newton; other versions are refused (peers.py).
"""

import argparse
import math
import statistics
import time

import numpy as np
import peers

import ti_cloth as tc
from ti_cloth.inputs import limits

NEWTON_CHECKED = ("1.8.",)
WARP_CHECKED = ("1.19.",)
SIZE, DENSITY, STRETCH, SHEAR, BENDING = 0.5, 0.324, 5e3, 1e3, 1e-4
DURATION = 0.3
LEVELS = (1e-2, 1e-3, 1e-4)
DIVERGED = 1.0        # [m]: a run this far from its reference flew apart (Newton's XPBD does)


def fabric_cloth(n: int) -> tc.Cloth:
    mesh = tc.grid_mesh(rows=n, cols=n, size=(SIZE, SIZE), plane="xz")
    return tc.Cloth(mesh, tc.Fabric(density=DENSITY, stretch=STRETCH, shear=SHEAR,
                                    bending=BENDING), pinned=[0, n - 1])


def steps_for(dt: float) -> tuple[int, float]:
    """Steps reaching DURATION, and the step that lands on it."""
    steps = max(1, round(DURATION / dt))
    return steps, DURATION / steps


class TiRun:
    """One ti_cloth configuration, kept compiled between timed runs (restart). On the CPU
    it is timed on each plan a long run chooses between (`plans`: one worker, a team of a
    worker per core), each plan always (stepping.ManySteps.adaptive off); measure() keeps the
    cheaper plan's median, the one a long run's timed choice settles on. (With the choice
    left adaptive, a run of a few launches spends some of them trying the other plan: the
    benchmark's third of three repeats ran on one worker.)"""

    def __init__(self, label: str, integrator, dt: float, cloth: tc.Cloth):
        self.label, self.simulator = label, "ti_cloth"
        self.steps, self.dt = steps_for(dt)
        self.sim = tc.Simulation(cloth, integrator=integrator, dt=self.dt)
        many = self.sim.many_steps
        self.plans = (None,) if many is None else tuple(sorted({1, many.workers}))

    def run(self, plan: int | None = None) -> tuple[np.ndarray, float]:
        many = self.sim.many_steps
        if plan is not None:
            many.adaptive, many.workers = False, plan
        self.sim.restart(self.dt)
        start = time.perf_counter()
        try:
            self.sim.step(self.steps)
        except tc.SimulationDiverged:
            return np.full((self.sim.cloth.particle_count, 3), math.inf), math.inf
        return self.sim.positions(), time.perf_counter() - start


class NewtonRun:
    """One Newton configuration (module doc: the conversion), rebuilt state per run."""

    def __init__(self, label: str, solver: str, iterations: int, dt: float, cloth: tc.Cloth,
                 n: int):
        import newton
        import warp as wp
        wp.config.quiet = True
        self.label, self.simulator, self.wp = label, "newton", wp
        self.steps, self.dt = steps_for(dt)
        spacing = SIZE / (n - 1)
        builder = newton.ModelBuilder(up_axis=newton.Axis.Y, gravity=(0.0, -9.81, 0.0))
        common = dict(pos=(0.0, 0.0, 0.0), rot=wp.quat_identity(), scale=1.0,
                      vel=(0.0, 0.0, 0.0), vertices=[tuple(v) for v in cloth.mesh.vertices],
                      indices=cloth.mesh.triangles.ravel().tolist(), density=DENSITY,
                      tri_kd=0.0, edge_kd=0.0, particle_radius=1e-5)
        if solver in ("xpbd", "springs"):       # XPBD's spring sheet, and its reference
            builder.add_cloth_mesh(**common, tri_ke=0.0, tri_ka=0.0, add_springs=True,
                                   spring_ke=STRETCH, spring_kd=0.0, edge_ke=0.0)
        else:
            lame = STRETCH - 2 * SHEAR
            builder.add_cloth_mesh(**common, tri_ke=SHEAR,
                                   tri_ka=lame if solver == "vbd" else lame + SHEAR,
                                   edge_ke=BENDING / spacing if solver == "vbd"
                                   else BENDING / spacing ** 3)
        for i in np.flatnonzero(cloth.pinned):
            builder.particle_mass[i] = 0.0
            builder.particle_flags[i] = 0     # not ACTIVE: VBD and XPBD leave it in place
        if solver == "vbd":
            builder.color(include_bending=True)
        self.model = builder.finalize(device="cpu")
        if solver in ("semi_implicit", "springs"):
            self.solver = newton.solvers.SolverSemiImplicit(self.model, enable_tri_contact=False)
        elif solver == "vbd":
            self.solver = newton.solvers.SolverVBD(self.model, iterations=iterations)
        else:
            self.solver = newton.solvers.SolverXPBD(self.model, iterations=iterations)
        self.control = self.model.control()
        self.plans = (None,)

    def run(self, plan: None = None) -> tuple[np.ndarray, float]:
        states = [self.model.state(), self.model.state()]
        start = time.perf_counter()
        for _ in range(self.steps):
            states[0].clear_forces()
            self.solver.step(states[0], states[1], self.control, None, self.dt)
            states.reverse()
        self.wp.synchronize_device("cpu")
        return states[0].particle_q.numpy().astype(np.float64), time.perf_counter() - start


def ti_reference(cloth: tc.Cloth, arch: str) -> np.ndarray:
    """RK4 in f64 at half the symplectic stable step, on the CPU whatever `arch` the runs take
    (on an H100 the 32² sheet's reference took over 100 s); prints the halving check and
    starts `arch` in f32 again."""
    tc.init(arch="cpu", precision="f64")
    dt = 0.5 * tc.stable_dt(cloth, "symplectic_euler", 0.0, pinned=cloth.pinned)
    results = []
    for h in (dt, 2 * dt):
        run = TiRun("reference", "rk4", h, cloth)
        results.append(run.run()[0])
        del run
    print(f"  ti_cloth reference: RK4 f64, dt {dt:.3g} s; against twice that "
          f"step {1e3 * np.abs(results[0] - results[1]).max():.3g} mm")
    tc.init(arch=arch, precision="f32")
    return results[0]


def newton_reference(cloth: tc.Cloth, n: int, solver: str) -> np.ndarray:
    """SemiImplicit at a quarter of ti_cloth's symplectic stable step (the conversion keeps
    the wave speeds, so about its own) on the FEM sheet ("semi_implicit") or on XPBD's spring
    sheet ("springs"); prints the halving check."""
    dt = 0.25 * tc.stable_dt(cloth, "symplectic_euler", 0.0, pinned=cloth.pinned)
    results = [NewtonRun("reference", solver, 1, h, cloth, n).run()[0] for h in (dt, 2 * dt)]
    print(f"  Newton {solver} reference: dt {dt:.3g} s; against twice that step "
          f"{1e3 * np.abs(results[0] - results[1]).max():.3g} mm")
    return results[0]


def configurations(cloth: tc.Cloth, n: int, newton: bool, only: tuple = ("",)) -> list:
    """(label, maker) of every run: ti_cloth's solvers over their useful steps (those whose
    label holds a word of `only`), Newton's."""
    stable = tc.stable_dt(cloth, "symplectic_euler", 0.0, pinned=cloth.pinned)
    runs = [(f"symplectic_euler h={f:g}x stable", "symplectic_euler", f * stable)
            for f in (0.95, 0.5)]
    runs += [(f"verlet h={f:g}x stable", "verlet", f * stable) for f in (0.95,)]
    runs += [(f"rk4 h={f:g}x stable", "rk4", f * stable) for f in (1.3,)]
    # six stages fitted to the damped spectrum (integrators/stabilized_rk2.py), at its own limit
    limit = tc.stable_dt(cloth, "stabilized_rk2", 0.0, pinned=cloth.pinned)
    runs += [(f"stabilized_rk2 h={f:g}x stable", "stabilized_rk2", f * limit) for f in (0.95, 0.5)]
    runs += [(f"implicit_euler 1/{r}", tc.ImplicitEuler(tolerance=1e-3), 1 / r) for r in (60, 240, 960)]
    runs += [(f"xpbd {it} it 1/{r}", tc.XPBD(iterations=it), 1 / r)
             for it, r in ((2, 60), (10, 240), (4, 3840))]
    # its bending swept in every pass (as before XPBD.bending_tolerance): the trade it makes
    runs += [(f"xpbd every pass {it} it 1/{r}", tc.XPBD(iterations=it, bending_tolerance=0.0),
              1 / r) for it, r in ((2, 60), (10, 240), (4, 3840))]
    # its membrane passes over-relaxed (XPBD.membrane_relaxation)
    runs += [(f"xpbd relaxed 1.5 {it} it 1/{r}", tc.XPBD(iterations=it, membrane_relaxation=1.5),
              1 / r) for it, r in ((2, 60), (10, 240), (4, 3840))]
    # its passes on BDF2's step (XPBD.scheme), plain and over-relaxed
    runs += [(f"xpbd bdf2 {it} it 1/{r}", tc.XPBD(iterations=it, scheme="bdf2"), 1 / r)
             for it, r in ((2, 60), (10, 240), (4, 3840))]
    runs += [(f"xpbd bdf2 relaxed 1.5 {it} it 1/{r}", tc.XPBD(
        iterations=it, membrane_relaxation=1.5, scheme="bdf2"), 1 / r)
        for it, r in ((2, 60), (10, 240), (4, 3840))]
    # and tethered to the pins (XPBD.tethers: strain 0.1 %, and 0, 0.3 % and the body's beside)
    runs += [(f"xpbd tethered {s} {it} it 1/{r}", tc.XPBD(
        iterations=it, membrane_relaxation=1.5, scheme="bdf2", tethers=s), 1 / r)
        for s, it, r in ((1e-3, 4, 120), (1e-3, 10, 120), (1e-3, 6, 240), (1e-3, 7, 240),
                         (1e-3, 8, 240), (1e-3, 10, 240), (1e-3, 3, 400), (1e-3, 2, 480),
                         (1e-3, 2, 960), (1e-3, 1, 1600), (1e-3, 1, 1920),
                         (1e-3, 20, 240), (0.0, 10, 240), (3e-3, 10, 240), ("auto", 10, 240))]
    for name, cls in (("implicit_midpoint", tc.ImplicitMidpoint), ("tr_bdf2", tc.TRBDF2)):
        runs += [(f"{name} 1/{r}", cls(tolerance=1e-4, cg_tolerance=1e-1), 1 / r)
                 for r in (60, 120, 240)]
        runs += [(f"{name} tight 1/{r}", cls(tolerance=1e-5, cg_tolerance=1e-2), 1 / r)
                 for r in (240, 480)]
    # the CG preconditioned by the diagonal alone (the default adds a coarse level: coarse.py)
    runs += [(f"implicit_midpoint jacobi 1/{r}", tc.ImplicitMidpoint(
        tolerance=1e-4, cg_tolerance=1e-1, preconditioner="jacobi"), 1 / r) for r in (60, 120)]
    runs += [("implicit_midpoint jacobi tight 1/480", tc.ImplicitMidpoint(
        tolerance=1e-5, cg_tolerance=1e-2, preconditioner="jacobi"), 1 / 480)]
    runs += [("implicit_euler jacobi 1/60", tc.ImplicitEuler(tolerance=1e-3,
                                                              preconditioner="jacobi"), 1 / 60)]
    runs = [run for run in runs if any(word in run[0] for word in only)]
    made = [(label, lambda l=label, i=integ, h=dt: TiRun(l, i, h, cloth))
            for label, integ, dt in runs]
    if newton:
        made += [(f"newton semi_implicit h={f:g}x stable",
                  lambda f=f: NewtonRun(f"newton semi_implicit h={f:g}x stable",
                                        "semi_implicit", 1, f * stable, cloth, n))
                 for f in (0.9, 0.45)]
        made += [(f"newton vbd {it} it 1/{r}",
                  lambda it=it, r=r: NewtonRun(f"newton vbd {it} it 1/{r}", "vbd", it, 1 / r,
                                               cloth, n))
                 for it, r in ((1, 60), (10, 60), (10, 240), (5, 960))]
        made += [(f"newton xpbd {it} it 1/{r}",
                  lambda it=it, r=r: NewtonRun(f"newton xpbd {it} it 1/{r}", "xpbd", it,
                                               1 / r, cloth, n))
                 for it, r in ((2, 60), (10, 240), (4, 3840))]
    return made


def pareto(rows: list[dict]) -> list[dict]:
    """The rows no other row beats in both cost and max error, cheapest first (runs that
    diverged left out)."""
    front, best = [], DIVERGED
    for row in sorted(rows, key=lambda r: (r["cost"], r["max"])):
        if row["max"] < best:
            front.append(row)
            best = row["max"]
    return front


def cheapest(rows: list[dict], level: float) -> dict | None:
    within = [r for r in rows if r["max"] <= level]
    return min(within, key=lambda r: r["cost"]) if within else None


def measure(n: int, repeats: int, newton: bool, only: tuple = ("",),
            arch: str = "cpu") -> list[dict]:
    cloth = fabric_cloth(n)
    print(f"\n## {n} x {n} ({n * n} particles)")
    references = {"ti_cloth": ti_reference(cloth, arch)}
    if newton:
        references["newton"] = newton_reference(cloth, n, "semi_implicit")
        references["newton xpbd"] = newton_reference(cloth, n, "springs")
    runs = [make() for _, make in configurations(cloth, n, newton, only)]
    positions = {}
    for run in runs:                                 # compile, and the run's positions
        positions[run.label] = run.run()[0]
    walls = {(run.label, plan): [] for run in runs for plan in run.plans}
    for _ in range(repeats):                         # alternated: a drift hits every run
        for run in runs:
            for plan in run.plans:
                walls[run.label, plan].append(run.run(plan)[1])
    rows = []
    for run in runs:
        key = ("newton xpbd" if run.label.startswith("newton xpbd") else run.simulator)
        x = positions[run.label]
        costs = [statistics.median(walls[run.label, plan]) / DURATION for plan in run.plans]
        error = (np.linalg.norm(x - references[key], axis=1) if np.isfinite(x).all()
                 else np.full(len(x), math.inf))
        rows.append({"simulator": run.simulator, "label": run.label, "dt": run.dt,
                     "max": float(error.max()), "rms": float(np.sqrt((error ** 2).mean())),
                     "cost": min(costs),
                     "plans": " / ".join(f"{cost:.3g}" for cost in costs)})
    workers = "cost on 1 / a team of workers"
    print(f"\n| run | dt [s] | max error [mm] | RMS error [mm] | cost [s/s] | {workers} |"
          "\n|---|---|---|---|---|---|")
    for row in rows:
        if row["max"] > DIVERGED:
            print(f"| {row['label']} | {row['dt']:.3g} | diverged | | {row['cost']:.3g} | "
                  f"{row['plans']} |")
            continue
        print(f"| {row['label']} | {row['dt']:.3g} | {1e3 * row['max']:.3g} | "
              f"{1e3 * row['rms']:.3g} | {row['cost']:.3g} | {row['plans']} |")
    for simulator in ("ti_cloth", "newton") if newton else ("ti_cloth",):
        front = pareto([r for r in rows if r["simulator"] == simulator])
        print(f"\nPareto front, {simulator}: " + "; ".join(
            f"{r['label']} ({1e3 * r['max']:.3g} mm, {r['cost']:.3g} s/s)" for r in front))
    print("\n| max error | ti_cloth's cheapest | cost | Newton's cheapest | cost | Newton / ti_cloth |"
          "\n|---|---|---|---|---|---|")
    for level in LEVELS:
        ours = cheapest([r for r in rows if r["simulator"] == "ti_cloth"], level)
        theirs = cheapest([r for r in rows if r["simulator"] == "newton"], level) if newton else None
        ratio = f"{theirs['cost'] / ours['cost']:.3g}" if ours and theirs else "-"
        print(f"| {1e3 * level:g} mm | {ours['label'] if ours else 'none'} | "
              f"{ours['cost']:.3g} | " if ours else f"| {1e3 * level:g} mm | none | - | ", end="")
        print(f"{theirs['label']} | {theirs['cost']:.3g} | {ratio} |" if theirs
              else f"none | - | {ratio} |")
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-newton", action="store_true")
    parser.add_argument("--only", nargs="+", default=[""],
                        help="ti_cloth's runs whose label holds one of these words")
    parser.add_argument("--arch", default="cpu", choices=limits.ARCH_NAMES,
                        help="ti_cloth's (Newton's runs stay on the CPU)")
    args = parser.parse_args()
    newton = not args.no_newton
    if newton:
        peers.require("newton", NEWTON_CHECKED, "trade_vs_newton.py")
        peers.require("warp-lang", WARP_CHECKED, "trade_vs_newton.py")
    tc.init(arch=args.arch, precision="f32")
    print(f"ti_cloth on {args.arch}, f32; error at t = {DURATION} s; cost = wall s "
          f"per simulated s, median of {args.repeats} alternated runs (ti_cloth: of its "
          f"cheaper plan, one worker or a team)")
    for n in args.sizes:
        measure(n, args.repeats, newton, tuple(args.only), args.arch)


if __name__ == "__main__":
    main()
