"""Refining a scene's bodies (body/refine.py, app/scene_bodies.py: scene.build(resolution=f)):
the scene's particles come first and in order at every resolution, pins, hems and handles
carry over (checked against geometry computed here: which refined particles lie on a pinned
line), the material stays the same material (total mass, a string's static stretch against
its closed form), and a refined scene runs to the same bits on every rerun and thread count."""

import numpy as np
import pytest
from helpers import users_runtime

import ti_cloth as tc
from ti_cloth.app.scene import SceneError, load_scene
from ti_cloth.runtime import backend

GRID = """
[simulation]
integrator = "symplectic_euler"
fps = 30
duration = 0.1
[[bodies]]
type = "grid"
rows = 5
cols = 4
size = [0.3, 0.4]
pinned = ["top", 0, 1]
material = { hem_mass = 0.002 }
[[bodies.handles]]
particles = ["bottom_right"]
path = { type = "keyframes", times = [0.0, 0.1], values = [[0, 0, 0], [0.05, 0, 0]] }
"""


def on_segment(points, a, b, tol=1e-12):
    """Which points lie on the segment from a to b."""
    ab = b - a
    t = (points - a) @ ab / (ab @ ab)
    foot = a + np.clip(t, 0, 1)[:, None] * ab
    return np.linalg.norm(points - foot, axis=1) <= tol


@pytest.mark.parametrize("factor", [2, 3])
def test_a_refined_grid_keeps_the_scenes_particles_first_and_its_pins(tmp_path, factor):
    path = tmp_path / "grid.toml"
    path.write_text(GRID)
    scene = load_scene(path)
    fine = scene.refined(factor)
    coarse, cloth = scene.cloth, fine.cloth
    n = coarse.particle_count
    x = cloth.particle_position
    assert cloth.particle_count == (4 * factor + 1) * (3 * factor + 1)
    np.testing.assert_array_equal(x[:n], coarse.particle_position)
    np.testing.assert_array_equal(cloth.pinned[:n], coarse.pinned)
    # pinned: the top line and the segment between coarse particles 0 and 1, found here
    top = np.abs(x[:, 1] - x[:, 1].max()) < 1e-12
    between = on_segment(x, coarse.particle_position[0], coarse.particle_position[1])
    np.testing.assert_array_equal(cloth.pinned, top | between)
    assert between.sum() == factor + 1
    # the hem: the bottom row, less its pinned part, each with 1/f of the hem mass
    bottom = np.abs(x[:, 1] - x[:, 1].min()) < 1e-12
    np.testing.assert_array_equal(cloth.hem, bottom & ~cloth.pinned)
    hem_mass = cloth.particle_mass.sum() - 0.3 * 0.4 * tc.Material().density
    assert hem_mass == pytest.approx(0.002 / factor * cloth.hem.sum(), rel=1e-12)
    # the handle holds the same corner, particle 3 of the scene
    assert [h.particles.tolist() for h in fine.handles] == [[3]] == \
        [h.particles.tolist() for h in scene.handles]
    # Stuyck's pattern at the refined size: stretch springs h / f long
    springs = cloth.spring_count_by_kind()
    rows, cols = 4 * factor + 1, 3 * factor + 1
    assert springs["stretch"] == rows * (cols - 1) + cols * (rows - 1)
    stretch = cloth.spring_rest_length[cloth.spring_kind == tc.SpringKind.STRETCH]
    assert set(np.round(stretch * factor, 12)) == {0.1}


MIXED = """
[simulation]
integrator = "symplectic_euler"
fps = 30
duration = 0.1
[[bodies]]
type = "mesh"
path = "disc.obj"
pinned = [0, 1, 2]
[[bodies]]
type = "string"
n = 5
length = 0.4
start = [1, 0, 0]
direction = [0, -1, 0]
stretch = { k = 300, kd = 0.05 }
[[bodies.handles]]
particles = [3, 4]
path = { type = "oscillation", amplitude = [0.01, 0, 0], frequency = 2 }
[[bodies]]
type = "hair"
strands = 3
segments = 4
length = 0.2
anchor = [0, 1, 0]
[[bodies]]
type = "tet_block"
cells = [2, 1, 1]
size = [0.2, 0.1, 0.1]
origin = [-1, 0, 0]
"""


