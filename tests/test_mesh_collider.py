"""Mesh colliders (mesh_collider.py, sdf.py, collision.py) against independent geometry: an
icosphere mesh against the analytic Sphere, a table of boxes tested point by point, a bowl's
radius, a platform's path and a turntable's angle."""

import math
import sys

import numpy as np
import pytest
from helpers import report

import ti_cloth as tc
from ti_cloth.contact.colliders import sdf

THICKNESS = 0.01


def far_particle():
    return tc.Cloth.from_particles([[50.0, 50.0, 50.0]], [0.01], np.zeros((0, 2), int))


def sheet(n, size, height, centre=(0.0, 0.0)):
    """An n x n horizontal cloth of side `size` [m] at `height` [m] centred over `centre` (x, z)."""
    origin = (centre[0] - size / 2, height, centre[1] - size / 2)
    return tc.Cloth(tc.grid_mesh(n, n, size=(size, size), plane="xz", origin=origin),
                    tc.Material())


def test_an_icosphere_mesh_measures_what_the_analytic_sphere_does(f64):
    """Distances and normals sampled from the mesh's grid against |x - c| - R: within half a
    cell in the band the grid is exact in (in fact within the facets' depth plus trilinear
    interpolation's (h^2 / 8) x trace of the Hessian, 2 / r), the sign right everywhere beyond a cell of the surface, the
    normals radial to a few degrees."""
    radius, centre = 0.3, np.array([0.0, 0.5, 0.0])
    collider = tc.MeshCollider(tc.sphere_mesh(radius, centre, subdivisions=4), resolution=48)
    sim = tc.Simulation(far_particle(), colliders=[collider])
    cell = collider.grid().cell
    points = centre + np.random.default_rng(1).uniform(-0.45, 0.45, (6000, 3))
    d, n = sim.collider_distance(points)
    offset = points - centre
    exact = np.linalg.norm(offset, axis=1) - radius
    band = np.abs(exact) < collider.margin - 2 * cell
    error = np.abs(d - exact)[band]
    facets = radius * 0.3 / 4**4
    bound = facets + cell**2 / (4 * (radius - collider.margin))
    radial = offset / np.linalg.norm(offset, axis=1, keepdims=True)
    angle = np.degrees(np.arccos(np.clip(np.sum(n * radial, axis=1), -1, 1)))[band]
    report("largest distance error in the band, bound, half a cell [m]; largest normal angle",
           (error.max(), bound, cell / 2, angle.max()), "")
    assert band.sum() > 400
    assert error.max() < bound < cell / 2
    outside_a_cell = np.abs(exact) > cell
    assert np.array_equal(np.sign(d[outside_a_cell]), np.sign(exact[outside_a_cell]))
    assert angle.max() < 3.0


@pytest.mark.slow
def test_a_cloth_draped_on_the_icosphere_ends_where_it_does_on_the_sphere(f64):
    radius, centre = 0.3, (0.0, 0.5, 0.0)
    mesh = tc.MeshCollider(tc.sphere_mesh(radius, centre, subdivisions=4), resolution=48,
                           thickness=THICKNESS, static_friction=0.4)
    sphere = tc.Sphere(centre=centre, radius=radius, thickness=THICKNESS, static_friction=0.4)
    final = {}
    for name, collider in (("sphere", sphere), ("mesh", mesh)):
        sim = tc.Simulation(sheet(12, 1.0, 0.85), integrator="xpbd", dt=1 / 120, drag=1.0,
                            colliders=[collider])
        sim.step(240)
        final[name] = sim.positions()
    apart = np.linalg.norm(final["mesh"] - final["sphere"], axis=1).max()
    report("largest distance between the drapes, a cell [m]", (apart, mesh.grid().cell), "")
    assert final["mesh"][:, 1].min() < 0.4                 # it drapes, not still flat
    assert apart < mesh.grid().cell


TABLE_BOXES = [((-0.4, 0.70, -0.3), (0.4, 0.75, 0.3))] + [
    ((x - 0.025, 0.0, z - 0.025), (x + 0.025, 0.70, z + 0.025))
    for x in (-0.35, 0.35) for z in (-0.25, 0.25)]


def inside_boxes(points, boxes, by=0.0):
    """Which points lie inside any of the boxes grown by `by` [m] (an independent inside test)."""
    inside = np.zeros(len(points), bool)
    for lo, hi in boxes:
        inside |= np.all((points > np.subtract(lo, by)) & (points < np.add(hi, by)), axis=1)
    return inside


