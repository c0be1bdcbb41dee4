"""Strings, hair strands and tetrahedral soft bodies: construction, statics against independent
solutions, and a soft block dropped on the ground."""

import numpy as np
import pytest

import ti_cloth as tc
from helpers import report

G = 9.81


def settle(sim, seconds):
    sim.step(int(round(seconds / sim.dt)))
    return sim.positions()


def string_equilibrium(cloth, x0, iterations=50):
    """Static equilibrium of a string (free particles only) by Newton's method on
    sum of spring forces + m g = 0, with the analytic spring Jacobian; independent of the
    simulator's kernels."""
    x = x0.copy()
    free = np.flatnonzero(~cloth.pinned)
    index = {p: a for a, p in enumerate(free)}
    gravity = np.array([0.0, -G, 0.0])
    for _ in range(iterations):
        residual = cloth.particle_mass[:, None] * gravity
        jacobian = np.zeros((3 * len(free), 3 * len(free)))
        for (i, j), rest, k in zip(cloth.spring_indices, cloth.spring_rest_length, cloth.spring_stiffness):
            d = x[i] - x[j]
            length = np.linalg.norm(d)
            n = d / length
            f = -k * (length - rest) * n
            residual[i] += f
            residual[j] -= f
            block = -k * ((1 - rest / length) * (np.eye(3) - np.outer(n, n)) + np.outer(n, n))
            for a, b, sign in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
                if a in index and b in index:
                    jacobian[3 * index[a]:3 * index[a] + 3, 3 * index[b]:3 * index[b] + 3] += sign * block
        r = residual[free].ravel()
        if np.abs(r).max() < 1e-14:
            break
        x[free] -= np.linalg.solve(jacobian, r).reshape(-1, 3)
    return x


def test_string_fixed_at_both_ends_sags_to_the_independent_equilibrium(f64):
    """The lecture's string held at both ends: after the motion has died out, every particle
    sits within 1e-6 m of the equilibrium found by Newton's method. Drag (1/s) only speeds up
    the settling; it does not change the equilibrium."""
    cloth = tc.string(11, 1.0, mass=0.1, stretch=tc.SpringParams(500.0, 0.1), fixed="both")
    guess = cloth.particle_position.copy()
    guess[:, 1] -= 0.4 * np.sin(np.pi * guess[:, 0])
    expected = string_equilibrium(cloth, guess)
    sim = tc.Simulation(cloth, dt=1e-3, drag=20.0)
    got = settle(sim, 4.0)
    err = np.abs(got - expected).max()
    report("mid-span sag [m]", -got[5, 1], -expected[5, 1])
    report("max |x - x_newton| [m]", err, "< 1e-6")
    assert err < 1e-6
    assert expected[5, 1] < -0.05      # a real sag, not the straight rest line


@pytest.mark.parametrize("end_mass", ["half", "full"])
def test_hanging_string_stretches_by_the_weight_below_each_spring(f64, end_mass):
    """Fixed at the top, free below: spring j carries the weight of the particles under it,
    so its length is L + g sum(m below) / k (closed form), with lumped ends or the lecture's
    equal masses."""
    n, k = 8, 200.0
    cloth = tc.string(n, 0.7, mass=0.2, stretch=tc.SpringParams(k, 0.05), direction=(0, -1, 0),
                      end_mass=end_mass)
    sim = tc.Simulation(cloth, dt=1e-3, drag=15.0)
    x = settle(sim, 4.0)
    below = np.cumsum(cloth.particle_mass[::-1])[::-1][1:]
    expected = cloth.spring_rest_length + G * below / k
    got = np.linalg.norm(np.diff(x, axis=0), axis=1)
    report("spring lengths [m]", got, expected)
    assert np.abs(got - expected).max() < 1e-6
    assert np.abs(x[:, [0, 2]]).max() < 1e-9     # straight down


