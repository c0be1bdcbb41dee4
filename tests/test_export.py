"""Geometry export (export.py): OBJ and PLY read back through meshio, USD through pxr, PC2
parsed back, npz; ghosts left out, torn triangles dropped per frame."""

import meshio
import numpy as np
import pytest
from helpers import report

import ti_cloth as tc
from ti_cloth.export import read_pc2


def torn_sheet():
    """A 6 x 6 sheet held at its left edge while a handle drags its right edge away fast: it
    tears within a few frames."""
    mesh = tc.grid_mesh(6, 6, size=(0.5, 0.5))
    left = np.flatnonzero(mesh.vertices[:, 0] == 0.0)
    right = np.flatnonzero(np.isclose(mesh.vertices[:, 0], 0.5))
    cloth = tc.Cloth(mesh, tc.Material(), pinned=left)
    pull = tc.Handle(right, lambda t: (2.0 * t, 0.0, 0.0))
    return tc.Simulation(cloth, integrator="xpbd", dt=1 / 240, tearing=0.3, handles=[pull]), cloth


def test_obj_ply_pc2_and_npz_hold_each_frame_as_the_simulation_had_it(f64, tmp_path):
    sim, cloth = torn_sheet()
    frames, positions, faces = 6, [], []
    with tc.Exporter(tmp_path, ["obj", "ply", "pc2", "npz", "usd"], name="sheet", cloth=cloth,
                     fps=30) as export:
        for frame in range(frames):
            if frame:
                sim.step(8)
            export.write(sim)
            positions.append(sim.positions())
            torn = set(sim.torn_triangles().tolist())
            faces.append([tuple(t) for k, t in enumerate(cloth.mesh.triangles.tolist())
                          if k not in torn])
    report("triangles shown per frame", [len(f) for f in faces], "fewer once it tears")
    assert len(faces[0]) == cloth.mesh.triangle_count and len(faces[-1]) < len(faces[0])
    for frame in range(frames):
        for ext in ("obj", "ply"):
            read = meshio.read(tmp_path / f"sheet_body0_{frame:05d}.{ext}")
            np.testing.assert_allclose(read.points, positions[frame], rtol=0, atol=1e-12)
            assert [tuple(t) for t in read.cells_dict["triangle"].tolist()] == faces[frame]
    header, cached = read_pc2(tmp_path / "sheet_body0.pc2")
    assert header == {"points": cloth.particle_count, "start": 0.0, "rate": 1.0, "samples": frames}
    np.testing.assert_array_equal(cached, np.asarray(positions, np.float32))
    rest = meshio.read(tmp_path / "sheet_body0_rest.obj")
    np.testing.assert_allclose(rest.points, cloth.particle_position, atol=1e-12)
    assert len(rest.cells_dict["triangle"]) == cloth.mesh.triangle_count
    saved = np.load(tmp_path / "sheet.npz")
    np.testing.assert_array_equal(saved["positions"], np.asarray(positions))
    np.testing.assert_allclose(saved["time"], np.arange(frames) * 8 / 240, atol=1e-12)
    assert not list(tmp_path.glob(".*tmp*"))
    from pxr import Usd, UsdGeom
    stage = Usd.Stage.Open(str(tmp_path / "sheet.usdc"))
    assert (stage.GetTimeCodesPerSecond(), stage.GetFramesPerSecond()) == (30, 30)
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, frames - 1)
    assert UsdGeom.GetStageUpAxis(stage) == "Y" and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/sheet/body0"))
    for frame in range(frames):
        np.testing.assert_array_equal(np.asarray(mesh.GetPointsAttr().Get(frame)),
                                      np.asarray(positions[frame], np.float32))
        indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(frame)).reshape(-1, 3)
        assert [tuple(t) for t in indices.tolist()] == faces[frame]


def test_ghost_particles_are_never_exported_and_strands_are_lines(f64, tmp_path):
    hair = tc.hair(4, 3, 0.2, ghosts=True)
    assert hair.ghost.any()
    sim = tc.Simulation(hair, integrator="implicit_euler", dt=1e-3)
    with tc.Exporter(tmp_path, ["ply", "pc2", "npz", "usd"], name="hair", cloth=hair, fps=30,
                     usd_suffix=".usda") as export:
        export.write(sim)
    shown = np.flatnonzero(~hair.ghost)
    read = meshio.read(tmp_path / "hair_body0_00000.ply")
    np.testing.assert_allclose(read.points, sim.positions()[shown], atol=1e-12)
    segments = shown[read.cells_dict["line"]]
    stretch = {tuple(s) for s in np.sort(hair.spring_indices[hair.spring_kind == tc.SpringKind.STRETCH], axis=1)}
    assert {tuple(s) for s in np.sort(segments, axis=1)} <= stretch and len(segments) == 4 * 3
    assert read_pc2(tmp_path / "hair_body0.pc2")[0]["points"] == len(shown)
    np.testing.assert_array_equal(np.load(tmp_path / "hair.npz")["particle"], shown)
    from pxr import Usd, UsdGeom
    stage = Usd.Stage.Open(str(tmp_path / "hair.usda"))
    curves = UsdGeom.BasisCurves(stage.GetPrimAtPath("/hair/body0"))
    assert list(curves.GetCurveVertexCountsAttr().Get()) == [2] * len(segments)
    np.testing.assert_array_equal(np.asarray(curves.GetPointsAttr().Get(0)),
                                  sim.positions()[segments.ravel()].astype(np.float32))