@pytest.mark.slow
def test_a_cloth_dropped_on_a_table_mesh_never_enters_it_and_rests_on_it(f64):
    """A 1 m cloth falls 25 cm onto a table made of five boxes (a 5 cm top on four legs) and
    hangs over its edges. After every step no particle is inside a box, nor closer to one than
    the thickness less half a cell (the grid rounds the table's edges by about that). After
    3 s it is at rest, lying on the top: the lowest particles over it at the thickness exactly
    (trilinear interpolation is exact for the top's planar distance), the rest in low
    wrinkles. Without the collider the cloth falls into the table."""
    table = tc.combine_meshes([tc.box_mesh(lo, hi) for lo, hi in TABLE_BOXES])
    collider = tc.MeshCollider(table, thickness=THICKNESS, static_friction=0.3)
    cell = collider.grid().cell
    runs = {}
    for colliders, steps in (([collider], 720), ([], 120)):
        sim = tc.Simulation(sheet(14, 1.0, 1.0), integrator="xpbd", dt=1 / 240, drag=1.0,
                            colliders=colliders)
        inside = near = 0
        for _ in range(steps):
            sim.step(1)
            x = sim.positions()
            inside += inside_boxes(x, TABLE_BOXES).sum()
            near += inside_boxes(x, TABLE_BOXES, THICKNESS - cell / 2).sum()
        runs[bool(colliders)] = inside, near, sim
    inside, near, sim = runs[True]
    x, v = sim.positions(), sim.velocities()
    over_top = (np.abs(x[:, 0]) < 0.35) & (np.abs(x[:, 2]) < 0.25)
    speed = np.sqrt(np.mean(np.sum(v**2, axis=1)))
    report("inside, too near (all steps); over the top: lowest, highest; rms speed; inside "
           "without", (inside, near, x[over_top, 1].min(), x[over_top, 1].max(), speed,
                       runs[False][0]), (0, 0, 0.75 + THICKNESS, "< 0.78", "< 0.02", "> 0"))
    assert inside == 0 and near == 0
    assert abs(x[over_top, 1].min() - (0.75 + THICKNESS)) < 1e-9
    assert x[over_top, 1].max() < 0.75 + THICKNESS + 0.02
    assert speed < 0.02
    assert x[:, 1].min() < 0.6                              # it hangs over the edges
    assert runs[False][0] > 0


def bowl(radius, centre):
    """The lower half of an icosphere: an open bowl (its rim is a boundary)."""
    sphere = tc.sphere_mesh(radius, centre, subdivisions=3)
    lower = np.all(sphere.vertices[sphere.triangles][:, :, 1] <= centre[1] + 1e-9, axis=1)
    return tc.Mesh(sphere.vertices, sphere.triangles[lower])


@pytest.mark.slow
def test_cloth_falls_into_an_open_bowl_and_stays_inside_its_shell(f64):
    """An open hemisphere (not watertight: a shell) catches a cloth dropped into it: the cloth
    ends down in the bowl, touching the shell, and no particle below the rim ever gets farther
    from the centre than the radius less the thickness, give or take the facets' depth and the
    trilinear error h^2 / (4 r).
    Taken as a solid instead, the winding number fills the bowl to its rim while the nearest
    surface is the bowl's bottom: the cloth is pushed through the bottom and falls away."""
    radius, centre, thickness = 0.3, np.array([0.0, 0.5, 0.0]), 0.02
    mesh = bowl(radius, centre)
    shell = tc.MeshCollider(mesh, thickness=thickness, static_friction=0.2, resolution=48)
    assert shell.solid is False
    cell = shell.grid().cell
    lowest, highest, farthest = {}, {}, {}
    for collider in (shell, tc.MeshCollider(mesh, thickness=thickness, solid=True,
                                            resolution=48)):
        sim = tc.Simulation(sheet(8, 0.3, 0.6), integrator="xpbd", dt=1 / 240, drag=0.5,
                            colliders=[collider])
        farthest[collider.solid] = 0.0
        for _ in range(60):
            sim.step(6)
            x = sim.positions()
            in_bowl = x[:, 1] < centre[1]
            farthest[collider.solid] = max(farthest[collider.solid], np.linalg.norm(
                x[in_bowl] - centre, axis=1).max(initial=0.0))
        lowest[collider.solid] = x[:, 1].min()
        highest[collider.solid] = x[:, 1].max()
    bound = radius - thickness + radius * 0.3 / 4**3 + cell**2 / (4 * (radius - thickness))
    report("farthest from the centre (shell), bound; highest, lowest (shell); lowest (solid)",
           (farthest[False], bound, highest[False], lowest[False], lowest[True]),
           (f"{radius - thickness} (touching)", "", f"< {centre[1]} (rim)", "", "fell through"))
    assert radius - thickness - cell < farthest[False] <= bound
    assert highest[False] < centre[1] - 0.2 * radius            # all of it down in the bowl
    assert lowest[True] < centre[1] - radius


