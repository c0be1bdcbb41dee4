"""The lecture's loop against ti_cloth's pbd (README "The lecture's loop"): per 1/30 s frame,
the lecture repeats numIter times (a Verlet update, then one relaxation pass) = pbd with
iterations = 1 and numIter substeps; pbd's own form predicts once and relaxes numIter passes
= pbd with iterations = numIter and 1 substep. Both relax numIter times per frame. Printed per
numIter: wall time per simulated second (median of 5 runs) and its ratio to the lecture's
numIter = 1, and how far the hanging sheet stretches (mean and largest strain of its stretch
springs after 2 s): what the extra predictions buy.

    python benchmarks/lecture_loop.py [--arch cpu|cuda]
"""

import argparse
import statistics
import time

import numpy as np

import ti_cloth as tc

FRAME = 1 / 30
SECONDS = 2.0


def sheet():
    return tc.Cloth(tc.grid_mesh(20, 20, size=(1.0, 1.0)), tc.Material(), pinned=[380, 399])


def run(cloth, iterations, substeps):
    """(seconds of wall time per simulated second, mean strain, max strain)."""
    sim = tc.Simulation(cloth, integrator=tc.PBD(iterations=iterations, damping=0.01),
                        dt=FRAME / substeps)
    sim.step(substeps)                                    # compile outside the timing
    walls = []
    for _ in range(5):
        sim.restart()
        start = time.perf_counter()
        sim.step(round(SECONDS / sim.dt))
        walls.append((time.perf_counter() - start) / SECONDS)
    x = sim.positions()
    stretch = cloth.spring_kind == tc.SpringKind.STRETCH
    i, j = cloth.spring_indices[stretch].T
    strain = np.linalg.norm(x[i] - x[j], axis=1) / cloth.spring_rest_length[stretch] - 1
    return statistics.median(walls), float(strain.mean()), float(strain.max())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arch", default="cpu")
    args = parser.parse_args()
    tc.init(arch=args.arch, precision="f32")
    cloth = sheet()
    rows, baseline = [], None
    for num_iter in (1, 2, 4, 8):
        for label, iterations, substeps in (("lecture loop", 1, num_iter),
                                            ("pbd, one prediction", num_iter, 1)):
            wall, mean, peak = run(cloth, iterations, substeps)
            baseline = baseline or wall
            rows.append(f"| {num_iter} | {label} | {wall * 1e3:.1f} | {wall / baseline:.2f} | "
                        f"{mean:.3f} | {peak:.3f} |")
    print(f"20 x 20 sheet hung by two corners, 1/30 s frames, {SECONDS:g} s, f32, {args.arch}\n")
    print("| numIter | scheme | ms per simulated s | cost ratio | mean strain | max strain |")
    print("|---|---|---|---|---|---|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