def test_bad_formats_are_refused_by_name(tmp_path):
    with pytest.raises(ValueError, match="export format must be one of"):
        tc.Exporter(tmp_path, ["obj", "fbx"], name="x", cloth=tc.string(4, 1.0), fps=30)


def normals_here(points, triangles):
    """Area-weighted unit vertex normals, computed here with a loop (not export.py's)."""
    n = np.zeros_like(points)
    for a, b, c in triangles:
        face = np.cross(points[b] - points[a], points[c] - points[a])
        for k in (a, b, c):
            n[k] += face
    return n / np.linalg.norm(n, axis=1, keepdims=True)


@pytest.mark.parametrize("kind", ["grid", "garment"])
def test_sheets_carry_uvs_and_normals_through_obj_ply_and_usd(kind, f64, tmp_path):
    """A grid's uvs (column / (cols - 1), row / (rows - 1)) or a garment's pattern, and each
    frame's vertex normals, read back through meshio (OBJ, PLY) and pxr (USD); OBJ faces name
    their texture and normal indices (f v/vt/vn), as Blender needs."""
    if kind == "grid":
        rows, cols = 4, 5
        mesh = tc.grid_mesh(rows, cols, size=(0.4, 0.3), plane="xz")
        r, c = np.divmod(np.arange(rows * cols), cols)
        uvs = np.stack([c / (cols - 1), r / (rows - 1)], axis=1)
        cloth = tc.Cloth(mesh, tc.Material(), pinned=[0, cols - 1])
    else:
        piece = tc.panel([(-0.2, 0.0), (0.2, 0.0), (0.15, 0.3), (-0.15, 0.3)], edge_length=0.08)
        garment = tc.Garment([piece.wrapped(0.2)], seams=[])
        mesh, uvs = garment.mesh, garment.mesh.uvs
        top = np.flatnonzero(mesh.vertices[:, 1] > mesh.vertices[:, 1].max() - 1e-9)
        cloth = tc.Cloth(mesh, tc.Material(), pinned=top, rest="uv")
    sim = tc.Simulation(cloth, integrator="xpbd", dt=1 / 240)
    positions = []
    with tc.Exporter(tmp_path, ["obj", "ply", "usd"], name="s", cloth=cloth, fps=30) as export:
        for frame in range(3):
            if frame:
                sim.step(8)
            export.write(sim)
            positions.append(sim.positions())
    triangles = cloth.mesh.triangles
    for frame, x in enumerate(positions):
        normals = normals_here(x, triangles)
        obj = meshio.read(tmp_path / f"s_body0_{frame:05d}.obj")
        np.testing.assert_allclose(obj.point_data["obj:vt"], uvs, atol=1e-12)
        np.testing.assert_allclose(obj.point_data["obj:vn"], normals, atol=1e-12)
        faces = [line for line in (tmp_path / f"s_body0_{frame:05d}.obj").read_text().splitlines()
                 if line.startswith("f ")]
        a, b, c = triangles[0] + 1
        assert faces[0] == f"f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}"
        ply = meshio.read(tmp_path / f"s_body0_{frame:05d}.ply")
        np.testing.assert_allclose(np.stack([ply.point_data[k] for k in "st"], 1), uvs, atol=1e-12)
        np.testing.assert_allclose(np.stack([ply.point_data[f"n{k}"] for k in "xyz"], 1),
                                   normals, atol=1e-12)
    from pxr import Usd, UsdGeom
    stage = Usd.Stage.Open(str(tmp_path / "s.usdc"))
    usd = UsdGeom.Mesh(stage.GetPrimAtPath("/s/body0"))
    st = UsdGeom.PrimvarsAPI(usd).GetPrimvar("st")
    assert st.GetInterpolation() == "vertex" and usd.GetNormalsInterpolation() == "vertex"
    np.testing.assert_allclose(np.array(st.Get()), uvs, atol=1e-6)
    for frame, x in enumerate(positions):
        np.testing.assert_allclose(np.array(usd.GetNormalsAttr().Get(frame)),
                                   normals_here(x, triangles), atol=1e-6)