def test_the_winding_number_keeps_the_inside_of_a_sphere_with_holes(f64):
    """A sphere with a tenth of its triangles removed, taken as solid: points inside have
    negative distances and points outside positive ones, as for the closed sphere, except
    within a hole's width of a hole (there the winding number passes 1/2)."""
    radius, centre = 0.3, np.zeros(3)
    sphere = tc.sphere_mesh(radius, centre, subdivisions=3)
    holed = tc.Mesh(sphere.vertices, sphere.triangles[np.arange(sphere.triangle_count) % 10 != 0])
    collider = tc.MeshCollider(holed, solid=True, resolution=32)
    with pytest.warns(UserWarning, match=r"shell's thickness \(0 m\) is less than its "
                      r"distance grid's cell"):
        assert tc.MeshCollider(holed, thickness=0.0).solid is False    # a shell by default
    sim = tc.Simulation(far_particle(), colliders=[collider])
    points = np.random.default_rng(2).uniform(-0.45, 0.45, (3000, 3))
    exact = np.linalg.norm(points, axis=1) - radius
    edges = sphere.vertices[sphere.edges()]
    hole = np.linalg.norm(edges[:, 0] - edges[:, 1], axis=1).max()
    clear = np.abs(exact) > max(collider.grid().cell, hole)    # near a hole w is near 1/2
    d, _ = sim.collider_distance(points)
    report("points with the wrong sign", int((np.sign(d) != np.sign(exact))[clear].sum()), 0)
    assert np.array_equal(np.sign(d[clear]), np.sign(exact[clear]))


def held_then(times, values):
    """A smooth path holding its first value until times[0] and its last after times[-1]
    (velocity continuous, so friction can carry a body along without slipping at the start)."""
    times = [0.0, *times, times[-1] + 0.5]
    values = [values[0], *values, values[-1]]
    return tc.Keyframes(times, values, interpolation="smooth")


def platform_sim(collider_options, patch_centre):
    """A 0.2 m cloth patch lying on a 1 m square slab (top at y = 0.1) at `patch_centre`."""
    slab = tc.box_mesh((-0.5, 0.0, -0.5), (0.5, 0.1, 0.5))
    collider = tc.MeshCollider(slab, thickness=THICKNESS, static_friction=1.0, resolution=32,
                               **collider_options)
    cloth = sheet(6, 0.2, 0.1 + THICKNESS, patch_centre)
    return tc.Simulation(cloth, integrator="xpbd", dt=1 / 120, colliders=[collider]), cloth


def test_a_moving_mesh_collider_carries_the_cloth_resting_on_it(f64):
    """A slab slides 0.4 m along x and rises 0.1 m (a smooth path); the patch on it, held by
    static friction, moves with it: every particle ends displaced by the path's displacement."""
    path = held_then([0.2, 1.2], [(0.0, 0.0, 0.0), (0.4, 0.1, 0.0)])
    sim, cloth = platform_sim({"path": path}, (0.0, 0.0))
    sim.step(round(1.7 * 120))
    moved = sim.positions() - cloth.particle_position
    report("displacement of the patch (min, max) vs the path's", (moved.min(axis=0).tolist(),
           moved.max(axis=0).tolist()), path(sim.time).tolist())
    assert np.abs(moved - path(sim.time)).max() < 2e-3