def test_string_layout_masses_and_ends():
    cloth = tc.string(5, 2.0, mass=1.0, start=(1, 2, 3), direction=(0, 0, 2), fixed="both",
                      bend=tc.SpringParams(3.0))
    np.testing.assert_allclose(cloth.particle_position[-1], [1, 2, 5])
    np.testing.assert_allclose(cloth.particle_mass, [0.125, 0.25, 0.25, 0.25, 0.125])
    lecture = tc.string(5, 2.0, mass=1.0, end_mass="full")
    np.testing.assert_allclose(lecture.particle_mass, [0.2] * 5)      # the same m everywhere
    assert cloth.pinned.tolist() == [True, False, False, False, True]
    assert cloth.spring_count_by_kind() == {"stretch": 4, "shear": 0, "bend": 3}
    np.testing.assert_allclose(cloth.spring_rest_length[cloth.spring_kind == tc.SpringKind.BEND], 1.0)


@pytest.mark.parametrize("kwargs, field", [
    (dict(n=1, length=1.0), "n"), (dict(n=4, length=0.0), "length"),
    (dict(n=4, length=1.0, fixed="left"), "fixed"), (dict(n=4, length=1.0, end_mass="heavy"), "end_mass"), (dict(n=4, length=1.0, direction=(0, 0, 0)), "direction"),
])
def test_string_rejects_bad_input_by_name(kwargs, field):
    with pytest.raises(ValueError, match=field):
        tc.string(**kwargs)


def test_hair_roots_lie_on_the_head_and_strands_point_outwards():
    body = tc.hair(40, 6, 0.3, anchor=(0, 1.5, 0), radius=0.1, mass=2e-3)
    roots = np.flatnonzero(body.pinned)
    assert body.particle_count == 40 * 7 and len(roots) == 40
    np.testing.assert_array_equal(roots, np.arange(40) * 7)
    x = body.particle_position
    np.testing.assert_allclose(np.linalg.norm(x[roots] - [0, 1.5, 0], axis=1), 0.1)
    assert (x[roots, 1] >= 1.5).all()
    tips = x[roots + 6]
    np.testing.assert_allclose(np.linalg.norm(tips - [0, 1.5, 0], axis=1), 0.4)
    assert body.spring_count_by_kind() == {"stretch": 40 * 6, "shear": 0, "bend": 40 * 5}
    np.testing.assert_allclose(body.particle_mass.reshape(40, 7).sum(axis=1), 2e-3)


@pytest.mark.slow
def test_hair_follows_a_moving_head_and_the_tips_lag(f64):
    """Roots moved by a Handle follow the head exactly; a strand's tip trails behind, and
    once the head stops the strands hang straight down again below their roots."""
    body = tc.hair([[0.0, 1.0, 0.0]], 8, 0.4, directions=[[0.0, -1.0, 0.0]], mass=1e-3,
                   stretch=tc.SpringParams(20.0, 0.01), bend=tc.SpringParams(0.5, 0.001))
    path = lambda t: (0.5 * min(t, 0.5), 0.0, 0.0)          # 1 m/s for 0.5 s, then still
    sim = tc.Simulation(body, dt=5e-4, drag=4.0,       # a quarter of the stable step
                        handles=[tc.Handle(np.flatnonzero(body.pinned), path)])
    sim.step(500)                                          # t = 0.25 s, head moving
    x = sim.positions()
    report("root x, tip x while moving [m]", (x[0, 0], x[-1, 0]), "0.125, behind it")
    assert abs(x[0, 0] - 0.125) < 1e-12
    assert x[-1, 0] < x[0, 0] - 0.01
    x = settle(sim, 6.0)
    report("tip offset from the root after the head stopped [m]", x[-1] - x[0], "straight down")
    assert np.abs(x[:, 0] - 0.25).max() < 1e-4
    assert (np.diff(x[:, 1]) < 0).all()


def test_hair_rejects_bad_input_by_name():
    with pytest.raises(ValueError, match="segments"):
        tc.hair(3, 0, 0.2)
    with pytest.raises(ValueError, match="directions"):
        tc.hair([[0, 0, 0]], 3, 0.2)


