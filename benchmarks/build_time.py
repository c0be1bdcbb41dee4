"""What a user waits for before the first frame (issue 53, item 4: "no compile on the way"):
seconds to build a simulation and take its first step in a fresh process with no offline
cache, for every integrator on issue 53's 32² denim sheet and for demo scenes; then, in the
same process, a second simulation of the same body whose integrator differs only in its
run-time options (a looser solve, other passes: Integrator.runtime_options), which must
compile nothing, and one step of each.

Each row is min / median / max over --processes fresh processes.

    python benchmarks/build_time.py [--processes 3] [--precision f32]
        [--integrators NAME ...] [--scenes demos/cape.toml ...]
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
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
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child, args.precision)))
        return 0
    environment = dict(os.environ, TI_OFFLINE_CACHE="0", ENABLE_TAICHI_HEADER_PRINT="False")
    print(f"seconds, min / median / max over {args.processes} fresh processes "
          f"({args.precision}, no offline cache)\n")
    print("| what | build | first step | then: other run-time options, build and step |")
    print("|---|---|---|---|")
    for what in [*args.integrators, *args.scenes]:
        runs = []
        for _ in range(args.processes):
            out = subprocess.run([sys.executable, __file__, "--precision", args.precision,
                                  "--child", what], capture_output=True, text=True,
                                 check=True, env=environment)
            runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
        other = (cells([r["other options"] for r in runs]) if "other options" in runs[0]
                 else "")
        print(f"| {what} | {cells([r['build'] for r in runs])} | "
              f"{cells([r['first step'] for r in runs])} | {other} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
