"""Where the steps/s swing comes from: one long-lived process against fresh processes.

Symplectic Euler on an N x N sheet (the README's throughput cloth), many steps per launch,
the team plan fixed (no timed plan choice). One process times --samples calls of step(1500)
(about a second each) one after another; then --processes fresh processes time 3 calls each.
Both for one Taichi thread and for the machine's threads. If a long-lived process swings as
much as fresh ones do, the swing is the machine's speed over time, not a process's luck.

    python benchmarks/swing.py [--size 128] [--samples 30] [--processes 8]
"""

import argparse
import json
import statistics
import subprocess
import sys
import time

import ti_cloth as tc

STEPS = 1500


def child(size: int, samples: int, threads: int | None) -> list[float]:
    tc.init(arch="cpu", precision="f32", threads=threads)
    cloth = tc.Cloth(tc.grid_mesh(size, size, plane="xz"), tc.Material(), pinned=[0, size - 1])
    sim = tc.Simulation(cloth, integrator="symplectic_euler", dt="auto")
    sim.many_steps.adaptive = False
    sim.step(200)
    sim.state.first_bad_step[None]
    rates = []
    for _ in range(samples):
        sim.restart()
        start = time.perf_counter()
        sim.step(STEPS)
        sim.state.first_bad_step[None]
        rates.append(STEPS / (time.perf_counter() - start))
    return rates


def spawn(size: int, samples: int, threads: int | None) -> list[float]:
    command = [sys.executable, __file__, "--child", "--size", str(size), "--samples",
               str(samples)] + (["--threads", str(threads)] if threads else [])
    out = subprocess.run(command, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def row(label: str, rates: list[float]) -> str:
    median = statistics.median(rates)
    return (f"| {label} | {len(rates)} | {min(rates):,.0f} / {median:,.0f} / {max(rates):,.0f} | "
            f"{min(rates) / median:.2f} / {max(rates) / median:.2f} |")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--samples", type=int, default=30)
    parser.add_argument("--processes", type=int, default=8)
    parser.add_argument("--threads", type=int, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.size, args.samples, args.threads)))
        return
    print(f"symplectic Euler {args.size}², f32, steps/s of calls of step({STEPS})\n")
    print("| threads, where | calls | min / median / max | min, max / median |")
    print("|---|---|---|---|")
    for threads in (1, None):
        name = "1" if threads else "all"
        print(row(f"{name}, one process", spawn(args.size, args.samples, threads)), flush=True)
        fresh = [r for _ in range(args.processes) for r in spawn(args.size, 3, threads)]
        print(row(f"{name}, {args.processes} fresh processes", fresh), flush=True)


if __name__ == "__main__":
    main()
