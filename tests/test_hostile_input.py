"""Hostile input: every mistake in a scene file or an API call stops with a message naming the
key or argument, before anything is allocated or run (limits.py holds the ranges), and runs
that would hide a blow-up or outlive their process say so. The property-based version of
these cases is test_fuzz.py."""

import gc
import re
import signal
import warnings
from pathlib import Path

import numpy as np
import pytest
from helpers import report, use

import ti_cloth as tc
from ti_cloth.app import signals
from ti_cloth.app.runner import Pace
from ti_cloth.app.scene import load_scene
from ti_cloth.app.study import run_study
from ti_cloth.errors import StaleSimulation
from ti_cloth.inputs import limits
from ti_cloth.inputs.scene_file import SceneError
from ti_cloth.render import Camera, Renderer
from ti_cloth.render.image import FrameSequence
from ti_cloth.runtime import backend

BASE = """
[scene]
name = "base"
[simulation]
{simulation}
[forces]
{forces}
[[bodies]]
type = "{body}"
{body_keys}
[camera]
{camera}
[output]
{output}
"""


def scene_text(simulation="", forces="", body="grid", body_keys="", camera="", output=""):
    return BASE.format(simulation=simulation, forces=forces, body=body, body_keys=body_keys,
                       camera=camera, output=output)


# (what the user wrote, the key the message must name); each one printed a traceback, hung,
# allocated without bound or ran to silent nonsense before (issue 16)
SCENE_MISTAKES = [
    (dict(camera="direction = [0, 1, 0]"), "Camera.up"),
    (dict(camera="direction = [0, 0, 0]"), "direction"),
    (dict(camera="fov = 1e-300"), "camera.fov"),
    (dict(output="width = 100000\nheight = 100000"), "output.width"),
    (dict(output="width = 8192\nheight = 8192\nsupersample = 2"), "output.width"),
    (dict(output="supersample = 1000"), "output.supersample"),
    (dict(output="ground = nan"), "output.ground"),
    (dict(output='folder = ""'), "output.folder"),
    (dict(output="checkpoint_every = 0"), "output.checkpoint_every"),
    (dict(simulation='integrator = "auto"'), "tolerance"),
    (dict(simulation='integrator = "auto"\ntolerance = 1e-3\nsubsteps = 4'), "substeps"),
    (dict(simulation='integrator = "auto"\ntolerance = 1e-3\nintegrators = ["rk5"]'),
     "simulation.integrators"),
    (dict(simulation="tolerance = 1e-3"), "tolerance"),
    (dict(output="style = { wireframe = 1e300 }"), "SurfaceStyle.wireframe"),
    (dict(forces="wind = { velocity = [1, 0, 0], seed = -1 }"), "forces.wind.seed"),
    (dict(forces="wind = { velocity = [1, 0, 0] }", body="string"), "forces.wind"),
    (dict(forces="gravity = [1e300, 0, 0]"), "forces.gravity"),
    (dict(forces="drag = 1e300"), "forces.drag"),
    (dict(body_keys="material = { density = 1e300 }"), "Material.density"),
    (dict(body_keys="material = { density = 1e39 }"), "Material.density"),
    (dict(body_keys="material = { density = 1e-45 }"), "Material.density"),
    (dict(body_keys="material = { stretch = { k = 1e20 } }"), "SpringParams.k"),
    (dict(body_keys="material = { stretch = { k = 100, kd = 1e300 } }"), "SpringParams.kd"),
    (dict(simulation="strain_limit = { kinds = 5 }"), "StrainLimit.kinds"),
    (dict(simulation="strain_limit = { kinds = [[1]] }"), "StrainLimit.kinds"),
    (dict(simulation="self_collision = { thickness = -0.01 }"), "SelfCollision.thickness"),
    (dict(simulation="self_collision = { thickness = 0.0 }"), "SelfCollision.thickness"),
    (dict(simulation="self_collision = { friction = -0.1 }"), "SelfCollision.friction"),
    (dict(simulation="self_collision = { thikness = 0.01 }"), "self_collision.thikness"),
    (dict(simulation="self_collision = 0.01"), "simulation.self_collision"),
    (dict(simulation='integrator = { name = "pbd", stiffness = [1, 2] }'), "PBD.stiffness"),
    (dict(simulation='integrator = { name = "pbd", stiffness = "high" }'), "PBD.stiffness"),
    (dict(simulation='integrator = { name = "xpbd", iterations = 1000000000 }'), "XPBD.iterations"),
    (dict(simulation="fps = 1e308\nduration = 1e308"), "simulation.fps"),
    (dict(simulation="fps = 1e-300"), "simulation.fps"),
    (dict(simulation="duration = 1e308"), "simulation.duration"),
    (dict(simulation="dt = 1e-320"), "simulation.dt"),
    (dict(simulation="dt = 1e-9"), "simulation.dt"),
    (dict(simulation="fps = 1\ndt = 2e-7"), "simulation.dt"),
    (dict(simulation="substeps = 1000000000000"), "simulation.substeps"),
    (dict(simulation="substeps = 1180591620717411303424"), "simulation.substeps"),
    (dict(body_keys="material = { density = 1e-6, stretch = { k = 1e9 } }"),
     "simulation.substeps"),                 # auto: a stable step of ~1e-9 s, 3e7 steps per frame
    (dict(body_keys="rows = 1000000000"), "bodies[0].rows"),
    (dict(body_keys="rows = 100000\ncols = 100000"), "bodies[0].rows"),
    (dict(body_keys="rows = 100000000000000000000"), "bodies[0].rows"),
    (dict(body_keys="size = [1e300, 1e300]"), "size[0]"),
    (dict(body_keys="origin = [1e300, 0, 0]"), "bodies[0].origin"),     # issue 40: the key
    (dict(camera="position = [1e300, 0.5, 2]"), "camera.position"),     # written, not a
    (dict(camera="position = [0, 0.5, 2]\ntarget = [0, -1e300, 0]"), "camera.target"),  # later one
    (dict(body="string", body_keys="n = 1000000000"), "bodies[0].n"),
    (dict(body="tet_block", body_keys="cells = [1000, 1000, 1000]"), "cells"),
    (dict(body="hair", body_keys="strands = 100000000"), "bodies[0].strands"),
    (dict(body="hair", body_keys="ghosts = 1"), "bodies[0].ghosts"),
    (dict(body="hair", body_keys="curl = [0.01]"), "bodies[0].curl"),
    (dict(body="hair", body_keys="altitude = 1"), "bodies[0].altitude"),
    (dict(body="hair", body_keys="altitude = { k = -1.0 }"), "k"),
    (dict(body="hair", body_keys="curl = [0.01, -0.01]"), "curl[1] (pitch)"),
    (dict(body="string", body_keys='end_mass = "heavy"'), "bodies[0].end_mass"),
    (dict(body="string", body_keys='hem = "bottom"'), "bodies[0].hem"),
    (dict(body="mesh", body_keys='path = "."'), "bodies[0].path"),
    (dict(body="mesh", body_keys='path = "../../../../../../etc/passwd"'), "bodies[0].path"),
    (dict(body="mesh", body_keys='path = "scene.toml"'), "bodies[0].path"),
    (dict(body="mesh", body_keys='path = "garbage.obj"'), "bodies[0].path"),
    (dict(body="mesh", body_keys='path = "garbage.stl"'), "bodies[0].path"),
]