def test_every_kind_of_body_refines_with_the_scenes_particles_first(tmp_path):
    tc.save_mesh(tmp_path / "disc.obj", tc.disc_mesh(0.2, rings=2))
    path = tmp_path / "mixed.toml"
    path.write_text(MIXED)
    scene = load_scene(path)
    fine = scene.refined(2)
    coarse, cloth = scene.cloth, fine.cloth
    n = coarse.particle_count
    assert fine.file_particles == n == scene.file_particles
    shown = ~coarse.ghost
    np.testing.assert_array_equal(cloth.particle_position[:n][shown],
                                  coarse.particle_position[shown])
    np.testing.assert_array_equal(cloth.particle_body[:n], coarse.particle_body)
    np.testing.assert_array_equal(cloth.ghost[:n], coarse.ghost)
    np.testing.assert_array_equal(fine.own_particles, scene.own_particles)
    body = cloth.particle_body
    # each body keeps its mass (areas, lengths and volumes are what masses come from)
    for b in range(4):
        assert cloth.particle_mass[body == b].sum() == pytest.approx(
            coarse.particle_mass[coarse.particle_body == b].sum(), rel=1e-12)
    # the disc: its area, and pins along the two pinned edges 0-1 and 0-2 (1-2 is an edge too)
    disc = np.flatnonzero(body == 0)
    triangles = cloth.mesh.triangles[np.all(body[cloth.mesh.triangles] == 0, axis=1)]
    assert len(triangles) == 4 * len(scene.cloth.mesh.triangles[
        np.all(coarse.particle_body[scene.cloth.mesh.triangles] == 0, axis=1)])
    p = coarse.particle_position
    on_pinned_edges = (on_segment(cloth.particle_position, p[0], p[1])
                       | on_segment(cloth.particle_position, p[0], p[2])
                       | on_segment(cloth.particle_position, p[1], p[2]))
    np.testing.assert_array_equal(cloth.pinned[disc], on_pinned_edges[disc])
    # the string: f x the springs, f x as stiff each (the same EA = k h), its handle on the
    # segment between the scene's particles 3 and 4
    string = np.flatnonzero(body == 1)
    assert len(string) == 9
    springs = np.all(body[cloth.spring_indices] == 1, axis=1)
    assert np.allclose(cloth.spring_stiffness[springs] * cloth.spring_rest_length[springs],
                       300 * 0.1)
    first = np.flatnonzero(coarse.particle_body == 1)[0]
    held = fine.handles[0].particles
    assert held[:2].tolist() == [first + 3, first + 4] == scene.handles[0].particles.tolist()
    assert len(held) == 3
    assert on_segment(cloth.particle_position[held], p[first + 3], p[first + 4]).all()
    # hair: twice the segments; its roots ("roots": found again) pinned as the builder pins
    # them, the root, its ghost and the next strand particle, now half as far
    hair = body == 2
    roots = np.flatnonzero(coarse.particle_body == 2)[[0, 5, 10]]
    assert cloth.pinned[roots].all()
    assert cloth.pinned[hair].sum() == coarse.pinned[coarse.particle_body == 2].sum() == 9
    assert (hair & ~cloth.ghost).sum() == 3 * (4 * 2 + 1)
    block = np.flatnonzero(body == 3)
    assert len(block) == 5 * 3 * 3
    block_springs = np.all(body[cloth.spring_indices] == 3, axis=1)
    coarse_block = np.all(coarse.particle_body[coarse.spring_indices] == 3, axis=1)
    assert cloth.spring_stiffness[block_springs].max() == coarse.spring_stiffness[coarse_block].max() / 2


def test_a_refined_fabric_is_the_same_fabric(tmp_path):
    path = tmp_path / "fabric.toml"
    path.write_text(GRID.replace("material = { hem_mass = 0.002 }",
                                 'fabric = { preset = "denim", hem_mass = 0.002 }')
                    .replace('fps = 30', 'fps = 30\nresolution = 2'))
    scene = load_scene(path)
    assert scene.resolution == 2 and scene.cloth.particle_count == 9 * 7
    coarse = scene.refined(1).cloth
    np.testing.assert_array_equal(scene.cloth.face_moduli[0], coarse.face_moduli[0])
    assert scene.cloth.face_area.sum() == pytest.approx(coarse.face_area.sum(), rel=1e-12)
    assert scene.cloth.material.hem_mass == 0.001
    np.testing.assert_array_equal(scene.cloth.particle_position[:coarse.particle_count],
                                  coarse.particle_position)


def test_resolutions_that_cannot_be_are_named(tmp_path):
    tc.save_mesh(tmp_path / "disc.obj", tc.disc_mesh(0.2, rings=2))
    path = tmp_path / "mixed.toml"
    path.write_text(MIXED)
    scene = load_scene(path)
    with pytest.raises(SceneError, match=r"resolution = 3: resolution must be a power of 2"):
        scene.refined(3)
    with pytest.raises(ValueError, match=r"resolution must be an integer in \[1, 64\], got 65"):
        scene.refined(65)
    path.write_text(MIXED.replace("duration = 0.1", "duration = 0.1\nresolution = 0"))
    with pytest.raises(SceneError, match=r"simulation.resolution must be"):
        load_scene(path)


STRING = """
[simulation]
integrator = "implicit_euler"
fps = 10
duration = 6
substeps = 4
[forces]
drag = 2.0
[[bodies]]
type = "string"
n = 6
length = 0.5
mass = 0.05
direction = [0, -1, 0]
stretch = { k = 40, kd = 0.0 }
"""


def test_a_hanging_string_stretches_as_its_closed_form_at_every_resolution(tmp_path, f64):
    """A string of mass m hanging from its top, its springs standing for EA = k h: at rest it
    is longer by g m L / (2 EA) whatever the resolution (the lumped chain's tensions sum to
    exactly that); keeping k instead would stretch it f times as much."""
    path = tmp_path / "string.toml"
    path.write_text(STRING)
    scene = load_scene(path)
    expected = 9.81 * 0.05 * 0.5 / (2 * 40 * 0.1)
    for factor in (1, 2, 4):
        sim = scene.build(resolution=factor)
        sim.step(scene.frames * scene.resolved_substeps())
        x = sim.positions()
        stretch = x[0, 1] - x[5, 1] - 0.5           # particle 5: the scene's bottom end
        assert stretch == pytest.approx(expected, rel=1e-4), factor


@pytest.mark.reinitialises
def test_a_refined_scene_reruns_to_the_same_bits_on_any_thread_count(tmp_path):
    path = tmp_path / "grid.toml"
    path.write_text(GRID)
    runs = []

    def run():
        sim = load_scene(path).build(resolution=3)
        sim.step(400)
        runs.append(sim.positions())

    with users_runtime():                      # one thread, compiled as users' runs are
        run()
    run()
    run()
    assert backend.cpu_threads() == backend.cpu_cores()
    assert np.abs(runs[0][:20] - load_scene(path).cloth.particle_position).max() > 1e-3
    for other in runs[1:]:
        np.testing.assert_array_equal(other, runs[0])
