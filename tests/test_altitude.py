"""Selle et al. 2008's altitude springs: forces against an independent derivation, the hair's
tetrahedra kept right side out by every integrator, statics against an independent Newton solve,
the stable step, and the same bits in every launch plan and thread count."""

import numpy as np
import pytest
from helpers import report, users_runtime

import ti_cloth as tc
from ti_cloth.body.topology import color_springs
from ti_cloth.energies.altitude import altitude_springs
from ti_cloth.physics.forces import compute_forces, energies
from ti_cloth.runtime import backend

G = 9.81


def independent_altitudes(x, indices):
    """(h, grad h (A, 4, 3)) by the quotient rule on h = D / A: D = (x_p - x_a) . N the
    triple product, A = |N|, N = (x_b - x_a) x (x_c - x_a) (not the simulator's barycentric
    form)."""
    p, a, b, c = (x[indices[:, k]] for k in range(4))
    e1, e2, u = b - a, c - a, p - a
    normal = np.cross(e1, e2)
    area = np.linalg.norm(normal, axis=1)
    unit = normal / area[:, None]
    triple = np.einsum("ij,ij->i", u, normal)
    d_triple = np.stack([normal, np.zeros_like(u), np.cross(e2, u), np.cross(u, e1)], axis=1)
    d_triple[:, 1] = -d_triple[:, 0] - d_triple[:, 2] - d_triple[:, 3]
    d_area = np.stack([np.zeros_like(u), np.zeros_like(u), np.cross(e2, unit), np.cross(unit, e1)],
                      axis=1)
    d_area[:, 1] = -d_area[:, 2] - d_area[:, 3]
    h = triple / area
    return h, d_triple / area[:, None, None] - (triple / area ** 2)[:, None, None] * d_area


def independent_forces(cloth, x, v):
    """Altitude forces -(k (h - h0) + kd dh/dt) grad h per particle."""
    h, grad = independent_altitudes(x, cloth.altitude_indices)
    rate = np.einsum("ack,ack->a", grad, v[cloth.altitude_indices])
    magnitude = -(cloth.altitude_stiffness * (h - cloth.altitude_rest_length)
                  + cloth.altitude_damping * rate)
    f = np.zeros_like(x)
    np.add.at(f, cloth.altitude_indices.ravel(), (magnitude[:, None, None] * grad).reshape(-1, 3))
    return f


def chain_of_tetrahedra(k=10.0, kd=0.5, pinned=()):
    """Six particles, every four consecutive ones a tetrahedron (a ghost chain's pattern)."""
    rng = np.random.default_rng(3)
    x = np.c_[np.arange(6) * 0.1, 0.05 * np.cos(np.arange(6) * np.pi / 2),
              0.05 * np.sin(np.arange(6) * np.pi / 2)] + rng.normal(scale=0.005, size=(6, 3))
    tets = [[0, 1, 2, 3], [1, 2, 3, 4], [2, 3, 4, 5]]
    return tc.Cloth.from_particles(x, np.full(6, 1e-3), np.zeros((0, 2), np.int64), pinned=pinned,
                                   altitude_tetrahedra=tets, altitude=tc.SpringParams(k, kd))


def test_rest_altitudes_are_three_volumes_over_the_face_area_and_positive():
    body = chain_of_tetrahedra()
    h, _ = independent_altitudes(body.particle_position, body.altitude_indices)
    corners = body.particle_position[body.altitude_indices]
    volume = np.abs(np.linalg.det(corners[:, 1:] - corners[:, :1])) / 6
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 2] - corners[:, 1], corners[:, 3] - corners[:, 1]),
                                axis=1)
    assert body.altitude_count == 12 and (h > 0).all()
    np.testing.assert_allclose(body.altitude_rest_length, 3 * volume / area, rtol=1e-12)
    np.testing.assert_allclose(h, body.altitude_rest_length, rtol=1e-12)
    for t in range(3):    # each tetrahedron: every corner once over the other three
        np.testing.assert_array_equal(np.sort(body.altitude_indices[4 * t:4 * t + 4, 0]), [t, t + 1, t + 2, t + 3])