def test_a_turning_mesh_collider_carries_the_cloth_round(f64):
    """A turntable (the slab turning a quarter turn about y through its centre, smoothly, in
    2 s) carries a patch lying 0.25 m off its axis round with it: the patch ends where the
    rotation takes its start, every particle within millimetres. Friction measures the slide
    against the turning surface point under each particle: with the table's bare translation
    (zero here) the patch would stay behind."""
    angle = math.pi / 2
    rotation = held_then([0.2, 2.2], [(0.0, 0.0, 0.0), (0.0, angle, 0.0)])
    sim, cloth = platform_sim({"rotation": rotation}, (0.25, 0.0))
    sim.step(round(2.7 * 120))
    turn = np.array([[math.cos(angle), 0, math.sin(angle)], [0, 1, 0],
                     [-math.sin(angle), 0, math.cos(angle)]])
    expected = cloth.particle_position @ turn.T
    off = np.linalg.norm(sim.positions() - expected, axis=1)
    report("farthest from the turned start [m]", off.max(), "< 3e-3")
    assert off.max() < 3e-3
    placed, = sim.collider_shapes()                           # drawn turned as well
    np.testing.assert_allclose(placed.mesh.vertices, tc.box_mesh(
        (-0.5, 0.0, -0.5), (0.5, 0.1, 0.5)).vertices @ turn.T, atol=1e-12)


@pytest.mark.parametrize("make, message", [
    (lambda: tc.MeshCollider(tc.Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [])),
     "MeshCollider.mesh must be a Mesh with at least one triangle"),
    (lambda: tc.MeshCollider(tc.Mesh([[1, 1, 1]] * 3, [[0, 1, 2]])), "not all at one point"),
    (lambda: tc.MeshCollider(tc.box_mesh(), resolution=4), "MeshCollider.resolution"),
    (lambda: tc.MeshCollider(tc.box_mesh(), rotation=lambda t: np.eye(3) * 2),
     r"MeshCollider.rotation\(0.0\) must be a rotation matrix"),
    (lambda: tc.MeshCollider(tc.box_mesh(), rotation=lambda t: (1.0, 2.0)),
     r"MeshCollider.rotation\(0.0\) must be a rotation vector"),
    (lambda: tc.MeshCollider(tc.box_mesh(), solid="yes"), "MeshCollider.solid"),
    (lambda: tc.MeshCollider(tc.box_mesh(), thickness=-1.0), "MeshCollider.thickness"),
])
def test_mesh_colliders_reject_bad_input_by_name(make, message):
    with pytest.raises(ValueError, match=message):
        make()


