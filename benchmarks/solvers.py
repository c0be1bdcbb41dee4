"""Steps per second of every integrator through Simulation.step, on a free cloth and on the
same cloth with a ground plane and a sphere collider (issue 22's table), each measurement in
a fresh process so that one process's luck (how the OS placed its threads) does not decide it.

The scene: an N x N sheet (1 m, stretch + shear + bend springs, default Material), two corners
pinned, hanging in gravity over a sphere (r = 0.2 m) resting on a plane. Steps: 1/240 s for
the integrators without a step limit (pbd, xpbd with 10 passes, implicit Euler), half the
predicted stable step for the others (stability.auto_dt). Each process runs --repeats calls of
step(n) with n steps taking about --seconds, after a warm-up, and reports the medians (and of
the ratios); the table gives min / median / max over --processes processes.

With --baseline DIR (a checkout of an earlier ti_cloth, e.g. `git worktree add /tmp/base
<commit>`), every process is run once with that checkout's package and once with this one,
alternating, and the table gives both and the ratio of their medians.

    python benchmarks/solvers.py [--sizes 64 128] [--integrators ...] [--processes 3]
        [--threads 2] [--arch cpu] [--baseline DIR] [--strain-limit 0.1]
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import ti_cloth as tc

LONG_STEP = 1 / 240
UNLIMITED = ("pbd", "xpbd", "implicit_euler")


def scene(n: int, integrator: str, colliders: bool, strain: float | None = None) -> tc.Simulation:
    cloth = tc.Cloth(tc.grid_mesh(n, n, plane="xz"), tc.Material(), pinned=[0, n - 1])
    shapes = [tc.Plane(point=(0, -0.6, 0), normal=(0, 1, 0), thickness=0.002, static_friction=0.3),
              tc.Sphere(centre=(0.5, -0.4, 0.5), radius=0.2, thickness=0.002,
                        static_friction=0.3)] if colliders else []
    return tc.Simulation(cloth, integrator=integrator, colliders=shapes,
                         strain_limit=None if strain is None else tc.StrainLimit(max_strain=strain),
                         dt=LONG_STEP if integrator in UNLIMITED else "auto")


def timed(sim: tc.Simulation, steps: int) -> float:
    """Seconds of sim.step(steps) from rest."""
    sim.restart()
    start = time.perf_counter()
    sim.step(steps)
    sim.state.first_bad_step[None]
    return time.perf_counter() - start


def measure(n: int, integrator: str, seconds: float, repeats: int,
            strain: float | None = None) -> dict:
    """Median steps/s of `repeats` calls of about `seconds` each, free and with colliders,
    the two timed in turn, and the median ratio (with / free) of the pairs: the process's
    own swing (see benchmarks/README.md) cancels in it."""
    sims = [scene(n, integrator, colliders, strain) for colliders in (False, True)]
    steps, elapsed = 2, 0.0
    for sim in sims:
        sim.step(2)
    while elapsed < seconds / 4:
        steps *= 2
        elapsed = max(timed(sim, steps) for sim in sims)
    steps = max(2, int(steps * seconds / elapsed))
    rates = [[], []]
    for _ in range(repeats):
        for sim, kept in zip(sims, rates):
            kept.append(steps / timed(sim, steps))
    return {"0": statistics.median(rates[0]), "1": statistics.median(rates[1]),
            "ratio": statistics.median(w / f for f, w in zip(*rates))}


def child(args) -> None:
    tc.init(arch=args.arch, precision="f32", threads=args.threads)
    rates = {}
    for n in args.sizes:
        for name in args.integrators:
            for key, value in measure(n, name, args.seconds, args.repeats,
                                      args.strain_limit).items():
                rates[f"{n} {name} {key}"] = value
    print(json.dumps(rates))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 128])
    parser.add_argument("--integrators", nargs="+", default=list(tc.INTEGRATORS))
    parser.add_argument("--processes", type=int, default=3)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--arch", default="cpu")
    parser.add_argument("--seconds", type=float, default=0.5)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--strain-limit", type=float, default=None,
                        help="both cloths strain-limited to this strain (Provot)")
    parser.add_argument("--baseline", type=Path, default=None,
                        help="an earlier checkout to time beside this one")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        return child(args)
    command = [sys.executable, __file__, "--child", "--arch", args.arch, "--seconds",
               str(args.seconds), "--repeats", str(args.repeats), "--sizes",
               *map(str, args.sizes), "--integrators", *args.integrators]
    if args.threads:
        command += ["--threads", str(args.threads)]
    if args.strain_limit is not None:
        command += ["--strain-limit", str(args.strain_limit)]
    versions = {"now": None} if args.baseline is None else {"before": args.baseline, "now": None}
    runs = {name: [] for name in versions}
    for _ in range(args.processes):
        for name, path in versions.items():
            env = dict(os.environ)
            if path is not None:
                env["PYTHONPATH"] = str(path)
            out = subprocess.run(command, check=True, capture_output=True, text=True, env=env,
                                 cwd=path or None).stdout
            runs[name].append(json.loads(out.strip().splitlines()[-1]))
    limited = "" if args.strain_limit is None else f", strain limited to {args.strain_limit:g}"
    print(f"arch={args.arch} f32 threads={args.threads or 'all'}{limited}: steps/s, min / median / max "
          f"over {args.processes} processes (each the median of {args.repeats} calls)")
    for name in runs:
        print(f"\n{name}:\n")
        print("| N | integrator | free | with plane + sphere | with / free |")
        print("|---|---|---|---|---|")
        for n in args.sizes:
            for integrator in args.integrators:
                cells = []
                for c in ("0", "1", "ratio"):
                    rates = sorted(run[f"{n} {integrator} {c}"] for run in runs[name])
                    digits = ".2f" if c == "ratio" else ",.0f"
                    cells.append(" / ".join(format(r, digits) for r in
                                            (rates[0], statistics.median(rates), rates[-1])))
                print(f"| {n}² | {integrator} | {' | '.join(cells)} |")
    if "before" in runs:
        print("\nnow / before, ratio of medians:\n")
        print("| N | integrator | free | with plane + sphere |")
        print("|---|---|---|---|")
        for n in args.sizes:
            for integrator in args.integrators:
                ratios = [statistics.median(r[f"{n} {integrator} {c}"] for r in runs["now"])
                          / statistics.median(r[f"{n} {integrator} {c}"] for r in runs["before"])
                          for c in (0, 1)]
                print(f"| {n}² | {integrator} | {ratios[0]:.2f}× | {ratios[1]:.2f}× |")


if __name__ == "__main__":
    main()
