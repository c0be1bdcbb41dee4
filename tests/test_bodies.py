"""Strings, hair strands and tetrahedral soft bodies: construction, statics against independent
solutions, and a soft block dropped on the ground."""

import numpy as np
import pytest
from helpers import report

import ti_cloth as tc
from ti_cloth.body.bodies import GHOST_SHARE
from ti_cloth.body.mesh import signed_volumes

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
    body = tc.hair(40, 6, 0.3, anchor=(0, 1.5, 0), radius=0.1, mass=2e-3, ghosts=False)
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
                   stretch=tc.SpringParams(20.0, 0.01), bend=tc.SpringParams(0.5, 0.001),
                   ghosts=False)
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


def test_hair_ghosts_make_a_chain_of_tetrahedra_with_pinned_root_segment():
    """Selle et al. 2008 as fig. 4.5 draws it: strand particles keep their indices and rest
    positions, a ghost beside every segment after them, every root/ghost/particle/ghost
    quadruple a tetrahedron of volume > 0, springs to the next three of the sequence, the root
    segment pinned, GHOST_SHARE of each strand's mass on its ghosts."""
    plain = tc.hair(3, 4, 0.3, mass=1e-3, ghosts=False)
    body = tc.hair(3, 4, 0.3, mass=1e-3)
    real, ghost = np.arange(15).reshape(3, 5), 15 + np.arange(12).reshape(3, 4)
    np.testing.assert_array_equal(body.particle_position[:15], plain.particle_position)
    np.testing.assert_array_equal(np.flatnonzero(body.ghost), ghost.ravel())
    np.testing.assert_array_equal(np.flatnonzero(body.pinned),
                                  sorted([*real[:, 0], *real[:, 1], *ghost[:, 0]]))
    share = GHOST_SHARE
    np.testing.assert_allclose(body.particle_mass[real].sum(axis=1), (1 - share) * 1e-3)
    np.testing.assert_allclose(body.particle_mass[ghost].sum(axis=1), share * 1e-3)
    sequence = np.empty((3, 9), int)
    sequence[:, 0::2], sequence[:, 1::2] = real, ghost
    x, segment = body.particle_position, 0.3 / 4
    expected = set()
    for strand in sequence:
        for a in range(6):
            tet = x[strand[a:a + 4]]
            volume = abs(np.linalg.det(tet[1:] - tet[0])) / 6
            assert volume > 1e-2 * segment ** 3, "a flat tetrahedron"
        expected |= {tuple(sorted((strand[a], strand[a + o]))) for o in (1, 2, 3)
                     for a in range(9 - o)}
    assert set(map(tuple, body.spring_indices)) == expected
    edges = np.isin(body.spring_indices, real).all(axis=1) & (body.spring_kind == tc.SpringKind.STRETCH)
    np.testing.assert_allclose(body.spring_rest_length[edges], segment)


def cantilever(bend_k, ghosts=True, segments=6, altitude=True):
    """A 0.3 m strand rooted at the origin pointing along +x (horizontal)."""
    return tc.hair([[0.0, 0.0, 0.0]], segments, 0.3, directions=[[1.0, 0.0, 0.0]], mass=2e-3,
                   stretch=tc.SpringParams(200.0, 0.05), bend=tc.SpringParams(bend_k, 0.01 * bend_k),
                   ghosts=ghosts, altitude=altitude)


def droop_degrees(x, segments=6):
    tip = x[segments] - x[0]
    return np.degrees(np.arctan2(-tip[1], tip[0]))


@pytest.mark.slow
def test_a_cantilever_strand_droops_less_the_stiffer_it_bends(f64):
    """Rooted horizontally: with ghosts the tip droops less as bend stiffness grows and stays
    within 10 degrees of horizontal when stiff; without them (the plain chain) nothing holds
    the root's direction and the strand hangs whatever its bend stiffness (the issue's 87°)."""
    droops = {}
    for k in (0.5, 5.0, 50.0, 500.0):
        sim = tc.Simulation(cantilever(k), dt="auto", drag=20.0)
        droops[k] = droop_degrees(settle(sim, 3.0))
    plain = tc.Simulation(cantilever(500.0, ghosts=False), dt="auto", drag=20.0)
    hanging = droop_degrees(settle(plain, 3.0))
    report("tip droop [deg] by bend k; plain chain at k = 500", (droops, hanging),
           "falling; < 10; > 60")
    values = [droops[k] for k in sorted(droops)]
    assert all(a > b for a, b in zip(values, values[1:]))
    assert 0 < droops[500.0] < 10 and hanging > 60


