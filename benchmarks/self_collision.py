"""What self-collision costs a step, and where the time goes.

Two scenes per size N x N (a 1 m sheet), each timed with and without SelfCollision after a
warm-up that reaches the part of the motion measured (and compiles the contact kernels):
- swing: pinned at two corners, falling and swinging above a ground plane (little contact:
  the cost of watching), symplectic Euler at its automatic step and xpbd at 1/240 s;
- pile: dropped flat from 0.3 m onto a small sphere on the ground, so it drapes, folds and lands
  on itself (xpbd at 1/240 s, timed from 0.4 s, while it folds).
Medians of several runs; the ratio is measured in the same run. With --profile, the share of
each self-collision kernel and of the contact passes (the stage's phases, run by plan.run;
launches timed one by one, so the total is a little higher).

--scenes: scene files (the skirt and the cape demos), each stepped to --from seconds, then
frames timed alternately without self-collision, with it (each step's integrator and the
stages before self-collision in one team launch: Simulation's default), and with it launch by
launch per stage (plan="per stage", how such a step ran before): ms per frame, medians, and
the ratios within the run.

    python benchmarks/self_collision.py [--sizes 32 64 128] [--thickness 0.005] [--profile]
    python benchmarks/self_collision.py --sizes --scenes demos/skirt_walk.toml demos/cape.toml
"""

import argparse
import dataclasses
import statistics
import time
import types
import warnings

import ti_cloth as tc
from ti_cloth.app.scene import load_scene
from ti_cloth.contact import self_collision
from ti_cloth.contact.broad_phase import box_grid
from ti_cloth.inputs import limits

KERNELS = {self_collision: ("displacement_box", "sweep_boxes", "mean_edge", "list_pairs",
                            "prefix_pairs"),
           box_grid.BoxGrid: ("build",)}   # where the stage looks them up
PASSES = "contact passes"   # self_collision's plan.run: the stage's phases


def simulation(n, scene, integrator, contact):
    mesh = tc.grid_mesh(n, n, plane="xz")
    ground = tc.Plane(point=(0.0, -2.0 if scene == "swing" else 0.0, 0.0), static_friction=0.4)
    if scene == "swing":
        cloth = tc.Cloth(mesh, tc.Material(), pinned=[0, n - 1])
        colliders = [ground]
    else:
        cloth = tc.Cloth(tc.Mesh(mesh.vertices + [-0.5, 0.3, -0.5], mesh.triangles), tc.Material())
        colliders = [ground, tc.Sphere(centre=(0.1, 0.1, 0.0), radius=0.1, static_friction=0.4)]
    return tc.Simulation(cloth, integrator=integrator,
                         dt="auto" if integrator == "symplectic_euler" else 1 / 240,
                         colliders=colliders, self_collision=contact)


def warm_up_steps(sim, scene):
    return round(0.4 / sim.dt) if scene == "pile" else 60


def ms_per_step(sim, steps, repeats, warm_up):
    sim.step(warm_up)
    sim.step(steps)                  # untimed: compiles what the timed part meets first
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        sim.step(steps)
        sim.positions()
        times.append((time.perf_counter() - start) / steps * 1e3)
    return statistics.median(times)


def profile(sim, steps):
    """ms per step spent in each self-collision kernel (and the grid's builds)."""
    spent = {}
    originals = []

    def timed(module, name):
        kernel = getattr(module, name)
        originals.append((module, name, kernel))

        def run(*args, **kwargs):
            start = time.perf_counter()
            result = kernel(*args, **kwargs)
            spent[name] = spent.get(name, 0.0) + time.perf_counter() - start
            return result
        setattr(module, name, run)

    for module, names in KERNELS.items():
        for name in names:
            timed(module, name)
    plan = self_collision.plan
    passes = types.SimpleNamespace(run=plan.run)
    self_collision.plan = passes
    timed(passes, "run")
    try:
        sim.step(steps)
    finally:
        for module, name, kernel in originals:
            setattr(module, name, kernel)
        self_collision.plan = plan
    spent[PASSES] = spent.pop("run", 0.0)
    return {name: t / steps * 1e3 for name, t in sorted(spent.items(), key=lambda kv: -kv[1])}