def write_scene(folder: Path, text: str) -> Path:
    rng = np.random.default_rng(16)
    (folder / "garbage.obj").write_bytes(rng.bytes(500))
    (folder / "garbage.stl").write_bytes(b"solid x\n" + rng.bytes(300))
    path = folder / "scene.toml"
    path.write_text(text)
    return path


@pytest.mark.filterwarnings("ignore::RuntimeWarning")     # meshio's STL reader on garbage
@pytest.mark.parametrize("keys, named", SCENE_MISTAKES, ids=[m[1] + ":" + next(iter(m[0].values()))[:24]
                                                            for m in SCENE_MISTAKES])
def test_a_scene_mistake_is_refused_at_load_naming_the_key(tmp_path, keys, named):
    load_scene(write_scene(tmp_path, scene_text()))           # the base scene itself loads
    path = write_scene(tmp_path, scene_text(**keys))
    with pytest.raises(SceneError, match=re.escape(named)):
        load_scene(path)


@pytest.mark.parametrize("name", ['"a\\u0000b"', '"' + "a" * 300 + '"', '"../../escape"', '".hidden"',
                                  '"a/b"', '""'])
def test_scene_names_that_are_not_file_names_are_refused(tmp_path, name):
    path = write_scene(tmp_path, scene_text().replace('name = "base"', f"name = {name}"))
    with pytest.raises(SceneError, match=r"scene\.name"):
        load_scene(path)


