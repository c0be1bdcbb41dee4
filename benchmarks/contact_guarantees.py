"""What self-contact keeps, frame by frame, on the scenes of issue 56, and what it costs.

For each scene, with self-collision on (and, for the cost, off: the free step), every
`--every` steps: the edge-triangle crossings of the cloth (segment through triangle, sharing
no particle, by float64 orientation tests: Moller-Trumbore with a determinant filter), also
over the elements with no held particle alone (the never-through fail-safe's assumption),
and the closest far vertex-triangle pair (sharing no particle, and not mesh neighbours: a
particle of each on one mesh edge and under two thicknesses apart at rest, which
SelfCollision.keep_thickness leaves to the passes; also over those with no held particle),
both over candidate pairs a k-d tree finds within reach, and the most stretched mesh edge
(its length over its rest length: a fail-safe that froze particles while the cloth around
them moved on shows there); then the run's totals, the closest pair as a fraction of the
thickness, the particles the fail-safe moved back and those it left where a collider had
taken their step start (stayed), the most particles inside a collider at a checked step (a
negative Simulation.collider_distance: the demos' figures are closed animated meshes), the
checked run's wall time (checks included: compare it between fail-safes of one scene in one
run),
and the wall time per step with and without self-contact (medians of --repeats alternated
runs in this process, after a warm-up); each scene with each --fail-safe: on (never_through
and keep_thickness), through (never_through alone, the default), off (the contact
passes alone) and solve (never_through, the contacts also in xpbd's passes:
SelfCollision.in_solve; xpbd only).

Scenes (N particles a side: 16, 24 and 6 times --scale, or --size; the issue's sizes are
--scenes pile --size 64 --layers 16 and --scenes twist --size 128):
  pile     --layers sheets of N x N (0.5 m) dropped 4 cm apart onto a horizontal cylinder
  twist    an N x N sheet (0.6 m) whose two opposite edges turn opposite ways at pi/3 rad/s
           each, with no gravity, for 5 s (Newton's cloth_twist: 1.67 turns in all)
  press    a sheet pressed onto another by a handle, 6 mm over the ground, thickness 20 mm
           (the dense pile the docs report: no pass can make room)
  land     an N x N sheet of issue 53's denim (0.4 m) dropped 15 cm onto another (0.5 m) that
           lies on a ball: the large steps' case (--dt 1/60, and --integrator)
  ribbon   a 1.6 m x 0.12 m ribbon (5 N x 6 particles) built waved (height 0.35 + 0.2
           sin(2 pi x / 0.4) m: its rest shape), dropped on the ground for 2 s, folding onto
           itself; 1 cm thick (issue 56's unseen scene)
  cape     demos/cape.toml as it is (its own step, xpbd, thickness 4 mm and friction; its
           attached neck held), over its 3.3 s
  skirt    demos/skirt_walk.toml likewise (two panels sewn on a walking figure; particles its
           seams sew together count as one)
(all but the press, the ribbon and the demos 5 mm thick, or half the mean rest edge where
that is less, as SelfCollision asks of a mesh)

    python benchmarks/contact_guarantees.py [--scenes cape land pile press ribbon skirt twist]
                                            [--scale 1] [--size N] [--layers 4]
                                            [--fail-safe on off]
                                            [--integrator xpbd] [--dt 0.0041667]
                                            [--every 4] [--repeats 3] [--arch cpu]
                                            [--progress 0]

Every scene but the demos steps with --integrator (xpbd: 10 iterations; xpbd_bdf2: the same
on BDF2's step; any other integrator by its name, with its defaults) at --dt (1/240 s).
--scenes defaults to all but the demos.
"""

import argparse
import dataclasses
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

import ti_cloth as tc
from ti_cloth.app.scene import load_scene
from ti_cloth.inputs import limits

THICKNESS = 0.005
DEMOS = Path(__file__).resolve().parent.parent / "demos"


def sheet(n: int, size: float, origin, plane: str = "xz") -> tc.Cloth:
    return tc.Cloth(tc.grid_mesh(n, n, size=(size, size), plane=plane, origin=origin),
                    tc.Material.preset("cotton_springs"))


