"""Animated meshes read from files (animation_files.py, AnimatedMeshCollider.load, scene files'
`type = "animated_mesh"`): each format written here independently (the PC2 header packed by
hand, the OBJ frames by meshio, the USD stage by pxr with a transform and centimetre units)
reads back as the motion written, our own exports read back as the frames they hold, and a
bad file is an error naming the key and what is wrong."""

import struct

import meshio
import numpy as np
import pytest
from helpers import report

import ti_cloth as tc
from ti_cloth.app.scene import load_scene
from ti_cloth.inputs.scene_file import SceneError

TETRAHEDRON = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
FACES = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
SAMPLES = np.stack([TETRAHEDRON * (1.0 + 0.1 * k) + (0.0, 0.05 * k, 0.0) for k in range(5)])
FLOAT32 = 1e-6       # PC2 and USD points are float32: a relative rounding of 2^-24 on ~1.5 m


def write_pc2(path, samples, start=0.0, rate=1.0):
    """A PC2 cache (Blender's point cache format), packed here from its published layout."""
    header = struct.pack("<12siiffi", b"POINTCACHE2\0", 1, samples.shape[1], start, rate,
                         len(samples))
    path.write_bytes(header + samples.astype("<f4").tobytes())


def write_usd(path, samples, times, per_second, metres_per_unit=None, translate=None,
              z_up=False):
    from pxr import Gf, Usd, UsdGeom
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetTimeCodesPerSecond(per_second)
    if z_up:                                       # as Blender writes: y up becomes z up
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
        samples = samples[..., [0, 2, 1]] * (1.0, -1.0, 1.0)
    if metres_per_unit is not None:
        UsdGeom.SetStageMetersPerUnit(stage, metres_per_unit)
    root = UsdGeom.Xform.Define(stage, "/figure")
    if translate is not None:
        root.AddTranslateOp().Set(Gf.Vec3d(*translate))
    mesh = UsdGeom.Mesh.Define(stage, "/figure/body")
    mesh.CreateFaceVertexCountsAttr([4, 3, 3])    # FACES[0] and FACES[1] as one quad
    mesh.CreateFaceVertexIndicesAttr([0, 2, 1, 3, 0, 3, 2, 1, 2, 3])
    for sample, time in zip(samples, times):
        mesh.GetPointsAttr().Set([Gf.Vec3f(*p) for p in sample], time)
    UsdGeom.Mesh.Define(stage, "/figure/still").CreatePointsAttr([Gf.Vec3f(0, 0, 0)] * 3)
    stage.Save()


def test_npz_pc2_and_an_obj_sequence_read_back_as_written(tmp_path):
    np.savez(tmp_path / "walk.npz", triangles=FACES, positions=SAMPLES, fps=24.0)
    write_pc2(tmp_path / "walk.pc2", SAMPLES, start=1.0, rate=2.0)
    meshio.write_points_cells(tmp_path / "rest.obj", SAMPLES[0], [("triangle", FACES)])
    for k in (10, 9, 8, 11, 12):           # numbered past 9: ordered by number, not by name
        meshio.write_points_cells(tmp_path / f"walk_{k}.obj", SAMPLES[k - 8], [("triangle",
                                                                                 FACES)])
    npz = tc.AnimatedMeshCollider.load(tmp_path / "walk.npz", thickness=0.01)
    pc2 = tc.AnimatedMeshCollider.load(tmp_path / "walk.pc2", rest=tmp_path / "rest.obj",
                                       fps=24)
    obj = tc.AnimatedMeshCollider.load(tmp_path / "walk_*.obj", fps=30)
    report("samples per second (npz, pc2 at 24 fps sampling every 2nd frame, obj)",
           (npz.fps, pc2.fps, obj.fps), (24.0, 12.0, 30.0))
    assert (npz.fps, pc2.fps, obj.fps) == (24.0, 12.0, 30.0) and npz.thickness == 0.01
    np.testing.assert_array_equal(npz.motion, SAMPLES)
    np.testing.assert_allclose(pc2.motion, SAMPLES, rtol=0, atol=FLOAT32)
    np.testing.assert_allclose(obj.motion, SAMPLES, rtol=0, atol=1e-12)
    for collider in (npz, pc2, obj):
        np.testing.assert_array_equal(collider.mesh.triangles, FACES)
    np.testing.assert_allclose(obj.vertices_at(1.5 / 30), 0.5 * (SAMPLES[1] + SAMPLES[2]),
                               atol=1e-12)