def test_a_file_name_that_is_not_a_scene_name_gives_a_safe_default(tmp_path):
    path = tmp_path / "my scene (v2)!.toml"
    path.write_text(scene_text().replace('name = "base"', ""))
    assert load_scene(path).name == "my scene _v2__"


@pytest.mark.parametrize("data, says", [
    (b"# caf\xe9\n[[bodies]]\ntype = \"grid\"\n", "not UTF-8 text (byte 0xe9 at offset 5)"),
    ("[[bodies]]\ntype = \"grid\"\n".encode("utf-16"), "not UTF-8 text (byte 0xff at offset 0)"),
    (bytes(range(256)) * 4, "not UTF-8"),
    (b"a = " + b"[" * 10_000 + b"]" * 10_000 + b"\n", "nested too deeply"),
])
def test_files_that_are_not_utf8_toml_are_refused_with_a_reason(tmp_path, data, says):
    path = tmp_path / "scene.toml"
    path.write_bytes(data)
    with pytest.raises(SceneError, match=re.escape(says)):
        load_scene(path)


def test_a_long_legal_run_says_so_up_front(tmp_path):
    """Work is estimated from the counts: 400 x 400 particles at 2,000 steps per frame for a
    minute of frames is far beyond LONG_RUN_SECONDS; the default tiny scene is not."""
    long = load_scene(write_scene(tmp_path, scene_text(
        simulation="substeps = 2000\nduration = 60", body_keys="rows = 400\ncols = 400")))
    work = long.work()
    springs = long.cloth.spring_count
    assert work.steps == 30 * 60 * 2000 and work.spring_steps == springs * work.steps
    assert work.seconds > limits.LONG_RUN_SECONDS and "days" in work.describe()
    assert load_scene(write_scene(tmp_path, scene_text())).work().seconds < limits.LONG_RUN_SECONDS


def test_the_pace_of_a_run_is_measured_on_its_own_frames_and_said_once():
    """The first stepped frame holds the compile and is not counted; the median of the
    next three sets the pace; a short remainder says nothing."""
    pace = Pace("walk", frames=101)
    said = [pace.frame(index, seconds) for index, seconds in
            enumerate([9.0, 1.0, 0.9, 1.2, 5.0, 5.0])]
    assert said[:3] == [None] * 3 and said[4:] == [None, None]
    assert "97 frames to go at 1 s a frame" in said[3] and "1.62 min" in said[3]
    quick = Pace("walk", frames=101)
    assert [quick.frame(i, 0.5) for i in range(6)] == [None] * 6     # 48 s to go


def test_a_refinement_too_big_for_memory_is_refused_before_it_is_computed(tmp_path):
    """A 5 x 5 x 5 tet block at resolution 64 would be 5.7e7 particles (grows as the cube):
    refused at once, naming the resolution; a study whose reference would be refined past
    the limit (twice the finest swept) says so."""
    block = load_scene(write_scene(tmp_path, scene_text(
        body="tet_block", body_keys="cells = [5, 5, 5]\nsize = [0.4, 0.4, 0.4]")))
    with pytest.raises(SceneError, match=r"resolution = 64 makes 56,623,104 particles"):
        block.refined(64)
    assert block.refined(2).cloth.particle_count == 11 ** 3
    with pytest.raises(ValueError, match=r"the reference is refined 128 times .* up to 32"):
        run_study(block, resolutions=(64,), duration=0.1)


# ---------------------------------------------------------------- the Python API

def sheet(rows=4):
    return tc.Cloth(tc.grid_mesh(rows, rows), tc.Material(), pinned=[0])


