"""What an animated (deforming) mesh collider costs a step: an N x N, 1 m cloth dropped onto a
breathing icosphere of 5,120 triangles (radius 0.3 m swinging +-10 % twice a second), timed
while it drapes, against the same cloth with no collider and with the rigid MeshCollider of the
same sphere turning (its distance grid). The animated sphere is given as samples at 60 fps
and as a callable (which Python evaluates at every step); the sphere's edges are too blunt
to pass between the cloth's particles, so edge_contact="auto" tests none of them: the
samples are timed again with edge_contact=True (every edge, animated_edges.py). Symplectic Euler at its automatic
step and xpbd at 1/240 s; the variants are timed in turn, several rounds, medians compared
(ratios within one run: mesh_collider.step_costs).

    python benchmarks/animated_collider.py [--sizes 64] [--arch cpu] [--repeats 5]
"""

import argparse

import numpy as np
from mesh_collider import CENTRE, RADIUS, step_costs

import ti_cloth as tc
from ti_cloth.inputs import limits

SPHERE = tc.sphere_mesh(RADIUS, CENTRE, subdivisions=4)
FPS = 60


def breathing(t):
    return CENTRE + (SPHERE.vertices - CENTRE) * (1.0 + 0.1 * np.sin(4 * np.pi * t))


def colliders(variant):
    options = dict(thickness=0.01, static_friction=0.4)
    if variant == "none":
        return []
    if variant == "rigid, turning":
        return [tc.MeshCollider(SPHERE, rotation=lambda t: (0.0, 0.5 * t, 0.0), **options)]
    if variant.startswith("samples"):
        samples = np.stack([breathing(k / FPS) for k in range(10 * FPS)])
        return [tc.AnimatedMeshCollider(SPHERE, samples, fps=FPS,
                                        edge_contact=True if variant.endswith("every edge") else "auto",
                                        **options)]
    return [tc.AnimatedMeshCollider(SPHERE, breathing, **options)]


def simulation(n, integrator, variant):
    mesh = tc.grid_mesh(n, n, plane="xz", origin=(-0.5, 1.1 * RADIUS + 0.06, -0.5))
    return tc.Simulation(tc.Cloth(mesh, tc.Material()), integrator=integrator,
                         dt="auto" if integrator == "symplectic_euler" else 1 / 240,
                         colliders=colliders(variant))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64])
    parser.add_argument("--arch", default="cpu", choices=limits.ARCH_NAMES)
    parser.add_argument("--precision", default="f32", choices=["f32", "f64"])
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    tc.init(arch=args.arch, precision=args.precision)
    variants = ("none", "rigid, turning", "samples", "samples, every edge", "callable")
    print(f"arch={args.arch} precision={args.precision}; ms per step, median of {args.repeats} "
          f"rounds x {args.steps} steps; {SPHERE.triangle_count:,} triangles")
    print(f"{'N':>5} {'integrator':>17} " + " ".join(f"{v:>17}" for v in variants)
          + f" {'samples/none':>13} {'every edge/none':>15} {'callable/none':>14}")
    for n in args.sizes:
        for integrator in ("symplectic_euler", "xpbd"):
            ms = step_costs(lambda v: simulation(n, integrator, v), variants, args.steps,
                            args.repeats)
            print(f"{n:>5} {integrator:>17} " + " ".join(f"{ms[v]:>17.3f}" for v in variants)
                  + f" {ms['samples'] / ms['none']:>13.2f}"
                  f" {ms['samples, every edge'] / ms['none']:>15.2f}"
                  f" {ms['callable'] / ms['none']:>14.2f}", flush=True)


if __name__ == "__main__":
    main()