@pytest.mark.slow
def test_a_stiff_cantilever_settles_at_the_minimum_of_its_spring_energy(f64):
    """The settled shape equals the equilibrium found independently (Newton on the spring
    forces plus weight, from the rest shape; its Jacobian negative definite there, so a
    minimum of the energy), to 1e-7 m. Edge springs only: with altitude springs as well,
    test_altitude.py."""
    body = cantilever(50.0, altitude=False)
    sim = tc.Simulation(body, dt="auto", drag=20.0)
    x = settle(sim, 4.0)
    expected = string_equilibrium(body, body.particle_position.copy())
    report("settled vs energy minimum, max |dx| [m]", np.abs(x - expected).max(), "< 1e-7")
    assert np.abs(x - expected).max() < 1e-7
    assert droop_degrees(expected) > 0.1, "it does droop"


def rigid_misfit(x, rest):
    """Largest distance [m] between x and rest after the best rigid motion (Kabsch)."""
    a, b = x - x.mean(axis=0), rest - rest.mean(axis=0)
    u, _, vt = np.linalg.svd(a.T @ b)
    flip = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    return float(np.linalg.norm(a @ (u @ flip @ vt) - b, axis=1).max())


@pytest.mark.slow
def test_a_curly_strand_keeps_its_helix_while_hanging(f64):
    """A helix of radius 2 cm and pitch 1 cm (2 turns) rooted pointing down: its rest strand
    particles lie on the helix; hanging under its own weight the ghost-braced strand keeps that
    shape up to a rigid motion within a quarter of the radius, where the plain chain (no
    ghosts, the same springs) loses it. A coil is soft in extension: it takes springs of
    2e4 N/m to hold 0.5 g of hair (2e3 N/m leave it 7 cm off at 4 turns)."""
    radius, pitch, segments, length = 0.02, 0.01, 12, 0.25
    misfit = {}
    for ghosts in (True, False):
        body = tc.hair([[0.0, 0.0, 0.0]], segments, length, directions=[[0.0, -1.0, 0.0]],
                       mass=5e-4, stretch=tc.SpringParams(2e4, 0.2),
                       bend=tc.SpringParams(2e4, 0.2), curl=(radius, pitch), ghosts=ghosts,
                       altitude=tc.SpringParams(2e3, 0.02))   # softer: a 3x longer stable step
        rest = body.particle_position[:segments + 1]
        flat = rest[:, [0, 2]]                    # circle fit: |p|^2 = 2 c . p + const
        solution = np.linalg.lstsq(np.c_[2 * flat, np.ones(len(flat))], (flat ** 2).sum(axis=1),
                                   rcond=None)[0]
        around = flat - solution[:2]
        np.testing.assert_allclose(np.linalg.norm(around, axis=1), radius, rtol=1e-9)
        turns = np.unwrap(np.arctan2(around[:, 1], around[:, 0]))
        assert abs(turns[-1] - turns[0]) / (2 * np.pi) == pytest.approx(
            length / np.hypot(2 * np.pi * radius, pitch), rel=1e-9)
        np.testing.assert_allclose(np.diff(rest[:, 1]), -pitch * length / segments
                                   / np.hypot(2 * np.pi * radius, pitch), rtol=1e-9)
        x = settle(tc.Simulation(body, dt="auto", drag=20.0), 1.5)[:segments + 1]
        misfit[ghosts] = rigid_misfit(x, rest)
    report("helix misfit after hanging, ghosts / plain [m]", misfit, f"< {0.25 * radius} / more")
    assert misfit[True] < 0.25 * radius < misfit[False]


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
    sim = tc.Simulation(body, dt=5e-4, drag=1.0, colliders=[tc.Plane(static_friction=0.5, thickness=0.0)])
    worst = 0.0
    for _ in range(40):
        sim.step(100)
        ratio = signed_volumes(sim.positions(), body.mesh.tetrahedra) / rest
        worst = max(worst, float(np.abs(ratio - 1).max()))
        assert (ratio > 0).all(), f"a tetrahedron inverted at t = {sim.time:.2f} s"
    x = sim.positions()
    ratio = signed_volumes(x, body.mesh.tetrahedra) / rest
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
