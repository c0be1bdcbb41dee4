"""Scene files: every key checked by name, scenes build the simulation the API would, and only
what a scene lists is compiled."""

import shutil
from pathlib import Path

import numpy as np
import pytest
from helpers import compiled, forget_compiled, report

import ti_cloth as tc
from ti_cloth.app.scene import load_scene
from ti_cloth.contact.colliders.collision import resolve
from ti_cloth.inputs.scene_file import SceneError
from ti_cloth.physics import wind as wind_module
from ti_cloth.physics.strain_limit import relax_stretched
from ti_cloth.render import Camera

DEMOS = Path(__file__).parents[1] / "demos"

GRID = """
[simulation]
fps = 50
substeps = 40
duration = 0.1

[forces]
drag = 0.3

[[bodies]]
type = "grid"
rows = 6
cols = 5
size = [0.5, 0.4]
plane = "xy"
pinned = ["top_left", "top_right", 3]
material = { preset = "cotton_springs", hem_mass = 0.001, stretch = { k = 900.0, kd = 0.2 } }
"""


def write(tmp_path, text, name="scene.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_a_grid_scene_builds_the_same_simulation_as_the_api(tmp_path, f64):
    scene = load_scene(write(tmp_path, GRID))
    sim = scene.build()
    material = tc.Material.preset("cotton_springs", hem_mass=0.001, stretch=tc.SpringParams(900.0, 0.2))
    cloth = tc.Cloth(tc.grid_mesh(6, 5, size=(0.5, 0.4)), material, pinned=[25, 29, 3])
    api = tc.Simulation(cloth, dt=1 / 50 / 40, drag=0.3)
    sim.step(40)
    api.step(40)
    report("max position difference scene vs API [m]", np.abs(sim.positions() - api.positions()).max(), 0.0)
    np.testing.assert_array_equal(sim.positions(), api.positions())
    assert scene.frames == 5 and scene.resolved_substeps() == 40


def test_a_scene_hem_takes_grid_names_and_indices(tmp_path):
    """hem = ["left", 4] is the API's hem of the same particles (less 25, pinned); without the
    key, the bottom row."""
    hemmed = load_scene(write(tmp_path, GRID.replace("pinned =", 'hem = ["left", 4]\npinned ='))).cloth
    left = np.arange(0, 30, 5)
    np.testing.assert_array_equal(np.flatnonzero(hemmed.hem), sorted(set(left) - {25} | {4}))
    material = tc.Material.preset("cotton_springs", hem_mass=0.001, stretch=tc.SpringParams(900.0, 0.2))
    api = tc.Cloth(tc.grid_mesh(6, 5, size=(0.5, 0.4)), material, pinned=[25, 29, 3],
                   hem=[*left, 4])
    np.testing.assert_array_equal(hemmed.particle_mass, api.particle_mass)
    default = load_scene(write(tmp_path, GRID)).cloth
    np.testing.assert_array_equal(np.flatnonzero(default.hem), [0, 1, 2, 4])    # 3 is pinned


def test_pins_as_a_ball_are_the_particles_within_it(tmp_path):
    """pinned = { centre, radius } pins exactly the particles within the ball at rest (an
    independent distance test); a ball holding none, or a bad radius, names the key."""
    ball = 'pinned = { centre = [0.25, 0.2, 0.0], radius = 0.15 }\n#'
    cloth = load_scene(write(tmp_path, GRID.replace("pinned =", ball))).cloth
    x = tc.grid_mesh(6, 5, size=(0.5, 0.4)).vertices
    inside = np.flatnonzero(np.linalg.norm(x - [0.25, 0.2, 0.0], axis=1) <= 0.15)
    assert 0 < len(inside) < 30
    np.testing.assert_array_equal(np.flatnonzero(cloth.pinned), inside)
    empty = GRID.replace("pinned =", 'pinned = { centre = [5, 5, 5], radius = 0.1 }\n#')
    with pytest.raises(SceneError, match=r"bodies\[0\]\.pinned must be a ball holding at least one"):
        load_scene(write(tmp_path, empty))
    negative = GRID.replace("pinned =", 'pinned = { centre = [0, 0, 0], radius = -1 }\n#')
    with pytest.raises(SceneError, match=r"bodies\[0\]\.pinned\.radius must be a number >= 0"):
        load_scene(write(tmp_path, negative))


def test_every_demo_scene_loads(tmp_path):
    scenes = sorted(DEMOS.glob("*.toml"))
    assert len(scenes) == 18   # the sixteen demos and the study's two scenes (springs, fabric)
    for path in scenes:
        scene = load_scene(path)
        assert scene.cloth.particle_count > 1 and scene.frames >= 15, path.name


def test_the_demos_of_the_source_texts_run_their_schemes_as_written():
    """stuyck_explicit: Stuyck's explicit Euler (eq. 4.8-4.9) with relative damping (eq. 4.7)
    at a stable step; verlet_pbd_cloth: the lecture's loop (numIter = 2 substeps of a Verlet
    update and one relaxation pass, 1.99 / 0.99) with a particle pulled and let go."""
    stuyck = load_scene(DEMOS / "stuyck_explicit.toml")
    assert stuyck.integrator.name == "explicit_euler" and stuyck.cloth.damping == "relative"
    dt = stuyck.frame_dt / stuyck.resolved_substeps()
    assert dt <= 0.5 * tc.stable_dt(stuyck.cloth, "explicit_euler", stuyck.drag)
    lecture = load_scene(DEMOS / "verlet_pbd_cloth.toml")
    assert lecture.integrator == tc.PBD(iterations=1, damping=0.01) and lecture.substeps == 2
    assert [h.release for h in lecture.handles] == [2.5]


def test_auto_substeps_keep_dt_under_half_the_stable_step(tmp_path):
    scene = load_scene(write(tmp_path, GRID.replace("substeps = 40", 'substeps = "auto"')))
    n = scene.resolved_substeps()
    dt = scene.frame_dt / n
    stable = tc.stable_dt(scene.cloth, "symplectic_euler", 0.3)
    report("auto dt, stable dt [s]", (dt, stable), "dt <= stable / 2, and one fewer substep is not")
    assert dt <= 0.5 * stable and scene.frame_dt / (n - 1) > min(0.5 * stable, 1 / 240)


def test_a_fabric_scene_builds_the_api_fabric(tmp_path, f64):
    """fabric = "denim", and a [bodies.fabric] table of a preset and fields (pairs for warp and
    weft), give the API's Fabric bodies; a scene may not give both material and fabric."""
    named = GRID.replace('material = { preset = "cotton_springs", hem_mass = 0.001, stretch = { k = 900.0, kd = 0.2 } }',
                         'fabric = "denim"')
    assert load_scene(write(tmp_path, named)).cloth.material == tc.Fabric.preset("denim")
    table = named.replace('fabric = "denim"', '[bodies.fabric]\npreset = "interlock"\n'
                          'stretch = [300.0, 100.0]\nbending = 2e-5\nwarp = [0, 1, 0]')
    with pytest.raises(SceneError, match=r"bodies\[0\]\.fabric\.warp is not a known key"):
        load_scene(write(tmp_path, table))
    table = table.replace("\nwarp = [0, 1, 0]", "").replace('fabric = "denim"', "")
    table = table.replace('plane = "xy"', 'plane = "xy"\nwarp = [0, 1, 0]')
    scene = load_scene(write(tmp_path, table))
    expected = tc.Fabric.preset("interlock", stretch=(300.0, 100.0), bending=2e-5)
    assert scene.cloth.material == expected
    api = tc.Cloth(tc.grid_mesh(6, 5, size=(0.5, 0.4)), expected, pinned=[25, 29, 3],
                   warp=(0, 1, 0))
    np.testing.assert_array_equal(scene.cloth.face_gradient, api.face_gradient)
    both = named.replace('fabric = "denim"', 'fabric = "denim"\nmaterial = "cotton"')
    with pytest.raises(SceneError, match=r"bodies\[0\]\.fabric must be absent when `material`"):
        load_scene(write(tmp_path, both))
    bad = named.replace('fabric = "denim"', 'fabric = { preset = "denim", poisson = 40.0 }')
    with pytest.raises(SceneError, match=r"Fabric\.poisson must be below"):
        load_scene(write(tmp_path, bad))


@pytest.mark.parametrize("change, message", [
    (("[forces]", "[forces]\ngravty = [0, -9.81, 0]"), r"forces\.gravty is not a known key .*allowed here: .*gravity"),
    (("rows = 6", "rows = 6\nrowz = 4"), r"bodies\[0\]\.rowz is not a known key"),
    (("stretch = { k = 900.0, kd = 0.2 }", "stretch = { k = 900.0, kdd = 0.2 }"),
     r"bodies\[0\]\.material\.stretch\.kdd is not a known key"),
    (("rows = 6", 'rows = "6"'), r"bodies\[0\]\.rows must be an integer in \[2, 10_000\], got '6'"),
    (("rows = 6", "rows = 1"), r"bodies\[0\]\.rows must be an integer in \[2, 10_000\], got 1"),
    (("fps = 50", "fps = 0"), r"simulation\.fps must be a number in \[1, 1000\] frames/s, got 0"),
    (("substeps = 40", "substeps = 0"), r"simulation\.substeps must be an integer in \[1, 100_000\], got 0"),
    (('type = "grid"', 'type = "blanket"'), r"bodies\[0\]\.type must be one of \['grid'"),
    (('"top_left"', '"top_middle"'), r"bodies\[0\]\.pinned must be particle indices in \[0, 29\] or one of"),
    (("pinned = [", "pinned = [30, "), r"bodies\[0\]\.pinned must be particle indices in \[0, 29\]"),
    (("pinned = [", 'hem = "hemline"\npinned = ['),
     r"bodies\[0\]\.hem must be particle indices in \[0, 29\] or one of \['boundary'"),
    (("size = [0.5, 0.4]", "size = [0.5, -0.4]"), r"bodies\[0\]: size\[1\] must be a finite number in \[1e-06, 10000\] m, got -0.4"),
    (('preset = "cotton_springs"', 'preset = "tweed"'), r"bodies\[0\]\.material\.preset must be one of"),
    (("drag = 0.3", "drag = -1"), r"forces\.drag must be a number in \[0, 10000\] 1/s, got -1"),
    (("[forces]", '[forces]\nwind = { velocity = [1, 0] }'), r"forces\.wind\.velocity must be a list of 3 numbers"),
    (("fps = 50", 'fps = 50\nintegrator = "rk5"'), r"simulation\.integrator\.name must be one of"),
    (("fps = 50", 'fps = 50\nintegrator = { name = "pbd", iterations = 0 }'),
     r"simulation\.integrator: PBD\.iterations must be an int in \[1, 10_000\], got 0"),
    (("fps = 50", 'fps = 50\nintegrator = { name = "pbd", iteration = 3 }'),
     r"simulation\.integrator\.iteration is not a known key .*allowed here: damping, iterations, name"),
])
def test_scene_errors_name_the_key_the_value_and_what_is_allowed(tmp_path, change, message):
    old, new = change
    assert old in GRID
    path = write(tmp_path, GRID.replace(old, new, 1))
    with pytest.raises(SceneError, match=message) as err:
        load_scene(path)
    assert str(path) in str(err.value)
    print(err.value)


def test_scene_file_problems_outside_the_keys(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.toml"):
        load_scene(tmp_path / "missing.toml")
    with pytest.raises(SceneError, match="not valid TOML"):
        load_scene(write(tmp_path, "[simulation\nfps = 3"))
    with pytest.raises(SceneError, match=r"at least one \[\[bodies\]\]"):
        load_scene(write(tmp_path, "[simulation]\nfps = 30\n"))
    with pytest.raises(SceneError, match=r"bodies\[0\]\.handles\[0\]\.path is required"):
        load_scene(write(tmp_path, GRID + '[[bodies.handles]]\nparticles = ["top_left"]\n'))


def test_a_scene_compiles_only_what_it_lists(tmp_path, f64):
    kernels = (wind_module.wind_on_triangle, resolve, relax_stretched)
    forget_compiled(*kernels)
    scene = load_scene(write(tmp_path, GRID))
    sim = scene.build()
    for _ in range(5):        # a launch per stage (many-steps launches: the stages' flags)
        sim.step(1)
    assert sim.wind is None and sim.colliders is None and sim.strain_limiter is None
    assert not any(compiled(k) for k in kernels)
    stages = sim.many_steps.stages
    assert not (stages.collides or stages.limits_strain or stages.holds or sim.forces.has_wind)
    full = GRID.replace("[forces]", '[forces]\nwind = { velocity = [2.0, 0.0, 1.0] }').replace(
        "duration = 0.1", "duration = 0.1\nstrain_limit = { max_strain = 0.1 }")
    full += '[[colliders]]\ntype = "sphere"\ncentre = [0.25, -0.5, 0.0]\nradius = 0.2\n'
    sim = load_scene(write(tmp_path, full)).build()
    for _ in range(5):
        sim.step(1)
    assert all(compiled(k) for k in kernels)
    stages = sim.many_steps.stages
    assert stages.collides and stages.limits_strain and sim.forces.has_wind


def test_bodies_of_a_scene_move_as_they_would_alone(tmp_path, f64):
    """Two bodies in one scene are joined into one Cloth; each moves exactly as it does alone
    (forces are gathered per particle, in the same order)."""
    text = GRID + """
[[bodies]]
type = "string"
n = 7
length = 0.6
start = [1.0, 0.0, 0.0]
mass = 0.02
"""
    both = load_scene(write(tmp_path, text)).build()
    alone = load_scene(write(tmp_path, GRID, "alone.toml")).build()
    both.step(50)
    alone.step(50)
    assert both.cloth.particle_body.tolist() == [0] * 30 + [1] * 7
    np.testing.assert_array_equal(both.positions()[:30], alone.positions())
    string = tc.Simulation(tc.string(7, 0.6, mass=0.02, start=(1, 0, 0)), dt=both.dt, drag=0.3)
    string.step(50)
    np.testing.assert_array_equal(both.positions()[30:], string.positions())


def test_handles_and_colliders_with_paths_from_a_scene(tmp_path, f64):
    text = GRID + """
[[bodies.handles]]
particles = ["bottom_left"]
path = { type = "keyframes", times = [0.0, 0.1], values = [[0, 0, 0], [0.0, -0.1, 0.05]] }

[[colliders]]
type = "box"
lo = [-1.0, -3.0, -1.0]
hi = [1.0, -2.0, 1.0]
path = { type = "oscillation", amplitude = [0, 0.5, 0], frequency = 2.0 }
"""
    scene = load_scene(write(tmp_path, text))
    sim = scene.build()
    sim.step(200)                                  # 0.1 s
    np.testing.assert_allclose(sim.positions()[0], scene.cloth.particle_position[0] + [0, -0.1, 0.05],
                               atol=1e-12)
    assert isinstance(scene.colliders[0], tc.Box) and scene.colliders[0].path is not None


def test_a_handle_release_time_from_a_scene(tmp_path):
    text = GRID + '[[bodies.handles]]\nparticles = [0]\nrelease = 0.05\n' \
                  'path = { type = "oscillation", amplitude = [0, 0.1, 0], frequency = 1.0 }\n'
    assert load_scene(write(tmp_path, text)).handles[0].release == 0.05
    with pytest.raises(SceneError, match=r"bodies\[0\]\.handles\[0\]: Handle\.release must be a "
                                         r"finite number in \[0, 1e\+06\] s, got -1"):
        load_scene(write(tmp_path, text.replace("release = 0.05", "release = -1")))


def test_the_scene_reference_is_a_valid_scene(tmp_path, f64):
    """docs/scenes.md's scene-file reference lists the keys as a real scene: it must load,
    build and step, so the documentation cannot drift from the reader."""
    reference = (Path(__file__).parents[1] / "docs" / "scenes.md").read_text()
    block = reference.split("```toml\n", 1)[1].split("```", 1)[0]
    (tmp_path / "assets").mkdir()
    for asset in ("table.obj", "figure_turn.npz"):
        shutil.copy(Path(__file__).parents[1] / "demos" / "assets" / asset, tmp_path / "assets")
    scene = load_scene(write(tmp_path, block))
    assert scene.name == "flag" and scene.wind is not None and len(scene.handles) == 2
    assert isinstance(scene.handles[1], tc.Attachment)
    assert scene.handles[1].collider is scene.colliders[2]
    assert isinstance(scene.colliders[1], tc.MeshCollider) and scene.colliders[1].solid
    assert isinstance(scene.colliders[2], tc.AnimatedMeshCollider)
    assert scene.strain_limit is not None and scene.tearing == 0.3
    scene.build().step(2)


def test_a_mesh_body_from_a_file_next_to_the_scene(tmp_path, f64):
    tc.save_mesh(tmp_path / "sheet.obj", tc.grid_mesh(4, 3, size=(0.3, 0.2)))
    text = """
[simulation]
dt = 7e-4
fps = 25
[[bodies]]
type = "mesh"
path = "sheet.obj"
scale = 2.0
translate = [0.0, 1.0, 0.0]
pinned = [0, 2]
material = "denim_springs"
"""
    scene = load_scene(write(tmp_path, text))
    x = scene.cloth.particle_position
    np.testing.assert_allclose(x.max(axis=0) - x.min(axis=0), [0.6, 0.4, 0.0], atol=1e-12)
    assert x[:, 1].min() == pytest.approx(1.0)
    assert scene.cloth.pinned.sum() == 2 and scene.cloth.material == tc.Material.preset("denim_springs")
    n = scene.resolved_substeps()
    assert n == 58 and scene.frame_dt / n <= 7e-4 < scene.frame_dt / (n - 1)
    with pytest.raises(SceneError, match="either dt or substeps"):
        load_scene(write(tmp_path, text.replace("dt = 7e-4", "dt = 7e-4\nsubsteps = 3")))


def test_errors_list_every_allowed_key_suggest_the_nearest_and_quote_values_whole(tmp_path):
    """A misspelt key lists every key the table allows (also those read only in some cases:
    fabric, hem) with the nearest; a misspelt preset gets the nearest preset; a long value is
    summarised, never cut in the middle of its structure; presets take any letter case."""
    named = GRID.replace('material = { preset = "cotton_springs", hem_mass = 0.001, stretch = { k = 900.0, kd = 0.2 } }',
                         'fabirc = "denim"')
    with pytest.raises(SceneError) as err:
        load_scene(write(tmp_path, named))
    message = str(err.value)
    assert "bodies[0].fabirc is not a known key (value 'denim') (did you mean 'fabric'?)" in message
    allowed = message.split("allowed here: ")[1].split(", ")
    assert {"fabric", "material", "hem", "warp", "pinned"} <= set(allowed)
    with pytest.raises(SceneError, match=r"got 'demin' \(did you mean 'denim'\?\)"):
        load_scene(write(tmp_path, named.replace('fabirc = "denim"', 'fabric = "demin"')))
    assert load_scene(write(tmp_path, named.replace('fabirc = "denim"', 'fabric = "DeNiM"'))
                      ).cloth.material == tc.Fabric.preset("denim")
    assert load_scene(write(tmp_path, named.replace('fabirc = "denim"', 'material = "Cotton_Springs"'))
                      ).cloth.material == tc.Material.preset("cotton_springs")
    long = named.replace('fabirc = "denim"', "fabirc = [" + ", ".join(["1.5"] * 60) + "]")
    with pytest.raises(SceneError, match=r"\(value a list of 60 items, starting 1\.5\)"):
        load_scene(write(tmp_path, long))


def test_a_scene_in_centimetres_is_warned_about(tmp_path):
    big = GRID.replace("size = [0.5, 0.4]", "size = [120.0, 90.0]")
    assert big != GRID
    with pytest.warns(UserWarning, match=r"150 m across; scene files are in metres"):
        load_scene(write(tmp_path, big))
    heard = []
    load_scene(write(tmp_path, big), note=heard.append)
    assert len(heard) == 1 and "centimetres" in heard[0]


def test_the_api_takes_the_particle_names_scene_files_take():
    mesh = tc.grid_mesh(4, 5)
    by_name = tc.Cloth(mesh, tc.Material(), pinned=["top_left", "top_right", 7])
    assert np.flatnonzero(by_name.pinned).tolist() == [7, 15, 19]
    assert np.flatnonzero(tc.Cloth(mesh, tc.Material(), pinned="top").pinned).tolist() == [
        15, 16, 17, 18, 19]
    with pytest.raises(ValueError, match="pinned must be particle indices or names of"):
        tc.Cloth(mesh, tc.Material(), pinned=["tpo"])


def test_combinations_the_api_refuses_are_refused_by_the_scene_reader(tmp_path):
    """A Fabric stepped by pbd, a warp on a body of springs, a warp of no finite length: each
    a SceneError naming the key, from the reader (before a Simulation is built); a warp along
    a flat sheet's normal is warned about."""
    fabric = GRID.replace('material = { preset = "cotton_springs", hem_mass = 0.001, stretch = { k = 900.0, kd = 0.2 } }',
                          'fabric = "denim"')
    assert fabric != GRID
    pbd = fabric.replace("[simulation]", '[simulation]\nintegrator = "pbd"')
    with pytest.raises(SceneError, match=r"simulation\.integrator = 'pbd' cannot step a body "
                                         r"made of a fabric"):
        load_scene(write(tmp_path, pbd))
    springs = GRID.replace('plane = "xy"', 'plane = "xy"\nwarp = [1, 0, 0]')
    with pytest.raises(SceneError, match=r"bodies\[0\]: warp must be None for a body of springs"):
        load_scene(write(tmp_path, springs))
    huge = fabric.replace('plane = "xy"', 'plane = "xy"\nwarp = [1e300, 1e300, 0]')
    with pytest.raises(SceneError, match=r"warp must be a non-zero direction of finite length"):
        load_scene(write(tmp_path, huge))
    normal = fabric.replace('plane = "xy"', 'plane = "xy"\nwarp = [0, 0, 1]')
    with pytest.warns(UserWarning, match=r"warp \[0\.0, 0\.0, 1\.0\] is along the normal of"):
        load_scene(write(tmp_path, normal))


def test_frames_beyond_the_step_count_are_refused_before_taichi(tmp_path, capsys):
    from ti_cloth.app import cli

    path = write(tmp_path, GRID)
    assert cli.main(["run", str(path), "--frames", str(10 ** 12), "--no-progress",
                     "--out", str(tmp_path / "o")]) == 2
    assert "more than the 2_147_483_646 a simulation can count" in capsys.readouterr().err


HANGING = """
[simulation]
integrator = "xpbd"
duration = 1.2
[[bodies]]
type = "grid"
rows = 12
cols = 12
size = [1.0, 1.0]
plane = "xz"
origin = [0.0, 1.5, 0.0]
pinned = [0, 11]
"""
DROPPED = """
[simulation]
integrator = "xpbd"
duration = 1.2
[[bodies]]
type = "grid"
rows = 12
cols = 12
size = [1.0, 1.0]
plane = "xz"
origin = [-0.5, 1.0, -0.5]
[[colliders]]
type = "sphere"
centre = [0.0, 0.35, 0.0]
radius = 0.35
[[colliders]]
type = "plane"
"""


@pytest.mark.parametrize("text", [HANGING, DROPPED], ids=["pinned at two corners", "dropped"])
def test_the_automatic_camera_frames_the_whole_motion(tmp_path, f32, text):
    """Without [camera], the camera is fitted to where the motion happens (Scene.motion_bounds):
    every particle of every frame projects inside the image, and the cloth at the end still
    spans a fair part of it; fitted to the cloth at rest (before), the sheet swinging from
    its corners leaves the frame."""
    scene = load_scene(write(tmp_path, text))
    width, height = scene.output.width, scene.output.height
    cameras = {"motion": Camera.fit(scene.motion_bounds(), aspect=width / height),
               "rest": Camera.fit(scene.cloth, aspect=width / height)}
    sim = scene.build(dt=1 / 240)
    outside = {name: 0 for name in cameras}
    for _ in range(36):
        sim.step(8)
        x = sim.positions()
        for name, camera in cameras.items():
            screen, depth = camera.project(x, width, height)
            outside[name] += int((~((screen >= 0).all(axis=1) & (screen[:, 0] <= width)
                                    & (screen[:, 1] <= height) & (depth > camera.near))).sum())
    span = np.ptp(cameras["motion"].project(x, width, height)[0], axis=0)
    report("particles outside the image over the run; the last frame's span (px)",
           (outside, span.tolist()), "motion: 0")
    assert outside["motion"] == 0 and max(span[0] / width, span[1] / height) > 0.15
    if "pinned" in text:
        assert outside["rest"] > 0


def test_self_collision_takes_its_fail_safe_switches_by_name(tmp_path, f64):
    """[simulation] self_collision's never_through, keep_thickness and in_solve reach
    SelfCollision (on, off and off unless given), and anything but a boolean is refused naming
    the key. A scene in xpbd's solve built with another integrator (the study's rk4
    reference) takes the contacts after its step."""
    given = GRID.replace("fps = 50", "fps = 50\nself_collision = { thickness = 0.004, "
                         "keep_thickness = true, never_through = false, in_solve = true }", 1)
    scene = load_scene(write(tmp_path, given))
    settings = scene.self_collision
    assert settings == tc.SelfCollision(thickness=0.004, keep_thickness=True,
                                        never_through=False, in_solve=True)
    assert scene.build(integrator="xpbd").self_collision.settings.in_solve
    assert not scene.build(integrator="rk4").self_collision.settings.in_solve
    assert not tc.SelfCollision().keep_thickness and tc.SelfCollision().never_through
    assert not tc.SelfCollision().in_solve
    with pytest.raises(SceneError, match=r"self_collision\.in_solve must be .*got 1"):
        load_scene(write(tmp_path, given.replace("in_solve = true", "in_solve = 1")))
    with pytest.raises(SceneError, match=r"self_collision\.keep_thickness must be .*got 1"):
        load_scene(write(tmp_path, given.replace("keep_thickness = true",
                                                 "keep_thickness = 1")))
