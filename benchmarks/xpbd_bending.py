"""XPBD's bending passes: what sweeping a Fabric's mid-edge bending only in the passes each
triangle needs (XPBD.bending_tolerance; energies/bending.py passes_needed) saves and changes.

Sheets: an N x N, 0.5 m sheet hanging from two adjacent corners, falling from rest for
--duration s: "denim" is Fabric.preset("denim") (its BendingCurve: the mid-edge tangents),
"issue 53" issue 53's flat denim-like Fabric(density=0.324, stretch=5e3, shear=1e3,
bending=1e-4) (flat: the isometric model, swept in every pass whatever the tolerance), and
"bending B" that fabric with bending=B on the sheet rippled 0.2 mm at rest (curved: the
mid-edge tangents). Scenes (--scenes, e.g.
demos/cape.toml): the scene's own integrator passes and step, from its start for --duration
s, with and without its self-collision (--free).

For each sheet or scene and step (--dts), XPBD with --iterations passes at each tolerance
(0: every pass, as before) is run in turn --repeats times in this process (f32, CPU): cost in
wall seconds per simulated second (medians), its ratio to the every-pass run's in the same
round, and at the end the largest particle distance from the every-pass run and (sheets)
from a run of --reference passes of every term, which is what the passes themselves miss.

    python benchmarks/xpbd_bending.py [--size 32] [--dts 0.0041667 0.016667]
        [--tolerances 0 0.2 0.1 0.05 0.01] [--scenes demos/cape.toml --free]
"""

import argparse
import dataclasses
import statistics
import time
import warnings

import numpy as np

import ti_cloth as tc
from ti_cloth.app.scene import load_scene


def sheets(n: int, bendings) -> dict[str, tc.Cloth]:
    mesh = tc.grid_mesh(rows=n, cols=n, size=(0.5, 0.5), plane="xz")
    x = mesh.vertices.copy()
    x[:, 1] += 2e-4 * np.sin(9 * x[:, 0]) * np.sin(7 * x[:, 2])
    rippled = tc.Mesh(x, mesh.triangles)
    out = {"denim": tc.Cloth(mesh, tc.Fabric.preset("denim"), pinned=[0, n - 1]),
           "issue 53": tc.Cloth(mesh, tc.Fabric(density=0.324, stretch=5e3, shear=1e3,
                                                bending=1e-4), pinned=[0, n - 1])}
    for b in bendings:
        fabric = tc.Fabric(density=0.324, stretch=5e3, shear=1e3, bending=b)
        out[f"bending {b:g}"] = tc.Cloth(rippled, fabric, pinned=[0, n - 1])
    return out


def timed(build, tolerances, iterations, dt, duration, repeats):
    """{tolerance: (median s/s, median ratio to tolerance 0, final positions)}."""
    steps = max(1, round(duration / dt))
    costs = {t: [] for t in tolerances}
    final = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")      # the contact passes' reports: not what is timed
        for _ in range(repeats):
            for t in tolerances:
                sim = build(tc.XPBD(iterations=iterations, bending_tolerance=t), dt)
                sim.step(1)                  # compiles
                began = time.perf_counter()
                sim.step(steps - 1)
                final[t] = sim.positions()
                costs[t].append((time.perf_counter() - began) / ((steps - 1) * dt))
    every = costs[0.0]
    return {t: (statistics.median(c), statistics.median(a / b for a, b in zip(c, every)),
                final[t]) for t, c in costs.items()}


def largest(a, b) -> float:
    return float(np.linalg.norm(a - b, axis=1).max())


def report(name, dt, rows, reference=None) -> None:
    every = rows[0.0][2]
    missed = f"{largest(every, reference) * 1e3:8.1f}" if reference is not None else "       -"
    for t, (cost, ratio, x) in rows.items():
        print(f"| {name:>16} | 1/{1 / dt:<5.0f} | {t:>9g} | {cost:7.3f} | {ratio:5.2f} | "
              f"{largest(x, every) * 1e3:9.3f} | {missed} |")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=32)
    parser.add_argument("--bendings", type=float, nargs="*", default=[1e-4, 1e-3, 1e-2])
    parser.add_argument("--dts", type=float, nargs="+", default=[1 / 240, 1 / 60])
    parser.add_argument("--tolerances", type=float, nargs="+", default=[0.2, 0.1, 0.05, 0.01])
    parser.add_argument("--iterations", type=int, default=10)
    parser.add_argument("--reference", type=int, default=200)
    parser.add_argument("--duration", type=float, default=0.3)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--scenes", nargs="*", default=[])
    parser.add_argument("--free", action="store_true", help="the scenes without self-collision too")
    args = parser.parse_args(argv)
    tc.init(arch="cpu", precision="f32")
    tolerances = [0.0] + [t for t in args.tolerances if t != 0.0]
    print("| run | step | tolerance | s/s | ratio | from every pass [mm] | every pass from "
          f"{args.reference} passes [mm] |\n|---|---|---|---|---|---|---|")
    for name, cloth in (sheets(args.size, args.bendings) if args.size else {}).items():
        for dt in args.dts:
            def build(integrator, step, cloth=cloth):
                return tc.Simulation(cloth, integrator=integrator, dt=step)
            reference = build(tc.XPBD(iterations=args.reference, bending_tolerance=0.0), dt)
            reference.step(max(1, round(args.duration / dt)))
            report(name, dt, timed(build, tolerances, args.iterations, dt, args.duration,
                                   args.repeats), reference.positions())
    for path in args.scenes:
        scene = load_scene(path)
        variants = {scene.name: scene}
        if args.free and scene.self_collision is not None:
            variants[f"{scene.name}, free"] = dataclasses.replace(scene, self_collision=None)
        for name, s in variants.items():
            dt = s.frame_dt / s.resolved_substeps()
            iterations = getattr(s.integrator, "iterations", args.iterations)
            rows = timed(lambda integrator, step, s=s: s.build(integrator, dt=step), tolerances,
                         iterations, dt, args.duration, args.repeats)
            report(name, dt, rows)


if __name__ == "__main__":
    main()