def test_altitude_forces_are_minus_the_gradient_of_their_energy_and_damp_its_rate(f64):
    """Deformed 20 % and moving: every particle's force equals the independent quotient-rule
    gradient to rounding (1e-9 of the largest); the host energy equals 1/2 k (h - h0)^2 summed
    independently; the forces have no net force or torque (the energy is rigid-invariant)."""
    body = chain_of_tetrahedra()
    rng = np.random.default_rng(5)
    x = body.particle_position + rng.normal(scale=0.02, size=(6, 3))
    v = rng.normal(scale=0.5, size=(6, 3))
    sim = tc.Simulation(body, gravity=(0.0, 0.0, 0.0))
    sim.set_positions(x)
    sim.state.particle_velocity.from_numpy(v)
    compute_forces(sim.model, sim.state, sim.forces)
    got = sim.state.particle_force.to_numpy()
    expected = independent_forces(body, x, v)
    scale = np.abs(expected).max()
    report("altitude forces: max |f - independent| / max |f|", np.abs(got - expected).max() / scale,
           "< 1e-9")
    np.testing.assert_allclose(got, expected, atol=1e-9 * scale)
    assert np.abs(got.sum(axis=0)).max() < 1e-12 * scale
    assert np.abs(np.cross(x, got).sum(axis=0)).max() < 1e-12 * scale
    h, _ = independent_altitudes(x, body.altitude_indices)
    energy = 0.5 * np.sum(body.altitude_stiffness * (h - body.altitude_rest_length) ** 2)
    assert energies(body, x, v, (0, 0, 0))["spring_altitude"] == pytest.approx(energy, rel=1e-12)
    assert energy > 0


def test_altitude_colours_share_no_particle_and_bodies_combine_with_offsets():
    body = chain_of_tetrahedra()
    order, offsets = color_springs(body.altitude_indices, body.particle_count)
    assert sorted(order) == list(range(body.altitude_count))
    for c in range(len(offsets) - 1):
        members = body.altitude_indices[order[offsets[c]:offsets[c + 1]]].ravel()
        assert len(members) == len(set(members))
    both = tc.Cloth.combine([tc.string(3, 1.0), body, body])
    np.testing.assert_array_equal(both.altitude_indices, np.concatenate(
        [body.altitude_indices + 3, body.altitude_indices + 9]))
    np.testing.assert_array_equal(both.altitude_rest_length, np.tile(body.altitude_rest_length, 2))


def test_a_flat_tetrahedron_is_refused_by_name():
    x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1]], float)
    with pytest.raises(ValueError, match=r"altitude_tetrahedra\[1\] \(particles \[0, 1, 2, 3\]\) "
                                         r"must have a volume > 0"):
        altitude_springs(x, [[0, 1, 2, 4], [0, 1, 2, 3]])
    with pytest.raises(ValueError, match=r"altitude_tetrahedra\[\[0\]\]"):
        altitude_springs(x, [[0, 1, 2, 7]])
    with pytest.raises(ValueError, match="altitude must be True"):
        tc.hair(2, 3, 0.2, altitude=None)


def cantilever(bend_k, altitude=True, segments=6):
    """A 0.3 m strand rooted at the origin pointing along +x (horizontal)."""
    return tc.hair([[0.0, 0.0, 0.0]], segments, 0.3, directions=[[1.0, 0.0, 0.0]], mass=2e-3,
                   stretch=tc.SpringParams(200.0, 0.05), bend=tc.SpringParams(bend_k, 0.01 * bend_k),
                   altitude=altitude)


def volume_ratios(body, x, segments=6):
    """Signed volume now / at rest of every tetrahedron of a one-strand ghost chain."""
    sequence = np.empty(2 * segments + 1, np.int64)
    sequence[0::2], sequence[1::2] = np.arange(segments + 1), segments + 1 + np.arange(segments)
    tets = np.stack([sequence[a:a + 4] for a in range(2 * segments - 2)])
    rest, now = body.particle_position[tets], x[tets]
    return (np.linalg.det(now[:, 1:] - now[:, :1]) / np.linalg.det(rest[:, 1:] - rest[:, :1]))


@pytest.mark.slow
def test_altitude_springs_keep_soft_strands_right_side_out(f64):
    """A soft horizontal strand (bend 0.5 and 5 N/m) settles with a tetrahedron of its ghost
    chain turned inside out (volume ratio < 0) when only edge springs brace it; with altitude
    springs every tetrahedron keeps at least half its rest volume, same side out."""
    smallest = {}
    for k in (0.5, 5.0):
        for altitude in (False, True):
            body = cantilever(k, altitude)
            sim = tc.Simulation(body, dt="auto", drag=20.0)
            sim.step(round(3.0 / sim.dt))
            smallest[k, altitude] = float(volume_ratios(body, sim.positions()).min())
    report("smallest tetrahedron volume ratio (bend k, altitude springs)", smallest,
           "< 0 without, > 0.5 with")
    for k in (0.5, 5.0):
        assert smallest[k, False] < 0 < 0.5 < smallest[k, True]


