"""What a mesh collider costs a step next to the analytic shape it stands for, and how long its
distance grid takes to build.

Step cost: an N x N, 1 m cloth dropped 5 cm onto a sphere of radius 0.3 m and timed while it
drapes (most particles touching or near), with no collider, the analytic Sphere, and the same
sphere as a MeshCollider (an icosphere of 5,120 triangles, grid resolution 64); and moving: the
sphere bobbing along a path against the mesh turning (both place their collider every step);
symplectic Euler at its automatic step and xpbd at 1/240 s. The variants are timed in
turn, several rounds, and the medians compared (ratios within one run).

Build: the grid of an icosphere of 5,120 triangles, an open terrain of 49,928 and an icosphere
of 81,920 at resolutions 64 and 128, from scratch (libigl) and read back from the disk cache.

    python benchmarks/mesh_collider.py [--sizes 64 128] [--arch cpu] [--repeats 5]
"""

import argparse
import os
import statistics
import tempfile
import time

import numpy as np

import ti_cloth as tc
from ti_cloth.contact.colliders import sdf
from ti_cloth.inputs import limits

RADIUS, CENTRE = 0.3, (0.0, 0.0, 0.0)


def colliders(variant):
    if variant == "none":
        return []
    if variant.startswith("sphere"):
        bobbing = (lambda t: (0.0, 0.01 * np.sin(t), 0.0)) if variant == "sphere, moving" else None
        return [tc.Sphere(centre=CENTRE, radius=RADIUS, thickness=0.01, static_friction=0.4,
                          path=bobbing)]
    turning = (lambda t: (0.0, 0.5 * t, 0.0)) if variant == "mesh, turning" else None
    return [tc.MeshCollider(tc.sphere_mesh(RADIUS, CENTRE, subdivisions=4), thickness=0.01,
                            static_friction=0.4, rotation=turning)]


def simulation(n, integrator, variant):
    mesh = tc.grid_mesh(n, n, plane="xz", origin=(-0.5, RADIUS + 0.06, -0.5))
    cloth = tc.Cloth(mesh, tc.Material())
    return tc.Simulation(cloth, integrator=integrator,
                         dt="auto" if integrator == "symplectic_euler" else 1 / 240,
                         colliders=colliders(variant))


def step_costs(build, variants, steps, repeats):
    """{variant: median ms per step} of the simulations build(variant) makes, each warmed up
    until the cloth has landed (0.15 s), then timed in turn with the others (big launches on
    the team always, so that no round takes the other plan)."""
    sims = {v: build(v) for v in variants}
    for sim in sims.values():
        if sim.many_steps is not None:
            sim.many_steps.adaptive = False   # the team always: no plan flips between rounds
        sim.step(round(0.15 / sim.dt))
        sim.step(steps)                  # untimed: compiles what the timed launches meet
    times = {v: [] for v in variants}
    for _ in range(repeats):
        for variant, sim in sims.items():
            start = time.perf_counter()
            sim.step(steps)
            sim.positions()
            times[variant].append((time.perf_counter() - start) / steps * 1e3)
    return {v: statistics.median(t) for v, t in times.items()}


def terrain(n=159):
    """An open height field of 2 (n - 1)^2 triangles over a 1 m square."""
    mesh = tc.grid_mesh(n, n, plane="xz", origin=(-0.5, 0.0, -0.5))
    x = mesh.vertices.copy()
    x[:, 1] = 0.05 * np.sin(9 * x[:, 0]) * np.cos(7 * x[:, 2])
    return tc.Mesh(x, mesh.triangles)


def build_times(resolutions, repeats):
    meshes = {"icosphere": tc.sphere_mesh(RADIUS, CENTRE, subdivisions=4), "terrain": terrain(),
              "icosphere ": tc.sphere_mesh(RADIUS, CENTRE, subdivisions=6)}
    rows = []
    for name, mesh in meshes.items():
        for resolution in resolutions:
            collider = tc.MeshCollider(mesh, resolution=resolution, thickness=0.05)
            cold, cached = [], []
            for _ in range(repeats):
                with tempfile.TemporaryDirectory() as folder:
                    sdf.clear_memory_cache()
                    os.environ["TI_CLOTH_CACHE"] = folder
                    start = time.perf_counter()
                    grid = collider.grid()
                    cold.append(time.perf_counter() - start)
                    sdf.clear_memory_cache()
                    start = time.perf_counter()
                    collider.grid()
                    cached.append(time.perf_counter() - start)
            rows.append((name.strip(), mesh.triangle_count, resolution, grid.shape,
                         statistics.median(cold), statistics.median(cached)))
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 128])
    parser.add_argument("--arch", default="cpu", choices=limits.ARCH_NAMES)
    parser.add_argument("--precision", default="f32", choices=["f32", "f64"])
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--resolutions", type=int, nargs="+", default=[64, 128])
    parser.add_argument("--no-build", action="store_true", help="skip the grid build timings")
    args = parser.parse_args(argv)
    tc.init(arch=args.arch, precision=args.precision)
    variants = ("none", "sphere", "mesh", "sphere, moving", "mesh, turning")
    print(f"arch={args.arch} precision={args.precision}; ms per step, median of {args.repeats} "
          f"rounds x {args.steps} steps")
    print(f"{'N':>5} {'integrator':>17} " + " ".join(f"{v:>14}" for v in variants)
          + f" {'mesh/sphere':>12} {'turning/moving':>15}")
    for n in args.sizes:
        for integrator in ("symplectic_euler", "xpbd"):
            ms = step_costs(lambda v: simulation(n, integrator, v), variants, args.steps,
                            args.repeats)
            print(f"{n:>5} {integrator:>17} " + " ".join(f"{ms[v]:>14.3f}" for v in variants)
                  + f" {ms['mesh'] / ms['sphere']:>12.2f}"
                  f" {ms['mesh, turning'] / ms['sphere, moving']:>15.2f}")
    if not args.no_build:
        print(f"\ngrid builds, median of {min(args.repeats, 3)}")
        print(f"{'mesh':>10} {'triangles':>10} {'resolution':>11} {'nodes':>16} "
              f"{'build s':>8} {'cached s':>9}")
        for name, triangles, resolution, shape, cold, cached in build_times(
                args.resolutions, min(args.repeats, 3)):
            print(f"{name:>10} {triangles:>10,} {resolution:>11} {str(shape):>16} {cold:>8.2f} "
                  f"{cached:>9.3f}")


if __name__ == "__main__":
    main()
