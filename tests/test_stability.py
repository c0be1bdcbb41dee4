"""The predicted largest stable step against a dense eigensolver and against the threshold
measured by running symplectic Euler; dt = "auto"."""

import math
from pathlib import Path

import numpy as np
import pytest
from helpers import report

import ti_cloth as tc
from ti_cloth.body.modes import stiffest_mode

DEMOS = Path(__file__).parents[1] / "demos"


def cloths():
    """Three different bodies: a square sheet pinned at two corners, a strip with a heavy hem
    all round and stiff shear, and a hanging string."""
    sheet = tc.Cloth(tc.grid_mesh(9, 9, size=(0.6, 0.6), plane="xz"), tc.Material(), pinned=[0, 8])
    hem = tc.Material(density=0.3, stretch=tc.SpringParams(2000.0, 0.5), shear=tc.SpringParams(800.0),
                      bend=tc.SpringParams(5.0), hem_mass=0.01)
    strip = tc.Cloth(tc.grid_mesh(5, 14, size=(1.2, 0.4)), hem, pinned=list(range(56, 70)),
                     hem="boundary")
    rope = tc.string(12, 1.0, mass=0.02, stretch=tc.SpringParams(300.0), direction=(1, -1, 0))
    return {"sheet": sheet, "strip": strip, "string": rope}


def dense_stiffest(cloth):
    """Largest eigenvalue of M^-1/2 K M^-1/2 at rest, assembled densely (pins removed)."""
    n = cloth.particle_count
    K = np.zeros((3 * n, 3 * n))
    for (i, j), k in zip(cloth.spring_indices, cloth.spring_stiffness):
        d = cloth.particle_position[i] - cloth.particle_position[j]
        u = d / np.linalg.norm(d)
        block = k * np.outer(u, u)
        for a, b, sign in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            K[3 * a:3 * a + 3, 3 * b:3 * b + 3] += sign * block
    free = np.repeat(~cloth.pinned, 3)
    s = 1 / np.sqrt(np.repeat(cloth.particle_mass, 3))[free]
    A = s[:, None] * K[np.ix_(free, free)] * s[None, :]
    return np.linalg.eigvalsh(A)[-1]


@pytest.mark.parametrize("name", ["sheet", "strip", "string", "20 x 20 sheet"])
def test_lanczos_finds_the_stiffest_mode(name):
    """Within LANCZOS_TOLERANCE-ish of the dense eigenvalue, from below (a Ritz value). The
    100 power iterations used before stopped 1e-5 short on the small bodies and 1.6e-3 short
    on the 20 x 20 sheet, whose top eigenvalues crowd together."""
    cloth = cloths()[name] if name in cloths() else tc.Cloth(
        tc.grid_mesh(20, 20, plane="xz"), tc.Material(), pinned=[0, 19])
    w2, _ = stiffest_mode(cloth)
    exact = dense_stiffest(cloth)
    report(f"{name}: w^2 Lanczos vs dense", w2, exact)
    assert exact * (1 - 1e-6) <= w2 <= exact * (1 + 1e-12)


def diverges(sim, dt, start, steps=1500):
    sim.restart(dt)
    sim.set_positions(start)
    try:
        sim.step(steps)
    except tc.SimulationDiverged:
        return True
    return False


def perturbed(cloth):
    x = cloth.particle_position + np.random.default_rng(1).normal(scale=1e-3, size=cloth.particle_position.shape)
    x[cloth.pinned] = cloth.particle_position[cloth.pinned]
    return x


@pytest.mark.parametrize("name", ["sheet", "strip", "string"])
def test_symplectic_euler_stable_below_prediction_and_diverges_above(f64, name):
    """Bounded at 0.9 x the prediction for 1500 steps; at 1.1 x the divergence exception names
    the step and the predicted stable dt. Bisection puts the measured threshold within 25 % of
    the prediction."""
    cloth = cloths()[name]
    predicted = tc.stable_dt(cloth, "symplectic_euler")
    sim = tc.Simulation(cloth, integrator="symplectic_euler", dt=predicted, position_limit=100.0)
    start = perturbed(cloth)
    assert not diverges(sim, 0.9 * predicted, start)
    energy = sim.energy()
    assert abs(energy["kinetic"] + energy["spring"]) < 10 * cloth.particle_mass.sum() * 9.81, "bounded"
    with pytest.raises(tc.SimulationDiverged, match=f"a stable dt for symplectic_euler is about "
                                                    f"{predicted:.3g} s") as caught:
        sim.restart(1.1 * predicted)
        sim.set_positions(start)
        sim.step(1500)
    assert 0 <= caught.value.step < 1500
    low, high = 0.9 * predicted, 1.1 * predicted
    for _ in range(6):
        mid = 0.5 * (low + high)
        low, high = (low, mid) if diverges(sim, mid, start) else (mid, high)
    measured = 0.5 * (low + high)
    report(f"{name}: predicted / measured stable dt", (predicted, measured), "within 25 %")
    assert abs(predicted / measured - 1) < 0.25