def pile(n: int, layers: int):
    body = tc.Cloth.combine([sheet(n, 0.5, (-0.25, 0.5 + 0.04 * k, -0.25))
                             for k in range(layers)])
    colliders = [tc.Capsule(a=(-0.5, 0.3, 0.0), b=(0.5, 0.3, 0.0), radius=0.1,
                            static_friction=0.3), tc.Plane(static_friction=0.5)]
    return body, dict(colliders=colliders), 1.5


TWIST_SPEED = np.pi / 3     # rad/s each edge turns, opposite ways (Newton's cloth_twist)
TWIST_SECONDS = 5.0         # Newton's example runs 300 frames at 60 fps: 1.67 turns in all


def twist(n: int, layers: int):
    body = sheet(n, 0.6, (0.0, 0.5, -0.3))
    x = body.particle_position
    handles = []
    for edge, sense in ((np.isclose(x[:, 0], 0.0), 1.0), (np.isclose(x[:, 0], 0.6), -1.0)):
        held = np.flatnonzero(edge)
        y, z = x[held, 1] - 0.5, x[held, 2]

        def turned(t, y=y, z=z, sense=sense):      # the edge's offsets, one row a particle
            a = sense * TWIST_SPEED * t
            return np.stack([np.zeros_like(y), y * np.cos(a) - z * np.sin(a) - y,
                             y * np.sin(a) + z * np.cos(a) - z], axis=1)
        handles.append(tc.Handle(held, turned))
    return body, dict(handles=handles, gravity=(0.0, 0.0, 0.0)), TWIST_SECONDS


def press(n: int, layers: int):
    lower = sheet(n, 0.3, (0.0, 0.0, 0.0))
    mesh = tc.grid_mesh(n, n, size=(0.2, 0.2), plane="xz")
    upper = tc.Cloth(tc.Mesh(mesh.vertices + [0.05, 0.05, 0.05], mesh.triangles),
                     tc.Material.preset("cotton_springs"))
    body = tc.Cloth.combine([lower, upper])
    count = n * n
    handle = tc.Handle(np.arange(count, 2 * count),
                       lambda t: (0.0, -min(t / 0.1, 1.0) * (0.05 - 0.006), 0.0))
    return body, dict(handles=[handle], colliders=[tc.Plane(thickness=0.0)]), 0.5


def land(n: int, layers: int):
    denim = dict(density=0.324, stretch=5e3, shear=1e3, bending=1e-4)
    lower = tc.Cloth(tc.grid_mesh(n, n, size=(0.5, 0.5), plane="xz", origin=(-0.25, 0.2, -0.25)),
                     tc.Fabric(**denim))
    upper = tc.Cloth(tc.grid_mesh(n, n, size=(0.4, 0.4), plane="xz", origin=(-0.2, 0.35, -0.2)),
                     tc.Fabric(**denim))
    colliders = [tc.Sphere(centre=(0.0, 0.1, 0.0), radius=0.1), tc.Plane()]
    return tc.Cloth.combine([lower, upper]), dict(colliders=colliders), 1.5


def ribbon(n: int, layers: int):
    """Issue 56's unseen scene as the issue describes it: a ribbon built waved, dropped on the
    ground, folding onto itself."""
    mesh = tc.grid_mesh(6, 5 * n, size=(1.6, 0.12), plane="xz", origin=(-0.8, 0.0, -0.06))
    x = mesh.vertices.copy()
    x[:, 1] = 0.35 + 0.2 * np.sin(x[:, 0] * 2.0 * np.pi / 0.4)     # its rest shape: waved
    body = tc.Cloth(tc.Mesh(x, mesh.triangles), tc.Material())
    return body, dict(colliders=[tc.Plane(static_friction=0.5)], drag=0.3), 2.0


def demo(file: str):
    """A demo's scene file as it is (its integrator, step, colliders, attachments and
    self-collision), with the fail-safe measured: (body, simulation(FAIL_SAFES' flags, or
    None: no self-collision), seconds, held particles, thickness)."""
    def build(n: int, layers: int, integrator: str, dt: float):
        scene = load_scene(DEMOS / file)
        held = np.concatenate([h.particles for h in scene.handles] or [[]]).astype(int)
        contact = scene.self_collision

        def simulation(flags):
            return dataclasses.replace(scene, self_collision=flags and dataclasses.replace(
                contact, **flags)).build()
        return scene.cloth, simulation, scene.frames / scene.fps, held, contact.thickness
    return build


