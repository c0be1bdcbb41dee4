"""Microseconds per step of an integrator (--integrator, default symplectic Euler) in each CPU
launch plan (ti_cloth/stepping.py), by cloth size and by how many steps one
Simulation.step(n) call asks for.

    parallel per step step(1, plan="per stage") n times, each phase's loops parallel loops
                      (plan.SERIAL_SPRING_LIMIT set to 0)
    launch per step   step(1, plan="per stage") n times: a launch per stage, one serial
                      launch of the whole step below plan.SERIAL_SPRING_LIMIT springs
    one worker        step(n): n steps in one launch on the launching thread, every loop serial
                      (what a body under stepping.TEAM_MIN_SPRINGS always runs)
    team              step(n): n steps in one launch, each Taichi CPU thread owning a slice of
                      every loop, meeting at barriers
    timed choice      step(n) as Simulation.step runs big launches: the team or one pool
                      worker, whichever timed launches in this process show faster

With --busy another process keeps one core busy meanwhile, as a second job on a shared
machine does: spinning team workers then wait for a core, which the timed choice notices.

The scene is throughput.py's (N x N sheet, stretch + shear + bend springs, two pinned corners,
f32). Each cell is the median (and the 90th percentile, which shows the thread pool's slow
wake-ups) of --repeats calls. Simulation.step runs every launch of a body under
stepping.TEAM_MIN_SPRINGS springs as "one worker", and a bigger body's as pool tasks: on one
worker below stepping.TEAM_MIN_SPRING_STEPS of work in a launch, else "timed choice"; this
table is what those thresholds rest on.

    python benchmarks/launch_plans.py [--sizes 32 64 128 256] [--counts 16 256] [--threads 2]
"""

import argparse
import subprocess
import sys
import time

import numpy as np
from throughput import scene

import ti_cloth as tc
from ti_cloth import stepping
from ti_cloth.runtime import plan as launch_plan

PLANS = ("parallel per step", "launch per step", "one worker", "team", "timed choice")
THRESHOLD = stepping.TEAM_MIN_SPRING_STEPS   # work below which step(n) runs on one worker
SMALL = stepping.TEAM_MIN_SPRINGS   # springs below which every step(n) runs on one worker
SERIAL_LIMIT = launch_plan.SERIAL_SPRING_LIMIT   # springs below which a step is one serial launch


def per_step_us(sim, plan: str, count: int, repeats: int) -> np.ndarray:
    """Microseconds per step of `repeats` calls that each advance `count` steps."""
    stepping.TEAM_MIN_SPRING_STEPS = 0 if plan == "team" else THRESHOLD
    stepping.TEAM_MIN_SPRINGS = {"one worker": 1 << 62, "team": 0}.get(plan, SMALL)
    sim.many_steps.adaptive = plan == "timed choice"
    launch_plan.SERIAL_SPRING_LIMIT = 0 if plan == "parallel per step" else SERIAL_LIMIT
    times = []
    for _ in range(repeats + 1):                      # the first call compiles
        start = time.perf_counter()
        if plan in ("parallel per step", "launch per step"):
            for _ in range(count):
                sim.step(1, plan="per stage")
        else:
            sim.step(count, plan="many steps")
        sim.state.first_bad_step[None]               # waits for the launch to finish
        times.append((time.perf_counter() - start) / count * 1e6)
    return np.array(times[1:])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128, 256])
    parser.add_argument("--counts", type=int, nargs="+", default=[16, 256])
    parser.add_argument("--threads", type=int, default=None, help="CPU threads (default: all)")
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--integrator", default="symplectic_euler", help="any of tc.INTEGRATORS")
    parser.add_argument("--busy", action="store_true",
                        help="keep one core busy with another process meanwhile (what the timed "
                             "choice between one worker and the team is for)")
    args = parser.parse_args(argv)
    tc.init(arch="cpu", precision="f32", threads=args.threads)
    # the busy loop ends with this process, however it ends (it watches its parent)
    busy = (subprocess.Popen([sys.executable, "-c", "import os\nparent = os.getppid()\n"
                              "while os.getppid() == parent: pass"]) if args.busy else None)
    print(f"{'N':>5} {'springs':>9} {'steps/call':>10}  "
          + "  ".join(f"{plan + ' (p50/p90)':>26}" for plan in PLANS) + f"  {'step(n) picks':>13}")
    for n in args.sizes:
        cloth, start = scene(n)
        sim = tc.Simulation(cloth, integrator=args.integrator,
                            dt=tc.auto_dt(cloth, "explicit_euler"))
        sim.set_positions(start)
        for count in args.counts:
            cells = []
            for plan in PLANS:
                us = per_step_us(sim, plan, count, args.repeats)
                cells.append(f"{np.median(us):>12.1f} / {np.percentile(us, 90):>11.1f}")
            stepping.TEAM_MIN_SPRING_STEPS, stepping.TEAM_MIN_SPRINGS = THRESHOLD, SMALL
            many = sim.many_steps
            launch = min(count, many.steps_per_launch(sim.integrator, sim.model))
            picked = (1 if many.serial(sim.model)
                      else many.workers_for(sim.integrator, sim.model, launch))
            print(f"{n:>5} {cloth.spring_count:>9} {count:>10}  " + "  ".join(cells)
                  + f"  {'team' if picked > 1 else 'one worker':>13}")
    if busy is not None:
        busy.kill()


if __name__ == "__main__":
    main()