def test_a_usd_stage_gives_world_positions_in_metres_at_every_time_code(tmp_path):
    """Samples at codes 0, 2, 4, 6, 8 are read at every code (USD interpolates linearly
    between samples), through the prim's parent transform and the stage's centimetres."""
    pytest.importorskip("pxr")
    write_usd(tmp_path / "walk.usda", SAMPLES, range(0, 10, 2), 48, translate=(100, 0, 0))
    collider = tc.AnimatedMeshCollider.load(tmp_path / "walk.usda")
    expected = np.empty((9, 4, 3))
    expected[0::2] = SAMPLES
    expected[1::2] = 0.5 * (SAMPLES[:-1] + SAMPLES[1:])
    expected = (expected + (100.0, 0.0, 0.0)) * 0.01        # USD's default unit is the cm
    report("USD samples per second, sample count", (collider.fps, len(collider.motion)),
           (48.0, 9))
    assert collider.fps == 48.0
    np.testing.assert_allclose(collider.motion, expected, rtol=0, atol=FLOAT32)
    np.testing.assert_array_equal(collider.mesh.triangles, FACES)
    metres = tmp_path / "metres.usda"
    write_usd(metres, SAMPLES, range(5), 24, metres_per_unit=1.0)
    np.testing.assert_allclose(tc.AnimatedMeshCollider.load(metres, fps=12).motion, SAMPLES,
                               atol=FLOAT32)
    assert tc.AnimatedMeshCollider.load(metres, fps=12).fps == 12.0
    upright = tmp_path / "z_up.usda"
    write_usd(upright, SAMPLES, range(5), 24, metres_per_unit=1.0, z_up=True)
    np.testing.assert_allclose(tc.AnimatedMeshCollider.load(upright).motion, SAMPLES,
                               atol=FLOAT32)


def test_our_own_pc2_and_usd_exports_play_back_as_colliders(f64, tmp_path):
    """A body exported by tc.Exporter (PC2 with its rest OBJ, USD) is an animated collider
    whose samples are the frames the simulation had."""
    pytest.importorskip("pxr")
    mesh = tc.grid_mesh(5, 5, (0.4, 0.4))
    cloth = tc.Cloth(mesh, tc.Material(), pinned=[0, 4])
    sim = tc.Simulation(cloth, integrator="xpbd", dt=1 / 240)
    frames = []
    with tc.Exporter(tmp_path, ["pc2", "usd"], name="flag", cloth=cloth, fps=30) as export:
        for frame in range(4):
            if frame:
                sim.step(8)
            export.write(sim)
            frames.append(sim.positions())
    pc2 = tc.AnimatedMeshCollider.load(tmp_path / "flag_body0.pc2",
                                       rest=tmp_path / "flag_body0_rest.obj", fps=30)
    usd = tc.AnimatedMeshCollider.load(tmp_path / "flag.usdc")
    for collider in (pc2, usd):
        assert collider.fps == 30.0
        np.testing.assert_allclose(collider.motion, np.asarray(frames), rtol=0, atol=FLOAT32)


def test_bad_animation_files_are_refused_by_key(tmp_path):
    np.savez(tmp_path / "ok.npz", triangles=FACES, positions=SAMPLES, fps=24.0)
    np.savez(tmp_path / "nofps.npz", triangles=FACES, positions=SAMPLES)
    np.savez(tmp_path / "nopositions.npz", triangles=FACES)
    (tmp_path / "cut.npz").write_bytes((tmp_path / "ok.npz").read_bytes()[:200])
    write_pc2(tmp_path / "five.pc2", SAMPLES[:, :3])
    (tmp_path / "short.pc2").write_bytes(b"POINTCACHE2\0\x01")
    meshio.write_points_cells(tmp_path / "rest.obj", TETRAHEDRON, [("triangle", FACES)])
    meshio.write_points_cells(tmp_path / "seq_1.obj", TETRAHEDRON, [("triangle", FACES)])
    meshio.write_points_cells(tmp_path / "seq_2.obj", TETRAHEDRON[:3], [("triangle", FACES[:1])])
    np.savez(tmp_path / "complex.npz", triangles=FACES, positions=SAMPLES + 1j, fps=24.0)
    np.savez(tmp_path / "text.npz", triangles=FACES, positions=SAMPLES.astype(str), fps=24.0)
    collapsed = SAMPLES.copy()
    collapsed[3] = TETRAHEDRON[0]                  # sample 3: every vertex on one point
    np.savez(tmp_path / "collapsed.npz", triangles=FACES, positions=collapsed, fps=24.0)
    flat = SAMPLES.copy()
    flat[2, :, 1:] = 0.0                           # sample 2: every vertex on the x axis
    write_pc2(tmp_path / "flat.pc2", flat)
    (tmp_path / "broken.usda").write_text("#usda 1.0\n(\n  garbage (((\n")
    (tmp_path / "noise.usdc").write_bytes(bytes(range(256)))
    cases = [
        (dict(path=tmp_path / "cut.npz"), "is not a readable npz file"),
        (dict(path=tmp_path / "complex.npz"), "positions must be real numbers"),
        (dict(path=tmp_path / "text.npz"), "positions must be real numbers"),
        (dict(path=tmp_path / "collapsed.npz"), "motion[3] must be a surface in every sample"),
        (dict(path=tmp_path / "flat.pc2", rest=tmp_path / "rest.obj", fps=24),
         "motion[2] must be a surface in every sample"),
        (dict(path=tmp_path / "broken.usda"), "usd-core can open, got "),
        (dict(path=tmp_path / "broken.usda"), "(line 3, column 3: Expected )"),
        (dict(path=tmp_path / "noise.usdc"), "(usd-core cannot parse it)"),
        (dict(path=tmp_path / "nofps.npz"), "fps must be the animation's frames per second"),
        (dict(path=tmp_path / "nopositions.npz"), "missing: positions"),
        (dict(path=tmp_path / "ok.npz", rest=tmp_path / "rest.obj"),
         "rest must be given only with a PC2 cache"),
        (dict(path=tmp_path / "five.pc2", rest=tmp_path / "rest.obj", fps=24),
         "five.pc2: points must be 4, the vertex count of the rest mesh rest.obj, got 3"),
        (dict(path=tmp_path / "five.pc2", fps=24), "rest must be the mesh file"),
        (dict(path=tmp_path / "short.pc2", rest=tmp_path / "rest.obj", fps=24),
         "is not a readable PC2 cache"),
        (dict(path=tmp_path / "seq_*.obj", fps=24), "seq_2.obj: vertices must be 4"),
        (dict(path=tmp_path / "none_*.obj", fps=24), "a pattern matching at least one"),
        (dict(path=tmp_path / "ok.npz", fps=0.0), "fps must be a finite number in [1, 1000] frames/s"),
        (dict(path=tmp_path / "rest.obj"), "is not an animation file this reads"),
    ]
    for arguments, message in cases:
        with pytest.raises(ValueError) as caught:
            tc.AnimatedMeshCollider.load(**arguments)
        report(str(arguments["path"].name), str(caught.value), message)
        assert message in str(caught.value)