def made(scene, thickness: float):
    """A scene above as demo() gives it, at --integrator and --dt; `thickness`, or half the
    mean rest edge where that is less (as SelfCollision asks of a mesh: warn_if_thick) but
    for the press (pressed on purpose)."""
    def build(n: int, layers: int, integrator: str, dt: float):
        body, options, seconds = scene(n, layers)
        held = np.concatenate([h.particles for h in options.get("handles", ())]
                              or [[]]).astype(int)
        chosen = {"xpbd": tc.XPBD(iterations=10),
                  "xpbd_bdf2": tc.XPBD(iterations=10, scheme="bdf2")}.get(integrator, integrator)
        kept = thickness
        if scene is not press:
            kept = min(kept, 0.5 * float(np.mean(rest_edges(body))))

        def simulation(flags):
            return tc.Simulation(body, dt=dt, integrator=chosen, self_collision=flags and
                                 tc.SelfCollision(thickness=kept, **flags), **options)
        return body, simulation, seconds, held, kept
    return build


def mesh_edges(triangles: np.ndarray) -> np.ndarray:
    """The triangles' edges, each once, as sorted particle pairs."""
    return np.unique(np.sort(triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)


def edge_key(a, b, count: int):
    """One integer for the particle pair (a, b) in either order, of `count` particles."""
    return np.minimum(a, b) * count + np.maximum(a, b)


def rest_edges(body) -> np.ndarray:
    """The rest lengths of the mesh's edges."""
    edges, x = mesh_edges(body.mesh.triangles), body.particle_position
    return np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1)


SCENES = {"pile": made(pile, THICKNESS), "twist": made(twist, THICKNESS),
          "press": made(press, 0.02), "land": made(land, THICKNESS),
          "ribbon": made(ribbon, 0.01),
          "cape": demo("cape.toml"), "skirt": demo("skirt_walk.toml")}
FAIL_SAFES = {"on": dict(never_through=True, keep_thickness=True),
              "through": dict(never_through=True, keep_thickness=False),     # the defaults
              "off": dict(never_through=False, keep_thickness=False),
              "solve": dict(never_through=True, keep_thickness=False, in_solve=True)}
SIDES = {"pile": 16, "twist": 24, "press": 6, "land": 16,     # particles a side at --scale 1
         "ribbon": 16}                                          # (the ribbon: 5 N along, 6 across)


def crossings(x: np.ndarray, triangles: np.ndarray, edges: np.ndarray, reach: float,
              weld: np.ndarray) -> int:
    """Edges through triangles they share no particle with (`weld`: each particle's
    representative among those a garment's seams sew together, which count as one;
    candidates: edge midpoints within `reach` of a triangle's centroid)."""
    tree = cKDTree(x[triangles].mean(axis=1))
    mids = x[edges].mean(axis=1)
    pairs = [(e, t) for e, near in enumerate(tree.query_ball_point(mids, reach)) for t in near]
    if not pairs:
        return 0
    e, t = np.array(pairs).T
    keep = ~(weld[edges[e]][:, :, None] == weld[triangles[t]][:, None, :]).any(axis=(1, 2))
    e, t = e[keep], t[keep]
    p, q = x[edges[e, 0]], x[edges[e, 1]]
    a, b, c = (x[triangles[t, k]] for k in range(3))
    e1, e2, d = b - a, c - a, q - p
    h = np.cross(d, e2)
    det = np.einsum("kd,kd->k", h, e1)
    ok = np.abs(det) > 1e-14
    det = np.where(ok, det, 1.0)
    s = p - a
    u = np.einsum("kd,kd->k", s, h) / det
    qv = np.cross(s, e1)
    v = np.einsum("kd,kd->k", qv, d) / det
    w = np.einsum("kd,kd->k", qv, e2) / det
    return int((ok & (u > 0) & (v > 0) & (u + v < 1) & (w > 0) & (w < 1)).sum())


