"""What a user waits for before the first frame (issue 53, item 4: "no compile on the way"):
seconds to build a simulation and take its first step in a fresh process with no offline
cache, for every integrator on issue 53's 32² denim sheet and for demo scenes; then, in the
same process, a second simulation of the same body whose integrator differs only in its
run-time options (a looser solve, other passes: Integrator.runtime_options), which must
compile nothing, and one step of each.

Each row is min / median / max over --processes fresh processes, with no offline cache, or
with `--warm` from a warm one (a scene run again: Taichi's offline cache skips the compile
but still runs its Python front end; a process of each row warms it, unmeasured). With
`--compare-memo` each process runs twice, alternated: as ti_cloth does, with Taichi's front
end memoised (runtime/frontend.py), and with TI_CLOTH_TAICHI_MEMO=0, Taichi as it is; the
last column is the median of (build + first step) as it is over the memoised one.

    python benchmarks/build_time.py [--processes 3] [--precision f32] [--warm]
        [--compare-memo] [--integrators NAME ...] [--scenes demos/cape.toml ...]
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
INTEGRATORS = ("symplectic_euler", "verlet", "rk4", "xpbd", "implicit_euler",
               "implicit_midpoint", "tr_bdf2")
SCENES = ("demos/hanging_cloth.toml", "demos/cape.toml", "demos/skirt_walk.toml")
# a second integrator differing only in run-time options (None: the integrator has none)
OTHER_OPTIONS = {"xpbd": {"iterations": 4}, "implicit_euler": {"tolerance": 1e-3},
                 "implicit_midpoint": {"tolerance": 1e-4, "cg_tolerance": 0.1},
                 "tr_bdf2": {"tolerance": 1e-4, "cg_tolerance": 0.1}}


def sheet(integrator: str):
    """Issue 53's sheet: 0.5 m denim-like, 32 x 32, pinned at two adjacent corners; a step
    the integrator is stable at (an explicit one's at 0.9 of its stable step)."""
    import ti_cloth as tc
    fabric = tc.Fabric(density=0.324, stretch=5e3, shear=1e3, bending=1e-4)
    cloth = tc.Cloth(tc.grid_mesh(32, 32, (0.5, 0.5)), fabric, pinned=[992, 1023])
    dt = 1 / 120
    if tc.INTEGRATORS[integrator].step_limited:
        dt = 0.9 * tc.stable_dt(cloth, integrator)
    return cloth, dt


def child(what: str, precision: str) -> dict:
    """Seconds to build `what` (an integrator on the sheet, or a scene file) and take its
    first step; for an integrator with run-time options, the same for a second simulation
    with other values, after the first is dropped."""
    import ti_cloth as tc
    from ti_cloth.app.scene import load_scene
    warnings.simplefilter("ignore")
    tc.init(arch="cpu", precision=precision)
    scene = load_scene(ROOT / what) if what.endswith(".toml") else None
    cloth, dt = sheet(what) if scene is None else (None, None)
    began = time.perf_counter()
    if scene is not None:
        sim = scene.build()
    else:
        sim = tc.Simulation(cloth, integrator=what, dt=dt)
    built = time.perf_counter()
    sim.step(1)
    out = {"build": built - began, "first step": time.perf_counter() - built}
    if what in OTHER_OPTIONS:
        del sim
        began = time.perf_counter()
        other = tc.Simulation(cloth, integrator=tc.INTEGRATORS[what](**OTHER_OPTIONS[what]),
                              dt=dt)
        other.step(1)
        out["other options"] = time.perf_counter() - began
    return out


def cells(values) -> str:
    return " / ".join(f"{x:.2f}" for x in (min(values), statistics.median(values), max(values)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--processes", type=int, default=3)
    parser.add_argument("--precision", default="f32", choices=("f32", "f64"))
    parser.add_argument("--integrators", nargs="*", default=list(INTEGRATORS))
    parser.add_argument("--scenes", nargs="*", default=list(SCENES))
    parser.add_argument("--warm", action="store_true",
                        help="from a warm offline cache (module doc)")
    parser.add_argument("--compare-memo", action="store_true",
                        help="also with Taichi's front end as it is, alternated (module doc)")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child, args.precision)))
        return 0
    with tempfile.TemporaryDirectory(prefix="build_time_cache_") as cache:
        environment = dict(os.environ, ENABLE_TAICHI_HEADER_PRINT="False",
                           **({"TI_OFFLINE_CACHE_FILE_PATH": cache} if args.warm
                              else {"TI_OFFLINE_CACHE": "0"}))
        table(args, environment)
    return 0


def table(args, environment: dict) -> None:
    """Print the table (module doc), the processes run with `environment`."""
    memos = ("1", "0") if args.compare_memo else ("1",)

    def run(what, memo):
        out = subprocess.run([sys.executable, __file__, "--precision", args.precision,
                              "--child", what], capture_output=True, text=True, check=True,
                             env=dict(environment, TI_CLOTH_TAICHI_MEMO=memo))
        return json.loads(out.stdout.strip().splitlines()[-1])

    cache = "a warm offline cache" if args.warm else "no offline cache"
    print(f"seconds, min / median / max over {args.processes} fresh processes "
          f"({args.precision}, {cache})\n")
    head = ("| what | front end | build | first step "
            "| then: other run-time options, build and step |")
    print(head + (" as it is / memoised |" if args.compare_memo else ""))
    print("|---" * (head.count("|") - 1 + args.compare_memo) + "|")
    for what in [*args.integrators, *args.scenes]:
        if args.warm:
            run(what, "1")                      # fills the cache, unmeasured
        runs = {memo: [] for memo in memos}
        for _ in range(args.processes):
            for memo in memos:
                runs[memo].append(run(what, memo))
        total = {memo: statistics.median(r["build"] + r["first step"] for r in rows)
                 for memo, rows in runs.items()}
        for memo, rows in runs.items():
            other = (cells([r["other options"] for r in rows]) if "other options" in rows[0]
                     else "")
            ratio = (f" {total['0'] / total['1']:.2f}x |" if args.compare_memo and memo == "0"
                     else " |" if args.compare_memo else "")
            print(f"| {what} | {'memoised' if memo == '1' else 'as it is'} | "
                  f"{cells([r['build'] for r in rows])} | "
                  f"{cells([r['first step'] for r in rows])} | {other} |{ratio}", flush=True)


if __name__ == "__main__":
    raise SystemExit(main())
