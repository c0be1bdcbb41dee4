"""What every integrator does at the extremes (the README's "Extremes" table): each case is run
with each integrator in f64 and the outcome printed as a markdown table.

    python benchmarks/extremes.py
"""

import math

import numpy as np

import ti_cloth as tc


def sheet(k=800.0, density=0.15, kd=0.0):
    material = tc.Material(density=density, stretch=tc.SpringParams(k, kd),
                           shear=tc.SpringParams(k / 10, kd / 10), bend=tc.SpringParams(k / 800, kd / 800))
    return tc.Cloth(tc.grid_mesh(8, 8, size=(0.5, 0.5), plane="xz"), material, pinned=[0, 7])


def outcome(cloth, integrator, dt, seconds, start=None, gravity=(0.0, -9.81, 0.0)):
    """Run and describe: diverged (at which step) or the worst strain and energy change."""
    try:
        sim = tc.Simulation(cloth, integrator=integrator, dt=dt, gravity=gravity)
    except ValueError as err:
        return f"refused: {str(err).split(';')[0]}"
    if start is not None:
        sim.set_positions(start)
    e0 = sim.energy()["total"]
    peak = 0.0
    steps = max(1, round(seconds / sim.dt))
    try:
        for _ in range(min(steps, 50)):
            sim.step(max(1, steps // 50))
            peak = max(peak, sim.energy()["total"] - e0)
    except tc.SimulationDiverged as err:
        return f"diverges at step {err.step} (stable dt {err.stable_dt:.2g} s)"
    x = sim.positions()
    i, j = cloth.spring_indices.T
    rest = cloth.spring_rest_length
    strain = np.abs(np.linalg.norm(x[i] - x[j], axis=1)[rest > 0] / rest[rest > 0] - 1).max() if (rest > 0).any() else 0.0
    return f"runs: strain {strain:.2g}, energy peak +{peak:.2g} J"


def main():
    tc.init(arch="cpu", precision="f64")
    names = list(tc.INTEGRATORS) + ["xpbd bdf2"]
    made = {"xpbd bdf2": tc.XPBD(scheme="bdf2")}       # xpbd on BDF2's step (XPBD.scheme)
    micro = sheet(k=1.0, density=1e-6 * 64 / 0.25, kd=1e-4)
    zero = tc.Cloth.from_particles([[0, 0, 0], [0, 0, 0]], [0.0, 0.1], [[0, 1]],
                                   tc.Material(stretch=tc.SpringParams(40.0)), pinned=[0])
    cases = {
        "k = 1e7 N/m, dt = 1/30 s, 2 s": lambda name: outcome(sheet(k=1e7), name, 1 / 30, 2.0),
        "1e-6 kg particles, dt = auto, 0.2 s": lambda name: outcome(micro, name, "auto", 0.2),
        "zero-length rest spring, displaced, 1 s": lambda name: outcome(
            zero, name, 2 * math.pi * math.sqrt(0.1 / 40) / 400, 1.0, start=[[0, 0, 0], [0.03, -0.04, 0.02]],
            gravity=(0, 0, 0)),
        "every particle pinned, dt = 1/60 s": lambda name: outcome(
            tc.Cloth(tc.grid_mesh(4, 4), tc.Material(), pinned=list(range(16))), name, 1 / 60, 1.0),
        "no springs, dt = 1/60 s": lambda name: outcome(
            tc.Cloth.from_particles([[0, 0, 0], [1, 0, 0]], [0.1, 0.2], np.zeros((0, 2), int)), name, 1 / 60, 1.0),
    }
    print("| case | " + " | ".join(f"`{n}`" for n in names) + " |")
    print("|---|" + "---|" * len(names))
    for case, run in cases.items():
        print(f"| {case} | " + " | ".join(run(made.get(name, name)) for name in names) + " |")


if __name__ == "__main__":
    main()
