"""What batched uploads buy a simulation's build: seconds to build (and take one step of) a
scene in a fresh process with no offline cache, with a build's uploads sent as one kernel
(transfer.batched, the default) and with every upload sent, and compiled, on its own.

Each process builds one scene in one mode; the modes alternate process by process, and the
table gives min / median / max over --processes processes of each and the ratio of the
medians. The positions after the step are compared: the two modes must give the same bits.

    python benchmarks/build_cost.py [--processes 5] [--precision f64]
"""

import argparse
import contextlib
import hashlib
import json
import os
import statistics
import subprocess
import sys
import time

SCENES = ("sheet", "denim")   # a spring sheet; a Fabric with strain limiting and the wind


def build(scene: str, batched: bool, precision: str) -> dict:
    """Seconds to build `scene` and to take its first step, and a hash of the positions."""
    import ti_cloth as tc
    from ti_cloth.runtime import transfer

    tc.init(arch="cpu", precision=precision)
    if not batched:
        transfer.batched = contextlib.nullcontext     # every upload sent when it is made
    mesh = tc.grid_mesh(24, 24, size=(0.5, 0.5), plane="xz")
    began = time.perf_counter()
    if scene == "sheet":
        sim = tc.Simulation(tc.Cloth(mesh, tc.Material(), pinned=[0, 23]), dt=1e-4)
    else:
        sim = tc.Simulation(tc.Cloth(mesh, tc.Fabric.preset("denim"), pinned=[0, 23]),
                            dt=1e-4, strain_limit=tc.StrainLimit(max_strain=0.1),
                            wind=tc.Wind(velocity=(1.0, 0.0, 0.0)))
    built = time.perf_counter()
    sim.step(1)
    stepped = time.perf_counter()
    return {"build": built - began, "first step": stepped - built,
            "bits": hashlib.sha256(sim.positions().tobytes()).hexdigest()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--processes", type=int, default=5)
    parser.add_argument("--precision", default="f64", choices=("f32", "f64"))
    parser.add_argument("--child", nargs=2, metavar=("SCENE", "MODE"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        scene, mode = args.child
        print(json.dumps(build(scene, mode == "batched", args.precision)))
        return 0
    environment = dict(os.environ, TI_OFFLINE_CACHE="0")     # every kernel compiled afresh
    print(f"seconds, min / median / max over {args.processes} fresh processes each "
          f"({args.precision}, no offline cache)\n")
    print("| scene | uploads | build | first step | build: one-by-one / batched |")
    print("|---|---|---|---|---|")
    for scene in SCENES:
        runs = {"batched": [], "one by one": []}
        for _ in range(args.processes):
            for mode in runs:
                out = subprocess.run([sys.executable, __file__, "--precision", args.precision,
                                      "--child", scene, mode.replace(" ", "_")],
                                     capture_output=True, text=True, check=True, env=environment)
                runs[mode].append(json.loads(out.stdout.strip().splitlines()[-1]))
        bits = {run["bits"] for mode in runs.values() for run in mode}
        if len(bits) != 1:
            raise AssertionError(f"{scene}: the two modes gave different positions")
        median = {mode: statistics.median(r["build"] for r in rs) for mode, rs in runs.items()}
        for mode, rs in runs.items():
            cells = [" / ".join(f"{x:.3f}" for x in (min(v), statistics.median(v), max(v)))
                     for v in ([r["build"] for r in rs], [r["first step"] for r in rs])]
            ratio = f"{median['one by one'] / median['batched']:.2f}x" if mode == "batched" else ""
            print(f"| {scene} | {mode} | {cells[0]} | {cells[1]} | {ratio} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