API_MISTAKES = [
    (lambda: tc.stable_dt(sheet(), drag=-1e6), "drag"),
    (lambda: tc.auto_substeps(sheet(), "symplectic_euler", frame_dt=0), "frame_dt"),
    (lambda: tc.Cloth(tc.grid_mesh(4, 4), tc.Material(), pinned=np.array([0.0, 1.5])), "pinned"),
    (lambda: tc.Cloth(tc.grid_mesh(4, 4), tc.Material(), pinned=np.array([0.0, 1.0])), "pinned"),
    (lambda: tc.init(threads=10**6), "threads"),
    (lambda: tc.init(threads=True), "threads"),
    (lambda: tc.grid_mesh(10**20, 3), "rows"),
    (lambda: tc.string(10**9, 1.0), "n"),
    (lambda: tc.hair(10**8, 4, 0.3), "strands"),
    (lambda: tc.tet_block(cells=(1000, 1000, 1000)), "cells"),
    (lambda: tc.SpringParams(1e300), "SpringParams.k"),
    (lambda: tc.Material(density=1e-300), "Material.density"),
    (lambda: tc.PBD(stiffness=[1, 2]), "PBD.stiffness"),
    (lambda: tc.XPBD(iterations=10**9), "XPBD.iterations"),
    (lambda: tc.StrainLimit(kinds=[[1]]), "StrainLimit.kinds"),
    (lambda: tc.Wind(velocity=(1e300, 0, 0)), "Wind.velocity[0]"),
    (lambda: tc.Wind(seed=-1), "Wind.seed"),
    (lambda: tc.Sphere(radius=1e300), "Sphere.radius"),
    (lambda: tc.Plane(point=(0, 1e300, 0)), "Plane.point[1]"),
    (lambda: tc.Keyframes((0.0,), ((1e300, 0, 0),)), "Keyframes.values"),
    (lambda: tc.Simulation(sheet(), integrator=["rk4"]), "integrator"),
    # issue 40: an int too big for a float, a name where a body goes, indices out of range
    (lambda: tc.SpringParams(k=10**400), "SpringParams.k"),
    (lambda: tc.Sphere(radius=-10**400), "Sphere.radius"),
    (lambda: tc.Material(density=10**400), "Material.density"),
    (lambda: tc.stable_dt("cloth"), "cloth"),
    (lambda: tc.stable_dt(sheet(), pinned=[0, 99]), "pinned"),
    (lambda: tc.stable_dt(sheet(), pinned=np.ones(3, bool)), "pinned.shape"),
]


def test_stable_dt_takes_pins_as_indices_or_a_mask_alike():
    """Pins given as indices (issue 40: they failed inside numpy with a broadcast message)
    give the step the same pins as a mask give; none pinned differs (the free sheet's limit
    is its own)."""
    cloth = sheet(6)
    mask = np.zeros(cloth.particle_count, bool)
    mask[[0, 5, 17]] = True
    by_index = tc.stable_dt(cloth, "symplectic_euler", pinned=[0, 5, 17])
    assert by_index == tc.stable_dt(cloth, "symplectic_euler", pinned=mask)
    assert by_index != tc.stable_dt(cloth, "symplectic_euler", pinned=[])


@pytest.mark.parametrize("call, named", API_MISTAKES, ids=[m[1] for m in API_MISTAKES])
def test_an_api_mistake_raises_value_error_naming_the_argument(call, named):
    with pytest.raises(ValueError, match=re.escape(named)):
        call()


SIMULATION_MISTAKES = [
    (dict(gravity=(1e300, 0, 0)), "gravity[0]"),
    (dict(dt=1e-320), "dt"),
    (dict(drag=1e300), "drag"),
    (dict(handles=tc.Handle([1], lambda t: (0, 0, 0))), "handles"),
    (dict(handles=[tc.Handle([1], lambda t: (0.0, 1.0))]), "Handle.path(0.0)"),
    (dict(handles=[tc.Handle([1], lambda t: (1e300, 0, 0))]), "Handle.path(0.0)"),
]


@pytest.mark.parametrize("options, named", SIMULATION_MISTAKES, ids=[m[1] for m in SIMULATION_MISTAKES])
def test_a_simulation_mistake_raises_naming_the_argument(f64, options, named):
    with pytest.raises(ValueError, match=re.escape(named)):
        tc.Simulation(sheet(), **options)


def test_a_body_too_big_for_memory_is_refused_before_allocating(monkeypatch):
    """The estimate (limits.memory_needed) against a machine of 1 GB: a 1,000 x 1,000 grid
    needs 250 B x 1e6 + 400 B x 6e6 = 2.65 GB and is refused naming rows x cols; 100 x 100 fits."""
    monkeypatch.setattr(limits, "physical_memory", lambda: 2**30)
    with pytest.raises(ValueError, match=r"rows x cols = 1000 x 1000 .* need about 2.\d+ GB; "
                                         r"this machine has 1 GB"):
        tc.grid_mesh(1000, 1000)
    assert tc.grid_mesh(100, 100).vertex_count == 10_000


