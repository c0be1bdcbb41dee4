"""Keyframed and periodic paths, and handles and colliders following them."""

import numpy as np
import pytest
from helpers import report

import ti_cloth as tc

TIMES = [0.0, 0.5, 1.5, 2.0]
VALUES = [[0, 0, 0], [1, 0, 0], [1, 2, 0], [0, 2, -1]]


@pytest.mark.parametrize("interpolation", ["linear", "smooth"])
def test_keyframes_pass_through_every_key_and_hold_outside(interpolation):
    path = tc.Keyframes(TIMES, VALUES, interpolation)
    for t, v in zip(TIMES, VALUES):
        np.testing.assert_allclose(path(t), v, atol=1e-15)
    np.testing.assert_allclose(path(-1.0), VALUES[0])
    np.testing.assert_allclose(path(9.0), VALUES[-1])


def test_linear_keyframes_interpolate_at_constant_speed():
    path = tc.Keyframes(TIMES, VALUES)
    np.testing.assert_allclose(path(0.25), [0.5, 0, 0])
    np.testing.assert_allclose(path(1.0), [1, 1, 0])
    np.testing.assert_allclose(path(1.875), [0.25, 2, -0.75])


def test_smooth_keyframes_have_continuous_velocity_at_the_keys():
    path = tc.Keyframes(TIMES, VALUES, "smooth")
    eps = 1e-6
    for t in TIMES[1:-1]:
        left = (path(t) - path(t - eps)) / eps
        right = (path(t + eps) - path(t)) / eps
        report(f"velocity either side of t={t}", (left, right), "equal to O(eps)")
        np.testing.assert_allclose(left, right, atol=1e-4)


def test_smooth_keyframes_on_a_line_at_even_speed_reproduce_it():
    """Hermite interpolation with difference tangents is exact for linear motion, whatever
    the key spacing."""
    times = np.array([0.0, 0.3, 1.0, 1.2, 2.0])
    velocity = np.array([0.5, -1.0, 2.0])
    path = tc.Keyframes(times, times[:, None] * velocity, "smooth")
    for t in np.linspace(0, 2, 37):
        np.testing.assert_allclose(path(t), t * velocity, atol=1e-14)


def test_oscillation_matches_its_formula():
    path = tc.Oscillation((0.1, 0, 0.2), frequency=2.0, phase=0.3, start=0.5)
    np.testing.assert_allclose(path(0.4), 0)
    t = 0.9
    np.testing.assert_allclose(path(t), np.array([0.1, 0, 0.2]) * np.sin(4 * np.pi * 0.4 + 0.3))


@pytest.mark.parametrize("make, field", [
    (lambda: tc.Keyframes([0, 0], [[0, 0, 0]] * 2), "Keyframes.times"),
    (lambda: tc.Keyframes([0, 1], [[0, 0]] * 2), "Keyframes.values"),
    (lambda: tc.Keyframes([0, 1], [[0, 0, 0]] * 2, "cubic"), "Keyframes.interpolation"),
    (lambda: tc.Oscillation((1, 0, 0), frequency=0.0), "Oscillation.frequency"),
])
def test_paths_reject_bad_input_by_name(make, field):
    with pytest.raises(ValueError, match=field):
        make()


def test_a_handle_follows_keyframes_and_a_collider_follows_an_oscillation(f64):
    """The held particle sits exactly on the keyed path at every step; a particle resting on a
    box that bobs up and down rides it (it is never inside the box)."""
    cloth = tc.string(4, 0.3, mass=0.01, fixed="none")
    path = tc.Keyframes([0.0, 0.1, 0.2], [[0, 0, 0], [0.1, 0.1, 0], [0.1, 0.3, 0]], "smooth")
    sim = tc.Simulation(cloth, dt=1e-3, handles=[tc.Handle([0], path)])
    for _ in range(25):
        sim.step(10)
        np.testing.assert_allclose(sim.positions()[0], cloth.particle_position[0] + path(sim.time),
                                   atol=1e-12)

    bob = tc.Oscillation((0, 0.05, 0), frequency=1.0)
    particle = tc.Cloth.from_particles([[0, 0.5, 0]], [0.1], np.zeros((0, 2), int))
    box = tc.Box(lo=(-1, -1, -1), hi=(1, 0.5, 1), path=bob)
    sim = tc.Simulation(particle, dt=1e-3, colliders=[box])
    for _ in range(100):
        sim.step(10)
        top = 0.5 + bob(sim.time)[1]
        assert sim.positions()[0, 1] >= top - 1e-12
    report("height above the box top at the end [m]", sim.positions()[0, 1] - top, ">= 0, small")
    assert sim.positions()[0, 1] - top < 0.01