def test_stuycks_scheme_is_stable_below_its_prediction_and_blows_up_just_above(f64):
    """Explicit Euler with relative damping (demos/stuyck_explicit.toml), 0.5 s: at 0.9 x the
    prediction the sheet falls with a kinetic energy below 0.2 m g L (the physical swing: 0.11);
    at 1.2 x its sideways-damped modes explode (h > 2 / g: v' = (1 - h g) v), the kinetic
    energy passing m g L, though the damping's nonlinearity keeps positions inside the guard.
    The sprung-mode rule alone predicted 1.46 x this, deep in the blown regime."""
    from ti_cloth.app.scene import load_scene

    scene = load_scene(DEMOS / "stuyck_explicit.toml")
    predicted = tc.stable_dt(scene.cloth, "explicit_euler", scene.drag)
    weight_drop = scene.cloth.particle_mass.sum() * 9.81 * 1.0           # m g L, L = 1 m

    def peak_kinetic(fraction):
        sim = scene.build(dt=fraction * predicted)
        peak = 0.0
        for _ in range(50):
            sim.step(max(1, round(0.01 / sim.dt)))
            peak = max(peak, sim.energy()["kinetic"])
        return peak / weight_drop

    calm, blown = peak_kinetic(0.9), peak_kinetic(1.2)
    report("peak kinetic energy / m g L at 0.9 x and 1.2 x the prediction", (calm, blown),
           "< 0.2, > 1")
    assert calm < 0.2 < 1.0 < blown


def test_light_particles_on_damped_springs_are_stable_below_the_prediction(f64):
    """A curly hair strand: its ghosts are light and their springs damped, so some mode is
    damped far more (g ~ 1e5 1/s) than the stiffest one. The prediction pairs the largest w^2
    with the largest damping rate; pairing it with the stiffest mode's own damping predicted
    6e-5 s, where symplectic Euler diverged within 41 steps at half of it."""
    body = tc.hair([[0.0, 0.0, 0.0]], 24, 0.5, directions=[[0.0, -1.0, 0.0]], mass=1e-3,
                   stretch=tc.SpringParams(200.0, 0.05), bend=tc.SpringParams(20.0, 0.2),
                   curl=(0.02, 0.01))
    predicted = tc.stable_dt(body, "symplectic_euler", drag=20.0)
    sim = tc.Simulation(body, dt=0.9 * predicted, drag=20.0)
    sim.step(round(0.2 / sim.dt))
    assert np.isfinite(sim.positions()).all() and predicted < 3e-5


def test_auto_dt_is_half_the_stable_step_capped(f64):
    cloth = cloths()["sheet"]
    sim = tc.Simulation(cloth, integrator="symplectic_euler", dt="auto")
    assert sim.dt == pytest.approx(min(0.5 * tc.stable_dt(cloth, "symplectic_euler"), tc.AUTO_MAX_DT))
    soft = tc.Cloth(tc.grid_mesh(3, 3), tc.Material(stretch=tc.SpringParams(1.0), shear=tc.SpringParams(0.1),
                                                   bend=tc.SpringParams(0.01)))
    assert tc.Simulation(soft, integrator="symplectic_euler", dt="auto").dt == tc.AUTO_MAX_DT
    assert tc.Simulation(cloth, integrator="implicit_euler", dt="auto").dt == tc.AUTO_MAX_DT
    assert tc.auto_substeps(cloth, "symplectic_euler", 1 / 30) == math.ceil(1 / 30 / sim.dt - 1e-9)
    with pytest.raises(ValueError, match="dt='auto': no stable step exists for explicit_euler"):
        tc.Simulation(tc.string(4, 1.0, stretch=tc.SpringParams(10.0, 0.0)), integrator="explicit_euler",
                      dt="auto")
