"""Wall time of a study run serially and on local processes (--jobs), same rows either way.

The reference (rk4 / f64) is computed once and shared; each sweep is timed whole (spawning,
importing and compiling in the workers included), and its rows are compared with the serial
ones without their timings.

    python benchmarks/study_jobs.py [--scene demos/study_cloth.toml] [--jobs 1 2]
"""

import argparse
import time
from dataclasses import asdict

import ti_cloth as tc
from ti_cloth.app import study, sweep
from ti_cloth.runtime import backend


def rows(result):
    """The runs without their timings, as text (NaN, the metrics of a diverged run, equals
    itself there)."""
    return [{k: repr(v) for k, v in asdict(r).items() if k not in ("wall_seconds", "cost")}
            for r in result.runs]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="demos/study_cloth.toml")
    parser.add_argument("--jobs", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args(argv)
    scene = tc.load_scene(args.scene)
    start = time.perf_counter()
    reference = study.reference_trajectory(scene)
    print(f"reference: {time.perf_counter() - start:.1f} s; {backend.cpu_cores()} cores")
    print(f"{'jobs':>5} {'runs':>6} {'wall [s]':>9} {'vs 1 job':>9}  rows as serial")
    base, serial = None, None
    for jobs in args.jobs:
        start = time.perf_counter()
        if jobs == 1:
            result = study.run_study(scene, reference=reference, progress=False)
        else:
            with sweep.local_jobs(jobs) as workers:
                result = study.run_study(scene, reference=reference, executor=workers,
                                         progress=False)
        wall = time.perf_counter() - start
        base = base or wall
        serial = serial or rows(result)
        print(f"{jobs:>5} {len(result.runs):>6} {wall:>9.1f} {base / wall:>8.2f}x  "
              f"{rows(result) == serial}")


if __name__ == "__main__":
    main()