@pytest.mark.reinitialises
def test_step_counts_are_checked_and_a_simulation_after_a_second_init_raises(f64):
    """sim.step(True) stepped and sim.step(2**63) was accepted; init resets Taichi and frees
    every field, so stepping or reading an older simulation crashed the process (SIGSEGV).
    Now: ValueError naming n, StaleSimulation, and a new simulation works."""
    sim = tc.Simulation(sheet(), dt=1e-3)
    for bad in (True, 2**63, limits.STEPS.high + 1, -1, 1.0):
        with pytest.raises(ValueError, match="n must be an int in"):
            sim.step(bad)
    assert sim.step_count == 0
    tc.init(precision="f32")
    try:
        for use_it in (sim.step, sim.positions, sim.velocities, sim.spring_alive, sim.restart,
                       lambda: sim.set_positions(np.zeros((16, 3)))):
            with pytest.raises(StaleSimulation, match="init was called again"):
                use_it()
    finally:
        use("f64")
    fresh = tc.Simulation(sheet(), dt=1e-3)
    fresh.step(2)
    assert np.isfinite(fresh.positions()).all()


@pytest.mark.reinitialises
def test_init_closes_the_renderers_of_the_runtime_it_ends(f64):
    """A Renderer's Taichi ndarrays freed after a second init asked the new runtime to delete
    them, and it freed its own live ndarray at the same address (a demo test's worker crashed
    in CI; here a renderer of the new runtime lost its buffer). Now init closes live renderers
    and collects dead ones first: the old renderers' buffers go with their runtime."""
    camera = Camera(position=(0.5, 1.0, 2.0), target=(0.5, 0.0, 0.0), fov=60.0)
    cloth = sheet()

    def frame(renderer):
        renderer.begin()
        renderer.draw_mesh(cloth.particle_position, cloth.mesh.triangles)
        return renderer.end()

    kept = Renderer(48, 32, camera)
    expected = frame(kept)
    gc.disable()                  # dead renderers stay uncollected until after the init
    try:
        for _ in range(8):
            dead = Renderer(48, 32, camera)
            dead.itself = dead     # a reference cycle: only the cycle collector frees it
            frame(dead)
        del dead
        tc.init(precision="f32")
        fresh = [Renderer(48, 32, camera) for _ in range(8)]
        gc.collect()
        for renderer in fresh:
            assert np.array_equal(frame(renderer), expected)
    finally:
        gc.enable()
        use("f64")
    with pytest.raises(ValueError, match="renderer"):
        kept.begin()


@pytest.mark.reinitialises
def test_ensure_keeps_the_runtime_a_caller_chose_when_asked_for_no_thread_count(f64):
    """run_scene, the CLI and the demos call backend.ensure without a thread count; it
    re-initialised a runtime given one (tc.init(threads=...)), dropping the caller's setting
    and every compiled kernel. Now only another arch, precision or an explicit other count
    starts a new runtime."""
    generation, given = backend.generation(), backend.config().threads
    assert given is not None              # the f64 fixture gives a count
    backend.ensure("cpu", "f64")          # no count asked: kept
    backend.ensure("cpu", "f64", threads=given)
    assert (backend.generation(), backend.config().threads) == (generation, given)
    try:
        backend.ensure("cpu", "f32")
        assert backend.generation() == generation + 1
        assert backend.config().precision == "f32"
    finally:
        use("f64")


@pytest.mark.parametrize("keys, says, counted", [
    (dict(simulation="fps = 10\nduration = 1.5\ntearing = 1e-9", body_keys='pinned = ["left"]',
          forces="wind = { velocity = [6, 0, 3] }"), "tearing = 1e-09", "springs"),
    (dict(simulation="fps = 10\nduration = 1.5",
          camera="position = [0.5, 0.5, 3.0]\ntarget = [0.5, 0.5, 0.0]"), "camera", "particles")])
def test_a_run_that_shreds_or_leaves_the_view_says_so_once_naming_the_setting(
        f64, tmp_path, keys, says, counted):
    """Issue 40: tearing = 1e-9 is legal, tears most springs of a flag in the wind in the
    first frame and used to finish in silence with frames of shreds; a free sheet falls out of
    a fixed camera's view. Each run warns once, naming the setting, when the frames show it:
    checked against the springs still intact, or the particles projected onto the image."""
    from ti_cloth.app.runner import run_scene
    text = scene_text(output="width = 64\nheight = 48", **keys)
    scene = load_scene(write_scene(tmp_path, text))
    with pytest.warns(RuntimeWarning, match=re.escape(says)) as caught:
        result = run_scene(scene, folder=tmp_path / "out", progress=False)
    assert len([w for w in caught if says in str(w.message)]) == 1
    sim = scene.build()
    sim.step(result.steps)
    if counted == "springs":
        report("springs intact at the end", int(sim.spring_alive().sum()), 0)
        assert sim.spring_alive().mean() < 0.5
    else:
        screen, depth = scene.camera.project(sim.positions(), 64, 48)
        shown = ((screen >= 0) & (screen <= (64, 48))).all(axis=1) & (depth > 0)
        report("particles on the image at the end", int(shown.sum()), 0)
        assert shown.mean() < 0.5