def test_the_usd_stage_holds_every_collider_with_its_motion(f64, tmp_path):
    """Each kind of collider read back through pxr as the shape it is at each frame's time,
    computed here from its definition: a sphere on a path (its translation per frame), a box
    (its world bounds), a capsule (its axis ends), a plane (a square: its faces' normal and its
    middle), a static
    mesh (its points, once) and an animated mesh (its samples, one per frame)."""
    from pxr import Usd, UsdGeom

    fps, frames = 30, 5
    swing = lambda t: (0.2 * t, 0.0, 0.0)                              # noqa: E731
    box_mesh = tc.sphere_mesh(0.1, subdivisions=1)
    motion = np.stack([box_mesh.vertices + (0.0, 0.05 * k, 0.0) for k in range(frames)])
    colliders = [tc.Sphere(centre=(0.0, 0.3, 0.0), radius=0.2, path=swing),
                 tc.Box(lo=(0.3, 0.0, -0.2), hi=(0.6, 0.3, 0.2)),
                 tc.Capsule(a=(-0.6, 0.2, -0.3), b=(-0.3, 0.5, 0.3), radius=0.08),
                 tc.Plane(point=(0.0, -0.1, 0.0), normal=(0.0, 0.6, 0.8)),
                 tc.MeshCollider(tc.sphere_mesh(0.1, subdivisions=1, centre=(1.0, 0.0, 0.0))),
                 tc.AnimatedMeshCollider(box_mesh, motion, fps=fps)]
    cloth = tc.Cloth(tc.grid_mesh(4, 4, size=(0.5, 0.5), plane="xz", origin=(-0.25, 0.8, -0.25)),
                     tc.Material())
    sim = tc.Simulation(cloth, integrator="xpbd", dt=1 / 240, colliders=colliders)
    with tc.Exporter(tmp_path, ["usd"], name="scene", cloth=cloth, fps=fps,
                     usd_suffix=".usda", colliders=colliders) as export:
        for frame in range(frames):
            if frame:
                sim.step(8)
            export.write(sim)
    stage = Usd.Stage.Open(str(tmp_path / "scene.usda"))
    prims = [stage.GetPrimAtPath(f"/scene/colliders/collider{i}") for i in range(6)]
    assert [p.GetTypeName() for p in prims] == ["Sphere", "Cube", "Capsule", "Mesh", "Mesh",
                                                "Mesh"]

    def world(prim, point, frame):
        m = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(frame))
        return np.append(point, 1.0) @ m

    for frame in range(frames):
        t = frame / fps
        np.testing.assert_allclose(world(prims[0], (0, 0, 0), frame)[:3],
                                   np.add((0.0, 0.3, 0.0), swing(t)), atol=1e-9)
        np.testing.assert_allclose(np.asarray(UsdGeom.Mesh(prims[5]).GetPointsAttr().Get(frame)),
                                   motion[frame], atol=1e-6)            # float32 points
    assert UsdGeom.Sphere(prims[0]).GetRadiusAttr().Get() == 0.2
    bounds = UsdGeom.BBoxCache(0, ["default"]).ComputeWorldBound(prims[1]).ComputeAlignedRange()
    np.testing.assert_allclose([bounds.GetMin(), bounds.GetMax()],
                               [(0.3, 0.0, -0.2), (0.6, 0.3, 0.2)], atol=1e-6)
    half = UsdGeom.Capsule(prims[2]).GetHeightAttr().Get() / 2
    np.testing.assert_allclose([world(prims[2], (0, -half, 0), 0)[:3],
                                world(prims[2], (0, half, 0), 0)[:3]],
                               [(-0.6, 0.2, -0.3), (-0.3, 0.5, 0.3)], atol=1e-6)
    square = np.asarray(UsdGeom.Mesh(prims[3]).GetPointsAttr().Get(), np.float64)
    faces = np.asarray(UsdGeom.Mesh(prims[3]).GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
    for a, b, c in square[faces]:
        normal = np.cross(b - a, c - a)
        np.testing.assert_allclose(normal / np.linalg.norm(normal), (0.0, 0.6, 0.8), atol=1e-6)
    np.testing.assert_allclose(square.mean(axis=0), (0.0, -0.1, 0.0), atol=1e-6)
    points = UsdGeom.Mesh(prims[4]).GetPointsAttr()
    assert points.GetNumTimeSamples() == 0           # a still mesh: its points once
    np.testing.assert_allclose(np.asarray(points.Get()), colliders[4].mesh.vertices, atol=1e-6)
