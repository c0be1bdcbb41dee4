"""Launch plans (stepping.py): many serial steps per launch, one parallel launch per step and the
two-phase spring force (evaluate once, gather with signs) must all give the same bits, and the
divergence guard must name the same step whichever plan ran."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

import ti_cloth as tc
from ti_cloth import stepping
from ti_cloth.forces import ForceSettings, compute_forces
from ti_cloth.model import Model

FUSED = ["explicit_euler", "symplectic_euler", "verlet"]


def sheet(n=6, damping="axial"):
    cloth = tc.Cloth(tc.grid_mesh(n, n), tc.Material(damping=damping), pinned=[n * (n - 1), n * n - 1])
    centre = cloth.particle_position.mean(axis=0)
    return cloth, centre + 1.3 * (cloth.particle_position - centre)   # start stretched: it moves


@pytest.mark.parametrize("integrator", FUSED)
@pytest.mark.parametrize("tearing", [None, 0.2])
def test_many_steps_per_launch_equal_one_launch_per_step(f64, integrator, tearing):
    cloth, start = sheet()
    runs = []
    for batched in (True, False):
        sim = tc.Simulation(cloth, integrator=integrator, dt=2e-5, drag=0.3, tearing=tearing)
        assert sim._many_per_launch
        sim.set_positions(start)
        if batched:
            sim.step(2 * stepping.MAX_STEPS_PER_LAUNCH + 7)   # three launches, the last partial
        else:
            for _ in range(2 * stepping.MAX_STEPS_PER_LAUNCH + 7):
                sim.step(1)                                   # one parallel launch each
        runs.append((sim.positions(), sim.velocities(), sim.torn_springs(), sim.step_count))
    (x1, v1, torn1, n1), (x2, v2, torn2, n2) = runs
    moved = np.abs(x1 - start).max()
    print(f"{integrator}, tearing {tearing}: moved {moved:.3g} m, torn {len(torn1)} springs, "
          f"max |dx| between plans {np.abs(x1 - x2).max()}")
    assert moved > 1e-3 and n1 == n2 and np.array_equal(torn1, torn2)
    if integrator == "verlet":
        # Taichi's fast math lets LLVM contract Verlet's three-term update differently in the
        # two kernels: rounding differences (1e-16 m a step on this 1 m sheet), accumulated over
        # 519 steps and amplified where springs snap (up to 2e-12 m seen), far below the
        # millimetres any change of method or step would make.
        assert np.abs(x1 - x2).max() <= 1e-9
    else:
        assert np.array_equal(x1, x2) and np.array_equal(v1, v2)
    if tearing is not None:
        assert len(torn1) > 0, "the 30 % stretch tears springs at a 20 % tear strain"


def test_above_the_serial_limit_every_step_is_one_parallel_launch(f64, monkeypatch):
    cloth, start = sheet()
    serial = tc.Simulation(cloth, dt=2e-5)
    monkeypatch.setattr(stepping, "SERIAL_SPRING_LIMIT", cloth.spring_count - 1)
    parallel = tc.Simulation(cloth, dt=2e-5)
    assert serial._many_per_launch and not parallel._many_per_launch
    for sim in (serial, parallel):
        sim.set_positions(start)
        sim.step(300)
    assert np.array_equal(serial.positions(), parallel.positions())


def test_features_between_steps_take_one_launch_per_step(f64):
    cloth, _ = sheet()
    plain = tc.Simulation(cloth, dt=1e-4)
    assert plain._many_per_launch
    for kwargs in (dict(wind=tc.Wind(velocity=(1.0, 0.0, 0.0))),
                   dict(colliders=[tc.Plane(point=(0.0, -1.0, 0.0), normal=(0.0, 1.0, 0.0))]),
                   dict(strain_limit=tc.StrainLimit(0.1)),
                   dict(handles=[tc.Handle([0], lambda t: (0.0, 0.0, 0.0))])):
        assert not tc.Simulation(cloth, dt=1e-4, **kwargs)._many_per_launch, kwargs
    assert not tc.Simulation(cloth, integrator="rk4", dt=1e-4)._many_per_launch


@pytest.mark.parametrize("integrator", FUSED)
def test_divergence_names_the_same_step_in_either_plan(f64, integrator):
    cloth, start = sheet()
    steps = []
    for batched in (True, False):
        sim = tc.Simulation(cloth, integrator=integrator, dt=5.0 * sim_stable(cloth, integrator))
        sim.set_positions(start)
        with pytest.raises(tc.SimulationDiverged) as error:
            if batched:
                sim.step(5000)
            else:
                for _ in range(5000):
                    sim.step(1)
        steps.append(error.value.step)
    print(f"{integrator}: first bad step {steps}")
    assert steps[0] == steps[1] < 5000


def sim_stable(cloth, integrator):
    return tc.stable_dt(cloth, "symplectic_euler" if integrator == "explicit_euler" else integrator)


@pytest.mark.parametrize("damping", ["axial", "relative"])
def test_two_phase_gather_matches_an_independent_scatter(f64, damping):
    """At a random state, each particle's force equals a numpy scatter of the per-spring
    formula (Stuyck eq. 4.5, 4.7) over every spring kind, to rounding."""
    rng = np.random.default_rng(3)
    body, _ = sheet(5, damping)
    model = Model(body)
    state = model.state()
    x = body.particle_position + 0.05 * rng.normal(size=(body.particle_count, 3))
    v = rng.normal(size=(body.particle_count, 3))
    state.particle_position.from_numpy(x)
    state.particle_velocity.from_numpy(v)
    compute_forces(model, state, ForceSettings(gravity=(0.0, 0.0, 0.0)))
    got = state.particle_force.to_numpy()

    i, j = body.spring_indices.T
    d = x[i] - x[j]
    length = np.linalg.norm(d, axis=1)
    n = d / length[:, None]
    dv = v[i] - v[j]
    damp = (body.spring_damping[:, None] * dv if damping == "relative"
            else (body.spring_damping * np.sum(dv * n, axis=1))[:, None] * n)
    f = -(body.spring_stiffness * (length - body.spring_rest_length))[:, None] * n - damp
    expected = np.zeros_like(x)
    np.add.at(expected, i, f)
    np.add.at(expected, j, -f)
    error = np.abs(got - expected).max()
    print(f"max |f - scatter| = {error:.3g} N of max |f| {np.abs(expected).max():.3g} N")
    assert error <= 1e-12 * np.abs(expected).max()
    assert abs(got.sum(axis=0)).max() <= 1e-12 * np.abs(expected).max(), "third law"


def load_benchmark():
    path = Path(__file__).parents[1] / "benchmarks" / "throughput.py"
    spec = importlib.util.spec_from_file_location("throughput", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_benchmark_numpy_baseline_steps_like_ti_cloth(f64):
    """The baseline the README's speed-ups are quoted against computes the same step."""
    bench = load_benchmark()
    cloth, start = bench.scene(10)
    dt = tc.auto_dt(cloth, "explicit_euler")
    sim = tc.Simulation(cloth, dt=dt)
    sim.set_positions(start)
    baseline = bench.NumpyCloth(cloth, start, dt, (0.0, -9.81, 0.0), np.float64)
    sim.step(50)
    baseline.step(50)
    error = np.abs(baseline.velocities() - sim.velocities()).max()
    print(f"max |v_numpy - v_ti_cloth| = {error:.3g} of max |v| {np.abs(sim.velocities()).max():.3g}")
    assert error <= 1e-10 * np.abs(sim.velocities()).max()


def test_benchmark_runs_and_writes_its_table(tmp_path):
    bench = load_benchmark()
    out = tmp_path / "t.csv"
    bench.main(["--sizes", "6", "--precisions", "f64", "--integrators", "symplectic_euler", "pbd",
                "--seconds", "0.01", "--repeats", "1", "--csv", str(out)])
    text = out.read_text().splitlines()
    assert text[0].startswith("arch,precision,N,")
    assert [line.split(",")[5] for line in text[1:]] == ["ti_cloth symplectic_euler", "ti_cloth pbd", "numpy"]