def test_an_animation_too_big_is_refused_before_it_is_read(tmp_path, monkeypatch):
    """The npz member's stored size and the PC2 file's size are checked against the limit
    on numbers (limits.MOTION_VALUES, lowered here to 10) before any of it is loaded."""
    from ti_cloth.inputs import limits
    many = np.tile(SAMPLES, (10, 1, 1))                  # 600 numbers, 4,800 bytes
    np.savez(tmp_path / "walk.npz", triangles=FACES, positions=many, fps=24.0)
    write_pc2(tmp_path / "walk.pc2", SAMPLES)
    meshio.write_points_cells(tmp_path / "rest.obj", TETRAHEDRON, [("triangle", FACES)])
    monkeypatch.setattr(limits, "MOTION_VALUES", 10)
    with pytest.raises(ValueError, match=r"walk.npz: positions must be at most 10 numbers"):
        tc.AnimatedMeshCollider.load(tmp_path / "walk.npz")
    with pytest.raises(ValueError, match=r"walk.pc2 must be a cache of at most 10 numbers"):
        tc.AnimatedMeshCollider.load(tmp_path / "walk.pc2", rest=tmp_path / "rest.obj", fps=24)


def test_scene_files_read_an_animated_mesh_relative_to_the_scene_scaled_and_moved(tmp_path):
    (tmp_path / "assets").mkdir()
    np.savez(tmp_path / "assets" / "walk.npz", triangles=FACES, positions=SAMPLES, fps=24.0)
    scene = tmp_path / "walk.toml"
    body = ('[[bodies]]\ntype = "grid"\nrows = 4\ncols = 4\norigin = [0, 2, 0]\n'
            '[[colliders]]\ntype = "animated_mesh"\npath = "assets/walk.npz"\n'
            'scale = 2.0\ntranslate = [0, 0.5, 0]\nstatic_friction = 0.4\n')
    scene.write_text(body)
    collider = load_scene(scene).colliders[0]
    assert isinstance(collider, tc.AnimatedMeshCollider) and collider.static_friction == 0.4
    np.testing.assert_allclose(collider.motion, SAMPLES * 2.0 + (0.0, 0.5, 0.0), atol=1e-12)
    for extra, message in (('fps = "fast"', "colliders[0].fps must be"),
                           ('rest = "walk.obj"', "colliders[0]: rest must be given only with"),
                           ('prim = "/body"', "colliders[0]: prim must be given only with"),
                           ('motion = 1', "colliders[0].motion is not a known key")):
        scene.write_text(body + extra + "\n")
        with pytest.raises(SceneError, match=message.replace("[", r"\[").replace(".", r"\.")):
            load_scene(scene)
    scene.write_text(body.replace("assets/walk.npz", "assets/gone.npz"))
    with pytest.raises(SceneError, match="colliders\\[0\\]: path must be an existing animation"):
        load_scene(scene)