def newton_equilibrium(cloth, iterations=40):
    """Static equilibrium of the free particles (springs + altitude springs + weight) by
    Newton's method from the rest shape, the Jacobian by central differences of the
    independent forces; independent of the simulator's kernels."""
    x = cloth.particle_position.copy()
    free = np.flatnonzero(~cloth.pinned)
    gravity = np.array([0.0, -G, 0.0])

    def residual(y):
        f = cloth.particle_mass[:, None] * gravity + independent_forces(cloth, y, 0 * y)
        i, j = cloth.spring_indices.T
        d = y[i] - y[j]
        length = np.linalg.norm(d, axis=1)
        spring = -(cloth.spring_stiffness * (length - cloth.spring_rest_length) / length)[:, None] * d
        np.add.at(f, i, spring)
        np.add.at(f, j, -spring)
        return f[free].ravel()

    for _ in range(iterations):
        r = residual(x)
        if np.abs(r).max() < 1e-13:
            break
        jacobian = np.empty((len(r), len(r)))
        for column in range(len(r)):
            step = np.zeros_like(x)
            step[free[column // 3], column % 3] = 1e-6
            jacobian[:, column] = (residual(x + step) - residual(x - step)) / 2e-6
        x[free] -= np.linalg.solve(jacobian, r).reshape(-1, 3)
    assert np.abs(residual(x)).max() < 1e-12
    return x


FORCE_BASED = ["explicit_euler", "symplectic_euler", "verlet", "rk4", "implicit_euler"]


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["symplectic_euler", "implicit_euler"])
def test_a_braced_strand_settles_at_the_independent_equilibrium(f64, integrator):
    """A cantilever with altitude springs (bend 50 N/m, 9 degrees of droop), 4 s from rest with
    drag: settled within 1e-7 m of the independent Newton equilibrium, symplectic Euler at its
    automatic step and implicit Euler at a 1/60 s frame step."""
    body = cantilever(50.0)
    if integrator == "implicit_euler":
        sim = tc.Simulation(body, integrator=tc.ImplicitEuler(tolerance=1e-9, max_iterations=500),
                            dt=1 / 60, drag=20.0)
    else:
        sim = tc.Simulation(body, dt="auto", drag=20.0)
    sim.step(round(4.0 / sim.dt))
    x, expected = sim.positions(), newton_equilibrium(body)
    report(f"{integrator}: settled vs Newton, max |dx| [m]", np.abs(x - expected).max(), "< 1e-7")
    assert np.abs(x - expected).max() < 1e-7
    assert np.abs(expected - body.particle_position).max() > 0.01, "it does droop"


@pytest.mark.parametrize("integrator", FORCE_BASED)
def test_every_force_based_integrator_holds_the_independent_equilibrium(f64, integrator):
    """Placed at rest at the Newton equilibrium, where the forces cancel to 1e-12 N, a strand
    stays there to 1e-9 m over 300 steps (its automatic step; implicit Euler 1/60 s); a
    missing or wrong altitude force (of the weight's order) would move it by > 1e-6 m."""
    body = cantilever(50.0)
    expected = newton_equilibrium(body)
    sim = tc.Simulation(body, integrator=integrator,
                        dt=1 / 60 if integrator == "implicit_euler" else "auto", drag=20.0)
    sim.set_positions(expected)
    sim.step(300)
    assert np.abs(sim.positions() - expected).max() < 1e-9


@pytest.mark.parametrize("integrator", ["xpbd", "pbd"])
def test_position_based_integrators_keep_a_braced_strand_right_side_out(f64, integrator):
    """Their statics differ (pbd projects fully; xpbd's Gauss-Seidel fixed point is off by
    O(h)), but a soft braced strand dropped from rest stays finite with every tetrahedron at
    more than half its rest volume, same side out."""
    body = cantilever(0.5)
    sim = tc.Simulation(body, integrator=integrator, dt=1 / 240, drag=20.0)
    sim.step(480)
    x = sim.positions()
    assert np.isfinite(x).all() and volume_ratios(body, x).min() > 0.5
    assert np.abs(x - body.particle_position).max() > 0.01, "it moved"


def test_implicit_euler_takes_stiff_altitude_springs_at_a_frame_step(f64):
    """Altitude springs of 5e3 N/m on 70 mg ghosts: the explicit stable step is below 1e-4 s.
    Implicit Euler, whose matrix carries them (k G G^T), takes 1/60 s steps and stays finite
    and right side out (treated explicitly, as wind is, they would blow up at once)."""
    body = cantilever(5.0, altitude=tc.SpringParams(5e3, 1.0))
    assert tc.stable_dt(body, "symplectic_euler", drag=20.0) < 1e-4
    sim = tc.Simulation(body, integrator="implicit_euler", dt=1 / 60, drag=20.0)
    sim.step(60)
    x = sim.positions()
    assert np.isfinite(x).all() and volume_ratios(body, x).min() > 0.9
    assert sim.integrator.last_iterations < 200


def test_the_stable_step_counts_altitude_springs(f64):
    """Stiff altitude springs shorten the predicted step (Lanczos on k G G^T); symplectic Euler
    stays bounded at 0.9 x that prediction and diverges at 1.5 x."""
    body = cantilever(5.0, altitude=tc.SpringParams(500.0, 0.0))
    predicted = tc.stable_dt(body, "symplectic_euler")
    without = tc.stable_dt(cantilever(5.0, altitude=False), "symplectic_euler")
    report("predicted stable dt with / without altitude springs [s]", (predicted, without), "smaller")
    assert predicted < 0.8 * without
    start = body.particle_position + np.random.default_rng(2).normal(scale=1e-3, size=(body.particle_count, 3))
    start[body.pinned] = body.particle_position[body.pinned]
    sim = tc.Simulation(body, dt=0.9 * predicted, gravity=(0, 0, 0))
    sim.set_positions(start)
    sim.step(3000)
    assert np.abs(sim.positions() - body.particle_position).max() < 0.01
    sim.restart(1.5 * predicted)
    sim.set_positions(start)
    with pytest.raises(tc.SimulationDiverged):
        sim.step(3000)


@pytest.mark.reinitialises
@pytest.mark.slow
def test_braced_strands_give_the_same_bits_on_one_thread_and_all_cores():
    """Altitude forces are gathered per particle in a fixed order: implicit Euler (its CG
    sums in fixed blocks) gives identical positions on one CPU thread and on every core (two
    on CI), the one thread compiled as users' runs are and the others as the suite's
    (helpers.users_runtime), and a rerun repeats them. (Every integrator's one worker
    against a team of two: test_stepping; pbd and xpbd's parallel sweeps against the serial
    one: test_implicit_and_xpbd.)"""
    body = tc.hair(2, 5, 0.2, mass=1e-3, curl=(0.02, 0.02))
    results = {}

    def run():
        for integrator in ("implicit_euler",):
            sim = tc.Simulation(body, integrator=integrator, dt=2e-4, drag=1.0,
                                handles=[tc.Handle(np.flatnonzero(body.pinned),
                                                   lambda t: (0.2 * np.sin(20 * t), 0, 0))])
            sim.step(40)
            results.setdefault(integrator, []).append(sim.positions())

    with users_runtime():
        run()
    run()                                          # every core (two on CI), twice
    run()
    assert backend.cpu_threads() == backend.cpu_cores()
    for integrator, runs in results.items():
        assert np.abs(runs[0] - body.particle_position).max() > 1e-3
        for other in runs[1:]:
            np.testing.assert_array_equal(other, runs[0])


def test_scene_files_choose_the_altitude_springs(tmp_path):
    """altitude = true: the twist constants (here bend's); false: none; a table: those."""
    from ti_cloth.app.scene import load_scene
    counts = {}
    for value in ("true", "false", "{ k = 7.0, kd = 0.1 }"):
        path = tmp_path / "hair.toml"
        path.write_text(f'[[bodies]]\ntype = "hair"\nstrands = 2\nsegments = 3\n'
                        f'bend = {{ k = 3.0 }}\naltitude = {value}\n')
        cloth = load_scene(path).cloth
        counts[value] = cloth.altitude_count
        if cloth.altitude_count:
            expected = (3.0, 0.0) if value == "true" else (7.0, 0.1)
            assert (cloth.altitude_stiffness[0], cloth.altitude_damping[0]) == expected
    assert counts == {"true": 2 * 4 * 4, "false": 0, "{ k = 7.0, kd = 0.1 }": 2 * 4 * 4}
