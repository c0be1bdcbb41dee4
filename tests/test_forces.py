"""Spring, damping, gravity and drag forces against closed forms and -dE/dx."""

import numpy as np
import pytest
from helpers import report

import ti_cloth as tc
from ti_cloth.physics.forces import ForceSettings, compute_forces, energies


def forces_at(cloth, x, v, forces=ForceSettings(gravity=(0.0, 0.0, 0.0))):
    model = tc.Model(cloth)
    state = model.state()
    state.particle_position.from_numpy(x)
    state.particle_velocity.from_numpy(v)
    compute_forces(model, state, forces)
    return state.particle_force.to_numpy()


def perturbed_cloth(seed=1, damping="axial"):
    material = tc.Material(density=0.2, stretch=tc.SpringParams(5e3, 1.0), shear=tc.SpringParams(5e2, 0.3),
                           bend=tc.SpringParams(50.0, 0.1), damping=damping)
    cloth = tc.Cloth(tc.grid_mesh(5, 6, size=(1.0, 0.8)), material)
    rng = np.random.default_rng(seed)
    x = cloth.particle_position + rng.normal(scale=0.02, size=(cloth.particle_count, 3))
    return cloth, x, rng


def test_spring_forces_are_minus_energy_gradient(f64):
    cloth, x, _ = perturbed_cloth()
    f = forces_at(cloth, x, np.zeros_like(x))
    eps = 1e-6
    grad = np.zeros_like(x)
    for i in range(cloth.particle_count):
        for a in range(3):
            xp, xm = x.copy(), x.copy()
            xp[i, a] += eps
            xm[i, a] -= eps
            grad[i, a] = (energies(cloth, xp, 0 * x, (0, 0, 0))["spring"]
                          - energies(cloth, xm, 0 * x, (0, 0, 0))["spring"]) / (2 * eps)
    # central differences: truncation O(eps^2 |E'''|) ~ 1e-12 k, rounding ~ 1e-16 E / eps
    err = np.abs(f + grad).max()
    report("max |f + dE/dx| [N]", err, f"< 1e-6 (|f| max {np.abs(f).max():.3g})")
    assert err < 1e-6


def test_internal_forces_sum_to_zero_with_both_damping_models(f64):
    for damping in ("axial", "relative"):
        cloth, x, rng = perturbed_cloth(damping=damping)
        f = forces_at(cloth, x, rng.normal(size=x.shape))
        total = np.abs(f.sum(axis=0)).max()
        report(f"|sum f| ({damping})", total, f"~ rounding of {np.abs(f).sum():.3g}")
        assert total < 1e-13 * np.abs(f).sum()


@pytest.mark.parametrize("damping", ["axial", "relative"])
def test_two_particle_forces_match_hooke_and_damping(f64, damping):
    k, kd, rest = 40.0, 0.7, 1.0
    material = tc.Material(stretch=tc.SpringParams(k, kd), damping=damping)
    cloth = tc.Cloth.from_particles([[0, 0, 0], [rest, 0, 0]], [1.0, 2.0], [[0, 1]], material)
    x = np.array([[0.1, 0.2, -0.1], [1.3, 0.6, 0.1]])
    v = np.array([[0.5, -1.0, 2.0], [-0.3, 0.4, 1.0]])
    f = forces_at(cloth, x, v)
    xij = x[0] - x[1]
    n = xij / np.linalg.norm(xij)
    elastic = -k * (np.linalg.norm(xij) - rest) * n                       # Stuyck eq. 4.5
    vij = v[0] - v[1]
    damp = -kd * vij if damping == "relative" else -kd * np.dot(vij, n) * n  # eq. 4.7 / axial
    report("f_i", f[0], elastic + damp)
    np.testing.assert_allclose(f[0], elastic + damp, rtol=1e-12)
    np.testing.assert_allclose(f[1], -(elastic + damp), rtol=1e-12)     # eq. 4.6


def test_gravity_and_drag(f64):
    cloth, x, rng = perturbed_cloth()
    cloth = tc.Cloth(cloth.mesh, cloth.material, springs=np.zeros((0, 2), int))
    v = rng.normal(size=x.shape)
    g, drag = (0.3, -9.0, 1.2), 0.8
    f = forces_at(cloth, x, v, ForceSettings(gravity=g, drag=drag))
    m = cloth.particle_mass[:, None]
    np.testing.assert_allclose(f, m * np.array(g) - drag * m * v, rtol=1e-12)


def test_zero_length_spring_is_guarded(f64):
    material = tc.Material(stretch=tc.SpringParams(100.0, 1.0))
    cloth = tc.Cloth.from_particles([[0, 0, 0], [0, 0, 0]], [1.0, 1.0], [[0, 1]], material)
    assert cloth.spring_rest_length[0] == 0.0
    f = forces_at(cloth, np.zeros((2, 3)), np.zeros((2, 3)))
    assert np.all(f == 0.0)
    x = np.array([[0.0, 0.0, 0.0], [0.0, 0.2, 0.0]])
    f = forces_at(cloth, x, np.zeros((2, 3)))
    np.testing.assert_allclose(f[0], [0.0, 100.0 * 0.2, 0.0], rtol=1e-12)  # -k (x_i - x_j) at L = 0