def closest_far(x: np.ndarray, rest: np.ndarray, triangles: np.ndarray, reach: float,
                far: float, held: np.ndarray, weld: np.ndarray,
                edge_keys: np.ndarray) -> tuple[float, float]:
    """The nearest vertex-triangle distance over far pairs: sharing no particle (up to
    `weld`), and not mesh neighbours (the vertex on a mesh edge with a corner, `edge_keys`
    the mesh edges' edge_key, and nearer than `far` to the triangle in the rest shape:
    SelfCollision.keep_thickness leaves those to the passes); and over those of them with no
    `held` particle; inf when none is within `reach`."""
    tree = cKDTree(x[triangles].mean(axis=1))
    pairs = [(v, t) for v, near in enumerate(tree.query_ball_point(x, reach)) for t in near]
    if not pairs:
        return np.inf, np.inf
    v, t = np.array(pairs).T
    keep = ~(weld[triangles[t]] == weld[v][:, None]).any(axis=1)
    corners = triangles[t]
    joined = np.isin(edge_key(v[:, None], corners, len(x)), edge_keys).any(axis=1)
    rest_corners = rest[corners]
    keep &= ~joined | (point_triangle(rest[v], rest_corners[:, 0], rest_corners[:, 1],
                                      rest_corners[:, 2]) >= far)
    v, t = v[keep], t[keep]
    if not len(v):
        return np.inf, np.inf
    a, b, c = (x[triangles[t, k]] for k in range(3))
    distance = point_triangle(x[v], a, b, c)
    free = ~np.isin(v, held) & ~np.isin(triangles[t], held).any(axis=1)
    return float(distance.min()), float(distance[free].min()) if free.any() else np.inf