@pytest.mark.parametrize("content, error", [
    ("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n", "vertices.* must be finite"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no triangle, quad or tetra cells"),
    ("\x00\x01garbage\xff" * 20, "not a mesh meshio can read"),
])
def test_a_bad_mesh_file_is_refused_naming_the_file(tmp_path, content, error):
    path = tmp_path / "broken_table.obj"
    path.write_bytes(content.encode("latin-1"))
    with pytest.raises(ValueError, match=f"broken_table.obj.*{error}"):
        tc.load_mesh(path)
    with pytest.raises(FileNotFoundError, match="missing_table.obj"):
        tc.load_mesh(tmp_path / "missing_table.obj")


SCENE = """
[simulation]
integrator = "xpbd"
substeps = 4
fps = 30
duration = 0.1

[[bodies]]
type = "grid"
rows = 4
cols = 4
plane = "xz"
origin = [-0.2, 0.5, -0.2]
size = [0.4, 0.4]

[[colliders]]
type = "mesh"
path = "{path}"
scale = 2.0
translate = [0.0, 0.1, 0.0]
thickness = 0.02
static_friction = 0.5
resolution = 16
motion = {{ type = "keyframes", times = [0.0, 1.0], values = [[0, 0, 0], [0.5, 0, 0]] }}
rotation = {{ type = "keyframes", times = [0.0, 1.0], values = [[0, 0, 0], [0, 1.0, 0]] }}
"""


def test_a_scene_file_loads_a_moving_turning_mesh_collider_relative_to_itself(f64, tmp_path):
    from ti_cloth.inputs.scene_file import SceneError
    box = tc.box_mesh((-0.1, 0.0, -0.1), (0.1, 0.1, 0.1))
    tc.save_mesh(tmp_path / "assets" / "block.obj", box)
    scene_path = tmp_path / "block.toml"
    scene_path.write_text(SCENE.format(path="assets/block.obj"))
    collider, = tc.load_scene(scene_path).colliders
    assert isinstance(collider, tc.MeshCollider)
    np.testing.assert_allclose(collider.mesh.vertices, box.vertices * 2.0 + [0.0, 0.1, 0.0])
    assert (collider.thickness, collider.static_friction, collider.resolution) == (0.02, 0.5, 16)
    np.testing.assert_allclose(collider.offset(0.5), [0.25, 0.0, 0.0])
    np.testing.assert_allclose(collider.turn(0.5)[0], [math.cos(0.5), 0, math.sin(0.5)])
    scene_path.write_text(SCENE.format(path="assets/no_such_block.obj"))
    with pytest.raises(SceneError, match="no_such_block.obj"):
        tc.load_scene(scene_path)


def test_a_grid_is_built_once_then_read_from_the_disk_cache(tmp_path, monkeypatch):
    """The first request builds and writes sdf-<hash>.npz (atomically: no temporary left);
    a later process (the memory cache emptied) reads it back equal, without building; another
    resolution is another grid."""
    monkeypatch.setenv("TI_CLOTH_CACHE", str(tmp_path))
    sdf.clear_memory_cache()
    mesh = tc.sphere_mesh(0.2, subdivisions=2)
    built = sdf.distance_grid(mesh.vertices, mesh.triangles, 16, 0.05)
    files = sorted(p.name for p in tmp_path.iterdir())
    assert len(files) == 1 and files[0].startswith("sdf-") and files[0].endswith(".npz")
    sdf.clear_memory_cache()

    def no_build(*args):
        raise AssertionError("built again")
    monkeypatch.setattr(sdf, "build", no_build)
    again = sdf.distance_grid(mesh.vertices, mesh.triangles, 16, 0.05)
    np.testing.assert_array_equal(again.distance, built.distance)
    np.testing.assert_array_equal(again.gradient, built.gradient)
    assert again.cell == built.cell and np.array_equal(again.origin, built.origin)
    with pytest.raises(AssertionError, match="built again"):
        sdf.distance_grid(mesh.vertices, mesh.triangles, 17, 0.05)


def test_the_renderer_draws_a_mesh_collider_where_it_has_turned(f32):
    """Seen from straight above, a 0.6 m square slab covers 0.6 m of the image's width; turned
    45 degrees about y it covers its diagonal, 0.6 x sqrt(2)."""
    from ti_cloth.render import Camera, Renderer
    slab = tc.box_mesh((-0.3, 0.0, -0.3), (0.3, 0.05, 0.3))
    camera = Camera(position=(0.0, 3.0, 0.0), target=(0.0, 0.0, 0.0), up=(0.0, 0.0, -1.0),
                    orthographic=True, height=1.2)
    widths = []
    for angle in (0.0, math.pi / 4):
        collider = tc.MeshCollider(slab, rotation=lambda t, a=angle: (0.0, a, 0.0), resolution=8)
        sim = tc.Simulation(far_particle(), colliders=[collider])
        with Renderer(120, 120, camera, supersample=1) as renderer:
            renderer.begin()
            background = renderer.end().astype(int)
            renderer.begin()
            renderer.draw_colliders(sim)
            image = renderer.end().astype(int)
        drawn = np.abs(image - background).sum(axis=2) > 30
        columns = np.flatnonzero(drawn.any(axis=0))
        widths.append((columns[-1] - columns[0] + 1) * 1.2 / 120)
    report("drawn widths [m]", widths, [0.6, 0.6 * math.sqrt(2)])
    assert abs(widths[0] - 0.6) <= 0.02 and abs(widths[1] - 0.6 * math.sqrt(2)) <= 0.02


def test_a_set_without_meshes_holds_and_compiles_no_mesh_code(f64):
    plain = tc.Simulation(far_particle(), colliders=[tc.Plane()])
    assert not plain.colliders.meshes and not hasattr(plain.colliders, "samples")
    still = tc.Simulation(far_particle(), colliders=[tc.MeshCollider(tc.box_mesh(),
                                                                     resolution=8)])
    assert still.colliders.meshes and not still.colliders.turning


def test_without_libigl_the_error_says_how_to_install_it(monkeypatch, tmp_path):
    """libigl is a base dependency; a broken install that lacks it is told what to install."""
    monkeypatch.setitem(sys.modules, "igl", None)             # as if not installed
    monkeypatch.setenv("TI_CLOTH_CACHE", str(tmp_path))
    sdf.clear_memory_cache()
    mesh = tc.sphere_mesh(0.1, subdivisions=1)
    with pytest.raises(ImportError, match=r"pip install libigl scipy"):
        sdf.distance_grid(mesh.vertices, mesh.triangles, 8, 0.01)