def test_tearing_does_not_hide_a_step_ten_times_too_large(f64):
    """Issue 16: at 10 x the stable step a tearable cloth exploded into finite pieces flying at
    hundreds of m/s and the run ended 'fine'. Now the tear avalanche stops it, naming the step
    and a stable dt; at half the stable step the same cloth tears nothing."""
    cloth = tc.Cloth(tc.grid_mesh(8, 8, size=(0.5, 0.5)), tc.Material(), pinned=[56, 63])
    stable = tc.stable_dt(cloth, "symplectic_euler")
    sim = tc.Simulation(cloth, dt=10 * stable, tearing=0.3)
    with pytest.raises(tc.SimulationDiverged, match=r"springs tore in that step") as err:
        sim.step(200)
    assert err.value.step < 50 and err.value.stable_dt == pytest.approx(stable)
    assert np.isfinite(sim.positions()).all()            # finite: only the tear check saw it
    sim.restart(dt=0.5 * stable)
    sim.step(400)
    assert sim.torn_count == 0


def test_temporaries_of_a_killed_run_are_removed_when_the_next_run_starts(tmp_path):
    (tmp_path / ".frame_00048.tmp.png").write_bytes(b"")
    (tmp_path / ".tiny.tmp.gif").write_bytes(b"")
    (tmp_path / ".keep.png").write_bytes(b"")
    FrameSequence(tmp_path, gif=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == [".keep.png"]


def test_exit_codes_are_128_plus_the_signal():
    assert signals.exit_code(KeyboardInterrupt()) == 130                 # Ctrl-C
    assert signals.exit_code(signals.Stopped(signal.SIGTERM)) == 143


def test_a_signal_the_process_ignores_stays_ignored_during_a_run():
    """A shell script's background job starts with SIGINT ignored (the script's Ctrl-C is for
    its foreground job); a run keeps that, while SIGTERM still stops it."""
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with pytest.raises(signals.Stopped) as stop:
            with signals.stop_signals_raise():
                signal.raise_signal(signal.SIGINT)
                signal.raise_signal(signal.SIGTERM)
        assert stop.value.signum == signal.SIGTERM
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)


def test_the_documented_limits_table_is_the_one_in_limits_py():
    page = (Path(__file__).parents[1] / "docs" / "integrators.md").read_text()
    assert limits.markdown() in page


def test_a_mesh_that_is_not_a_surface_is_described_with_what_the_body_does_there():
    """Issue 40: three triangles on one edge (a fin) and two sheets sharing one vertex (a
    bowtie) were taken without a word. Now a warning names the edge and the vertex, and the
    body does what it says: no bend spring or hinge across the fin's edge (counted), while
    the same edge between two triangles gets one. A closed sphere and an open disc are
    surfaces: no warning."""
    v = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0.5], [-1, 0, 0.5], [0, 1, 0.5]], float)
    fin = tc.Mesh(v, np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]]))
    pair = tc.Mesh(v[:4], np.array([[0, 1, 2], [1, 0, 3]]))
    for material, count in ((tc.Material(), lambda c: (c.spring_kind == tc.SpringKind.BEND).sum()),
                            (tc.Fabric.preset("denim"), lambda c: c.hinge_count)):
        with pytest.warns(UserWarning, match=re.escape("shared by three or more triangles "
                                                       "(first [[0, 1]])")):
            assert count(tc.Cloth(fin, material)) == 0
        assert count(tc.Cloth(pair, material)) == 1
    bowtie = tc.Mesh(np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0.5], [2, 0, 0], [2, 0, 1]], float),
                     np.array([[0, 1, 2], [2, 3, 4]]))
    with pytest.warns(UserWarning, match=re.escape("separate sheets meet at a point (first [2])")):
        tc.Cloth(bowtie, tc.Material())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tc.Cloth(tc.sphere_mesh(1.0), tc.Material())
        tc.Cloth(tc.disc_mesh(), tc.Material())
        tc.Cloth(pair, tc.Material())