def point_triangle(p, a, b, c) -> np.ndarray:
    """Distances from points p to triangles (a, b, c) (Ericson, Real-Time Collision Detection
    5.1.5: the closest point by Voronoi regions, vectorised)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp, cp = p - b, p - c
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    denom = np.where(va + vb + vc == 0, 1.0, va + vb + vc)
    v, w = vb / denom, vc / denom
    closest = a + ab * v[:, None] + ac * w[:, None]                  # inside the face
    edge = [(d1 <= 0) & (d2 <= 0), (d3 >= 0) & (d4 <= d3), (d6 >= 0) & (d5 <= d6)]
    for region, point in zip(edge, (a, b, c)):
        closest = np.where(region[:, None], point, closest)
    for cond, start, direction, num, den in (
            ((vc <= 0) & (d1 >= 0) & (d3 <= 0), a, ab, d1, d1 - d3),
            ((vb <= 0) & (d2 >= 0) & (d6 <= 0), a, ac, d2, d2 - d6),
            ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), b, c - b, d4 - d3,
             (d4 - d3) + (d5 - d6))):
        s = np.clip(num / np.where(den == 0, 1.0, den), 0.0, 1.0)
        closest = np.where((cond & ~np.any(edge, axis=0))[:, None],
                           start + direction * s[:, None], closest)
    return np.linalg.norm(p - closest, axis=1)


def measure(name: str, n: int, layers: int, every: int, repeats: int,
            fail_safe: str, integrator: str, dt: float, progress: int = 0) -> dict:
    body, simulation, seconds, held, thickness = SCENES[name](n, layers, integrator, dt)
    triangles = body.mesh.triangles
    edges = mesh_edges(triangles)
    edge_keys = edge_key(edges[:, 0], edges[:, 1], body.particle_count)
    rest_length = rest_edges(body)
    reach = float(rest_length.max()) + 2 * thickness
    sims = {contact: simulation(FAIL_SAFES[fail_safe] if contact else None)
            for contact in (True, False)}
    steps = int(round(seconds / sims[True].dt))
    weld = np.asarray(body.particle_weld)
    free_triangles = triangles[~np.isin(triangles, held).any(axis=1)]
    free_edges = edges[~np.isin(edges, held).any(axis=1)]
    crossed, crossed_free, nearest, nearest_free, watched, inside = 0, 0, np.inf, np.inf, 0, 0
    stretched = 0.0
    sim = sims[True]
    start = time.perf_counter()
    for check in range(steps // every):
        sim.step(every)
        x = sim.positions()
        crossed += crossings(x, triangles, edges, reach, weld)
        crossed_free += crossings(x, free_triangles, free_edges, reach, weld)
        closest, closest_free = closest_far(x, body.particle_position, triangles, reach,
                                            2 * thickness, held, weld, edge_keys)
        nearest, nearest_free = min(nearest, closest), min(nearest_free, closest_free)
        inside = max(inside, int((sim.collider_distance(x)[0] < 0).sum()))
        stretched = max(stretched, float((np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1)
                                          / rest_length).max()))
        watched += 1
        if progress and (check + 1) % progress == 0:     # a long run at the sizes
            print(f"  {name}: step {(check + 1) * every} of {steps}, "
                  f"{time.perf_counter() - start:.0f} s, crossings {crossed}, closest far pair "
                  f"{nearest / thickness:.4f} thicknesses, most stretched edge "
                  f"{stretched:.2f}, moved back {sim.self_contacts().moved_back:,}, placed "
                  f"{sim.self_contacts().placed:,}",
                  file=sys.stderr, flush=True)
    run_s = time.perf_counter() - start
    report = sim.self_contacts()
    moved_back, placed, stayed = report.moved_back, report.placed, report.stayed
    cost = {True: [], False: []}
    for _ in range(repeats):
        for contact, timed in sims.items():
            timed.restart()
            timed.step(every)                        # warm: the list made, kernels compiled
            start = time.perf_counter()
            timed.step(4 * every)
            cost[contact].append((time.perf_counter() - start) / (4 * every))
    return dict(scene=name, moved_back=moved_back, placed=placed, stayed=stayed, inside=inside,
                run_s=run_s, stretched=stretched,
                particles=body.particle_count, thickness=thickness,
                frames=watched, crossings=crossed, free_crossings=crossed_free,
                closest=nearest / thickness, closest_free=nearest_free / thickness,
                contact_ms=1e3 * statistics.median(cost[True]),
                free_ms=1e3 * statistics.median(cost[False]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", choices=sorted(SCENES),
                        default=["land", "pile", "press", "ribbon", "twist"])
    parser.add_argument("--scale", type=int, default=1)
    parser.add_argument("--size", type=int, help="particles a side (overrides --scale)")
    parser.add_argument("--fail-safe", nargs="+", choices=sorted(FAIL_SAFES),
                        default=["on", "off"])
    parser.add_argument("--layers", type=int, default=4)
    parser.add_argument("--integrator", default="xpbd")
    parser.add_argument("--dt", type=float, default=1 / 240)
    parser.add_argument("--every", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--arch", default="cpu", choices=limits.ARCH_NAMES)
    parser.add_argument("--progress", type=int, default=0,
                        help="a line on stderr every this many checked frames (0: none)")
    args = parser.parse_args()
    tc.init(arch=args.arch, precision="f32")
    print(f"{args.integrator} at {args.dt:.4g} s on {args.arch}")
    print("| scene | fail-safe | particles | thickness | frames checked | crossings | "
          "of free elements | closest far pair / thickness | of free elements | "
          "most stretched edge | moved back | placed by a band | stayed | most inside a collider | "
          "run (checks included) | step with contact | free step | ratio |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.scenes:
        n = args.size or SIDES.get(name, 0) * args.scale
        for fail_safe in args.fail_safe:
            r = measure(name, n, args.layers, args.every, args.repeats, fail_safe,
                        args.integrator, args.dt, args.progress)
            print(f"| {r['scene']} | {fail_safe} | {r['particles']:,} | "
                  f"{r['thickness'] * 1e3:g} mm | {r['frames']} | {r['crossings']} | "
                  f"{r['free_crossings']} | {r['closest']:.4f} | {r['closest_free']:.4f} | "
                  f"{r['stretched']:.2f} | {r['moved_back']:,} | {r['placed']:,} | "
                  f"{r['stayed']:,} | {r['inside']} | "
                  f"{r['run_s']:.0f} s | {r['contact_ms']:.2f} ms | "
                  f"{r['free_ms']:.2f} ms | {r['contact_ms'] / r['free_ms']:.1f}x |",
                  flush=True)


if __name__ == "__main__":
    main()