def scene_frames(path, start: float, frames: int, repeats: int) -> None:
    """Print ms per frame of the scene at `path` without self-collision, with it, and with it
    launch by launch per stage (module doc)."""
    scene = load_scene(path)
    steps = scene.resolved_substeps()
    runs = {"free": (dataclasses.replace(scene, self_collision=None).build(), None),
            "self-collision": (scene.build(), None),
            "per stage": (scene.build(), "per stage")}
    times = {name: [] for name in runs}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")       # the passes' reports: not what is timed
        for sim, plan in runs.values():
            sim.step(round(start / scene.frame_dt) * steps, plan=plan)
        for _ in range(repeats):
            for name, (sim, plan) in runs.items():
                began = time.perf_counter()
                sim.step(frames * steps, plan=plan)
                sim.positions()
                times[name].append((time.perf_counter() - began) / frames * 1e3)
    ms = {name: statistics.median(values) for name, values in times.items()}
    print(f"{scene.name:>12} {scene.cloth.particle_count:>9} {steps:>6} {ms['free']:>9.1f} "
          f"{ms['self-collision']:>15.1f} {ms['per stage']:>10.1f} "
          f"{ms['self-collision'] / ms['free']:>11.2f} "
          f"{ms['per stage'] / ms['self-collision']:>17.2f} "
          f"{scene.frame_dt * 1e3 / ms['self-collision']:>10.2f}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[32, 64, 128])
    parser.add_argument("--arch", default="cpu", choices=limits.ARCH_NAMES)
    parser.add_argument("--precision", default="f32", choices=["f32", "f64"])
    parser.add_argument("--thickness", type=float, default=0.005)
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--profile", action="store_true")
    parser.add_argument("--scenes", nargs="*", default=[], help="scene files (module doc)")
    parser.add_argument("--from", dest="start", type=float, default=1.0,
                        help="seconds each scene runs before its frames are timed")
    parser.add_argument("--frames", type=int, default=5, help="frames per timed scene run")
    args = parser.parse_args(argv)
    tc.init(arch=args.arch, precision=args.precision)
    if args.scenes:
        print(f"scenes from t = {args.start:g} s, ms per frame, median of {args.repeats} runs "
              f"x {args.frames} frames, alternated")
        print(f"{'scene':>12} {'particles':>9} {'steps':>6} {'free':>9} {'self-collision':>15} "
              f"{'per stage':>10} {'/ free':>11} {'per stage / it':>17} {'real time':>10}")
        for path in args.scenes:
            scene_frames(path, args.start, args.frames, args.repeats)
    contact = tc.SelfCollision(thickness=args.thickness)
    if not args.sizes:
        return
    print(f"arch={args.arch} precision={args.precision} thickness={args.thickness} m, median of "
          f"{args.repeats} runs x {args.steps} steps")
    print(f"{'N':>5} {'scene':>6} {'integrator':>17} {'free ms/step':>13} "
          f"{'self-collision ms/step':>23} {'ratio':>6} {'pairs/particle':>15}")
    for n in args.sizes:
        for scene, integrator in (("swing", "symplectic_euler"), ("swing", "xpbd"),
                                  ("pile", "xpbd")):
            free_sim = simulation(n, scene, integrator, None)
            free = ms_per_step(free_sim, args.steps, args.repeats, warm_up_steps(free_sim, scene))
            sim = simulation(n, scene, integrator, contact)
            with_contact = ms_per_step(sim, args.steps, args.repeats, warm_up_steps(sim, scene))
            pairs = sim.self_collision.pair_total / sim.cloth.particle_count
            print(f"{n:>5} {scene:>6} {integrator:>17} {free:>13.3f} {with_contact:>23.3f} "
                  f"{with_contact / free:>6.1f} {pairs:>15.2f}")
            if args.profile:
                shares = profile(sim, args.steps)
                print("      " + ", ".join(f"{name} {ms:.3f}" for name, ms in shares.items()))


if __name__ == "__main__":
    main()