def test_tet_grid_tetrahedra_fill_the_box_and_its_surface_is_closed_and_outward():
    mesh = tc.tet_grid_mesh((3, 2, 4), size=(0.6, 0.3, 0.8), origin=(1, 0, 0))
    volumes = mesh.tetrahedron_volumes()
    assert len(volumes) == 6 * 24 and (volumes > 0).all()
    np.testing.assert_allclose(volumes.sum(), 0.6 * 0.3 * 0.8)
    p = mesh.vertices[mesh.triangles]
    area_vectors = 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    np.testing.assert_allclose(area_vectors.sum(axis=0), 0, atol=1e-15)       # closed
    enclosed = np.einsum("ij,ij->", p.mean(axis=1), area_vectors) / 3        # divergence theorem
    report("volume enclosed by the surface [m^3]", enclosed, 0.6 * 0.3 * 0.8)
    np.testing.assert_allclose(enclosed, 0.6 * 0.3 * 0.8)
    assert len(mesh.triangles) == 2 * 2 * (3 * 2 + 2 * 4 + 3 * 4)


def test_tet_block_mass_is_volume_times_density():
    body = tc.tet_block(cells=(3, 2, 2), size=(0.3, 0.2, 0.25), density=750.0)
    report("total mass [kg]", body.particle_mass.sum(), 0.3 * 0.2 * 0.25 * 750)
    np.testing.assert_allclose(body.particle_mass.sum(), 0.3 * 0.2 * 0.25 * 750)
    tets = body.mesh.tetrahedra
    edges = {tuple(sorted((t[a], t[b]))) for t in tets for a in range(4) for b in range(a + 1, 4)}
    assert set(map(tuple, body.spring_indices.tolist())) == edges
    assert body.spring_count == len(edges)


@pytest.mark.slow
def test_tet_block_dropped_on_the_ground_rests_with_every_volume_within_ten_percent(f64):
    body = tc.tet_block(cells=(3, 3, 3), size=(0.3, 0.3, 0.3), origin=(0.0, 0.2, 0.0),
                        density=500.0, stretch=tc.SpringParams(2e4, 5.0))
    rest = body.mesh.tetrahedron_volumes()
    sim = tc.Simulation(body, dt=5e-4, drag=1.0, colliders=[tc.Plane(static_friction=0.5)])
    worst = 0.0
    for _ in range(40):
        sim.step(100)
        ratio = tc.mesh.signed_volumes(sim.positions(), body.mesh.tetrahedra) / rest
        worst = max(worst, float(np.abs(ratio - 1).max()))
        assert (ratio > 0).all(), f"a tetrahedron inverted at t = {sim.time:.2f} s"
    x = sim.positions()
    ratio = tc.mesh.signed_volumes(x, body.mesh.tetrahedra) / rest
    speed = np.abs(sim.velocities()).max()
    report("volume ratio range at rest, worst during the fall", (ratio.min(), ratio.max(), worst),
           "within [0.9, 1.1] at rest")
    report("lowest particle [m], largest speed [m/s]", (x[:, 1].min(), speed), "0, ~0")
    assert np.abs(ratio - 1).max() < 0.10
    assert abs(x[:, 1].min()) < 1e-9 and speed < 1e-2


def test_soft_body_rejects_a_flat_tetrahedron():
    mesh = tc.Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2]], tetrahedra=[[0, 1, 2, 3]])
    with pytest.raises(ValueError, match=r"tetrahedra\[0\].*volume > 0"):
        tc.soft_body(mesh)
    with pytest.raises(ValueError, match="tetrahedra"):
        tc.Mesh([[0, 0, 0]] * 4, [], tetrahedra=[[0, 1, 2, 2]])


def test_volume_mesh_files_load_with_their_tetrahedra(tmp_path):
    import meshio

    mesh = tc.tet_grid_mesh((2, 1, 1))
    flipped = mesh.tetrahedra[:, [1, 0, 2, 3]]               # a file may wind them either way
    meshio.write_points_cells(tmp_path / "block.vtk", mesh.vertices, [("tetra", flipped)])
    loaded = tc.load_mesh(tmp_path / "block.vtk")
    assert (loaded.tetrahedron_volumes() > 0).all()
    np.testing.assert_allclose(loaded.tetrahedron_volumes().sum(), 1.0)
    assert len(loaded.triangles) == len(mesh.triangles)
