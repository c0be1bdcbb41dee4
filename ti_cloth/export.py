"""Geometry out of a run, frame by frame, for Blender, Houdini, Omniverse and numpy: OBJ / PLY
files per frame and body (through meshio), a PC2 point cache per body with its rest-pose OBJ
(Blender's Mesh Cache modifier), one USD stage (Pixar's usd-core, the optional extra `[usd]`)
and an npz of positions and velocities.

    with tc.Exporter("out", ["obj", "pc2"], name="drape", fps=30, cloth=cloth) as export:
        for frame in range(frames):
            export.write(sim)              # frame 0 first: the state as it is now
            sim.step(substeps)

A sheet carries texture coordinates and vertex normals in every mesh format: its mesh's uvs
(a garment's pattern, in metres; a mesh file's), or a grid's (u along its columns, v along its
rows, each from 0 to 1), and each frame's area-weighted vertex normals (OBJ: `vt` and `vn`,
faces `f v/vt/vn`; PLY: `s t` and `nx ny nz` per vertex; USD: `primvars:st` per vertex and
time-sampled `normals`). OBJ is written here rather than by meshio, whose OBJ faces name no
texture or normal index (Blender then drops both).

Only what a body shows is written: ghost particles (hair) never are, and a torn triangle
leaves the frame's OBJ / PLY from the frame it tore in (a PC2 cache keeps the rest topology).
Bodies without triangles (strings, hair) are written as line segments (their stretch
springs) in PLY, as points in OBJ (meshio's OBJ has no lines) and in full in the PC2 and npz.
OBJ / PLY files are written as frames come; the PC2 caches, the npz and the USD stage are
assembled by close() from a journal the frames are appended to (`.<name>.journal`, fixed-size
records), so a run stopped by Ctrl-C, SIGTERM or a divergence still gets them with every
finished frame, and a run killed outright (SIGKILL, power loss) resumes from a saved state
(`first_frame`) with the journal's earlier frames. Every file is written under a temporary
name and renamed.
"""

from __future__ import annotations

import json
import re
import struct
from pathlib import Path

import numpy as np

from .body.material import SpringKind
from .errors import StateMismatch
from .inputs import limits
from .inputs.files import atomic_path
from .inputs.validation import finite_number, require
from .runtime import backend

FORMATS = limits.EXPORT_FORMATS
STREAMS = ("pc2", "npz", "usd")            # assembled at close from the journal
PC2_HEADER = struct.Struct("<12siiffi")   # "POINTCACHE2\0", version 1, points, start, rate, samples
JOURNAL_MAGIC = b"TICLOTHJ"
MESHIO_STAMP = re.compile(rb"Created by meshio [^,\r\n]*(, [^\r\n]*)")   # group 1: the time
HEADER_BYTES = 512        # where OBJ's and PLY's header comment is


class Exporter:
    """Writes the frames of one run in `formats` (a list of FORMATS) into `folder`:
    obj, ply: `<name>_<body>_<frame:05d>.<ext>` per frame and body;
    pc2: `<name>_<body>.pc2` (float32 points per frame, start frame 0, one sample per frame)
        and `<name>_<body>_rest.obj`, its rest pose with the same vertices in the same order;
    npz: `<name>.npz` with `positions` and `velocities` (frames, points, 3) [m, m/s], `time`
        (frames,) [s], and per point its `particle` index in the Cloth and its `body`;
    usd: `<name>.usdc` (or `.usda` with usd_suffix=".usda"), one stage: each body a
        UsdGeom.Mesh (strings and hair: UsdGeom.BasisCurves, linear) under /<name>/body<b>
        with its points time-sampled per frame (time code = frame) and, for a mesh that tears,
        its faces too; time codes per second = frames per second = fps, start and end time
        codes, up axis Y, metres per unit 1.
        colliders: each under /<name>/colliders/collider<i>: a mesh (MeshCollider,
        AnimatedMeshCollider) a UsdGeom.Mesh whose points are time-sampled when it moves;
        a Sphere, Box (a Cube scaled) or Capsule (along Y, turned) the UsdGeom shape,
        translated by time samples when it has a path; a Plane a mesh square PLANE_SIZE wide
        (Blender 4.2 reads no UsdGeom.Plane).
    Bodies are named body0, body1, ... in the order the Cloth joined them.
    first_frame: the frame the first write() is (a resumed run: the files of the frames
        before it stay, and the journal keeps exactly those frames; StateMismatch if it holds
        fewer or another layout)."""

    def __init__(self, folder, formats, *, name: str, cloth, fps: float,
                 usd_suffix: str = ".usdc", first_frame: int = 0, colliders=()):
        formats = [formats] if isinstance(formats, str) else list(formats)
        for f in formats:
            require(f in FORMATS, "export format", f, f"one of {FORMATS}")
        require(usd_suffix in (".usdc", ".usda"), "usd_suffix", usd_suffix, '".usdc" or ".usda"')
        self.folder, self.formats, self.name = Path(folder), formats, name
        self.fps = finite_number("fps", fps, 0.0, strict=True, unit="frames/s")
        self.cloth, self.colliders = cloth, tuple(colliders)
        self.bodies = [_Body(cloth, b) for b in range(cloth.body_count)]
        self._shown = np.concatenate([body.points for body in self.bodies])   # npz order
        ends = np.cumsum([len(body.points) for body in self.bodies])
        self._slices = [slice(end - len(body.points), end) for body, end in zip(self.bodies, ends)]
        self.usd_path = self.folder / f"{name}{usd_suffix}"
        self.frames = first_frame
        self.paths: list[Path] = []
        self.folder.mkdir(parents=True, exist_ok=True)
        for ext in {"obj", "ply"} & set(formats):
            for path in self.folder.glob(f"{name}_body*_[0-9][0-9][0-9][0-9][0-9].{ext}"):
                if int(path.stem[-5:]) < first_frame:
                    self.paths.append(path)
                else:                              # an earlier run's: written again, or stale
                    path.unlink()
        if "pc2" in formats:
            for body in self.bodies:
                rest = self.folder / f"{name}_{body.name}_rest.obj"
                _write_mesh(rest, cloth.particle_position[body.points], body.triangles, (),
                            body.uvs)
                self.paths.append(rest)
        streams = set(STREAMS) & set(formats)
        self._journal = None
        if streams:
            if "usd" in streams:
                _UsdStage.check_available()
            record = [("time", "<f8"), ("positions", backend.numpy_real(), (len(self._shown), 3))]
            if "npz" in streams:
                record.append(("velocities", backend.numpy_real(), (len(self._shown), 3)))
            if "usd" in streams and cloth.mesh.triangle_count:
                record.append(("torn", "u1", (cloth.mesh.triangle_count,)))
            self._journal = _Journal(self.folder / f".{name}.journal", np.dtype(record),
                                     first_frame)

    def __enter__(self) -> Exporter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def write(self, sim) -> list[Path]:
        """Write the simulation's current state as the next frame; returns the files written."""
        x = sim.positions()
        written = []
        torn = np.zeros(self.cloth.mesh.triangle_count, bool)
        torn[sim.torn_triangles()] = True
        alive = sim.spring_alive()
        for body in self.bodies:
            for ext in ("obj", "ply"):
                if ext in self.formats:
                    path = self.folder / f"{self.name}_{body.name}_{self.frames:05d}.{ext}"
                    _write_mesh(path, x[body.points], body.triangles[~torn[body.triangle_index]],
                                body.segments[alive[body.segment_index]] if ext == "ply" else (),
                                body.uvs)
                    written.append(path)
        if self._journal is not None:
            record = np.zeros((), self._journal.dtype)
            record["time"] = sim.time
            record["positions"] = x[self._shown]
            if "velocities" in record.dtype.names:
                record["velocities"] = sim.velocities()[self._shown]
            if "torn" in record.dtype.names:
                record["torn"] = torn
            self._journal.append(record)
        self.frames += 1
        self.paths += written
        return written

    def close(self, keep_journal: bool = False) -> list[Path]:
        """Assemble the PC2 caches, the npz and the USD stage from the frames written (this
        run's and, resumed, the earlier ones); returns every file of the run. The journal is
        deleted, unless `keep_journal` (a stopped run that may be resumed)."""
        if self._journal is None:
            return self.paths
        records = self._journal.records()
        if len(records):
            self.paths += self._assemble(records)
        del records                              # the mapping, before the file goes
        self._journal.close(remove=not keep_journal)
        self._journal = None
        return self.paths

    def _assemble(self, records) -> list[Path]:
        """The PC2 caches, npz and USD stage of the journal's records."""
        paths = []
        if "pc2" in self.formats:
            for body, points in zip(self.bodies, self._slices):
                paths.append(_write_pc2(self.folder / f"{self.name}_{body.name}.pc2",
                                        records["positions"][:, points]))
        if "npz" in self.formats:
            paths.append(self._write_npz(records))
        if "usd" in self.formats:
            stage = _UsdStage(self.usd_path, self.name, self.bodies, self.fps)
            no_tears = np.zeros(self.cloth.mesh.triangle_count, bool)
            for frame, record in enumerate(records):
                torn = record["torn"] if "torn" in records.dtype.names else no_tears
                for body, points in zip(self.bodies, self._slices):
                    stage.add(body, frame, record["positions"][points],
                              torn[body.triangle_index].astype(bool))
            for index, collider in enumerate(self.colliders):
                stage.add_collider(index, collider, records["time"])
            paths.append(stage.save(len(records)))
        return paths

    def _write_npz(self, records) -> Path:
        path = self.folder / f"{self.name}.npz"
        with atomic_path(path) as tmp:
            np.savez(tmp, positions=records["positions"].astype(np.float64),
                     velocities=records["velocities"].astype(np.float64),
                     time=np.array(records["time"]), particle=self._shown,
                     body=np.concatenate([np.full(len(body.points), b)
                                          for b, body in enumerate(self.bodies)]))
        return path


class _Journal:
    """Records of a fixed numpy dtype, one per frame, appended unbuffered to `path` after a
    header naming the dtype. Opened at `first` > 0 it keeps the first `first` records of the
    file there (StateMismatch if it holds fewer or another dtype) and appends after them."""

    def __init__(self, path: Path, dtype: np.dtype, first: int):
        self.path, self.dtype = path, dtype
        layout = json.dumps(dtype.descr).encode()
        header = JOURNAL_MAGIC + struct.pack("<I", len(layout)) + layout
        self.start = len(header)
        if first == 0:
            self.file = open(path, "wb", buffering=0)
            self.file.write(header)
            return
        if not path.is_file():
            raise StateMismatch(f"no export journal {path} to resume from: the earlier frames' "
                                "PC2 / npz / USD data is gone; run again without resuming")
        self.file = open(path, "r+b", buffering=0)
        if self.file.read(len(header)) != header:
            self.file.close()
            raise StateMismatch(f"the export journal {path} was written for other formats or "
                                "bodies; run again without resuming")
        held = (path.stat().st_size - self.start) // dtype.itemsize
        if held < first:
            self.file.close()
            raise StateMismatch(f"the export journal {path} holds {held} frames, the saved "
                                f"state needs {first}; run again without resuming")
        self.file.truncate(self.start + first * dtype.itemsize)
        self.file.seek(0, 2)

    def append(self, record: np.ndarray) -> None:
        self.file.write(record.tobytes())

    def records(self) -> np.ndarray:
        """Every record in the file, in order (mapped, not read into memory)."""
        if self.path.stat().st_size <= self.start:
            return np.zeros(0, self.dtype)
        return np.memmap(self.path, self.dtype, mode="r", offset=self.start)

    def close(self, remove: bool) -> None:
        self.file.close()
        if remove:
            self.path.unlink(missing_ok=True)


class _Body:
    """One body of a Cloth as exported: its shown (non-ghost) particles, its triangles and its
    stretch springs renumbered to them, and which of the Cloth's triangles / springs they are."""

    def __init__(self, cloth, b: int):
        self.name = f"body{b}"
        self.points = np.flatnonzero(~cloth.ghost & (cloth.particle_body == b))
        local = np.full(cloth.particle_count, -1, np.int64)
        local[self.points] = np.arange(len(self.points))
        triangles = cloth.mesh.triangles
        self.triangle_index = np.flatnonzero(np.all(local[triangles] >= 0, axis=1))
        self.triangles = local[triangles[self.triangle_index]]
        springs = cloth.spring_indices
        mine = np.all(local[springs] >= 0, axis=1) & (cloth.spring_kind == SpringKind.STRETCH)
        self.segment_index = np.flatnonzero(mine) if not len(self.triangle_index) else np.zeros(0, int)
        self.segments = local[springs[self.segment_index]]
        self.uvs = texture_coordinates(cloth.mesh)[self.points] if len(self.triangles) else None


def texture_coordinates(mesh) -> np.ndarray:
    """(N, 2) uvs of a mesh: its own, or a grid's (u = column / (cols - 1), v = row /
    (rows - 1)), else the rest positions projected onto their two widest axes, over the
    wider extent (a mesh file without uvs, a joined Cloth)."""
    if mesh.uvs is not None:
        return mesh.uvs
    if mesh.grid_shape is not None:
        rows, cols = mesh.grid_shape
        r, c = np.divmod(np.arange(mesh.vertex_count), cols)
        return np.stack([c / max(cols - 1, 1), r / max(rows - 1, 1)], axis=1)
    x = mesh.vertices
    extent = x.max(axis=0) - x.min(axis=0)
    axes = np.sort(np.argsort(extent)[1:])
    return (x[:, axes] - x[:, axes].min(axis=0)) / max(float(extent.max()), 1e-300)


def vertex_normals(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(N, 3) unit area-weighted vertex normals of a triangle mesh (0 at a point no
    triangle touches), the triangles' corners summed in triangle order."""
    a, b, c = (points[triangles[:, k]] for k in range(3))
    face = np.cross(b - a, c - a)
    normals = np.zeros_like(points, dtype=np.float64)
    for k in range(3):
        np.add.at(normals, triangles[:, k], face)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)


def _write_mesh(path: Path, points: np.ndarray, triangles: np.ndarray, segments,
                uvs: np.ndarray | None = None) -> None:
    """An OBJ / PLY of `points` with `triangles`, (PLY) line `segments` and, for a sheet
    (uvs given), texture coordinates and vertex normals, atomically. The time meshio stamps in
    its header comment is taken out: the same frame gives the same bytes (a resumed run's
    files equal those of a run never stopped)."""
    import meshio

    points = np.asarray(points, np.float64)
    normals = None if uvs is None else vertex_normals(points, np.asarray(triangles, np.int64))
    if path.suffix == ".obj":
        with atomic_path(path) as tmp:
            _write_obj(tmp, points, triangles, uvs, normals)
        return
    cells = []
    if len(triangles):
        cells.append(("triangle", np.asarray(triangles, np.int32)))
    if len(segments):
        cells.append(("line", np.asarray(segments, np.int32)))
    data = {}
    if uvs is not None:
        data = {"nx": normals[:, 0], "ny": normals[:, 1], "nz": normals[:, 2],
                "s": np.asarray(uvs[:, 0], np.float64), "t": np.asarray(uvs[:, 1], np.float64)}
    with atomic_path(path) as tmp:
        meshio.write_points_cells(tmp, points, cells, point_data=data)
        with open(tmp, "r+b") as file:
            head = file.read(HEADER_BYTES)
            stamp = MESHIO_STAMP.search(head)
            if stamp:
                rest = file.read()
                file.seek(stamp.start(1))
                file.write(head[stamp.end(1):] + rest)
                file.truncate()


def _write_obj(path: Path, points: np.ndarray, triangles, uvs, normals) -> None:
    """Wavefront OBJ: `v` per point, with a sheet's `vt` and `vn` (one per point) and faces
    `f i/i/i` naming them; numbers in Python's shortest round-trip form (the same frame gives
    the same bytes)."""
    lines = ["# ti_cloth"]
    lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in points.tolist()]
    if uvs is not None:
        lines += [f"vt {u!r} {v!r}" for u, v in np.asarray(uvs, np.float64).tolist()]
        lines += [f"vn {x!r} {y!r} {z!r}" for x, y, z in normals.tolist()]
        lines += [f"f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}"
                  for a, b, c in (np.asarray(triangles, np.int64) + 1).tolist()]
    else:
        lines += [f"f {a} {b} {c}" for a, b, c in (np.asarray(triangles, np.int64) + 1).tolist()]
    Path(path).write_text("\n".join(lines) + "\n")


def _write_pc2(path: Path, positions: np.ndarray) -> Path:
    """A PC2 point cache of positions (samples, points, 3), one sample per frame, atomically."""
    samples, points = positions.shape[:2]
    with atomic_path(path) as tmp, open(tmp, "wb") as file:
        file.write(PC2_HEADER.pack(b"POINTCACHE2\0", 1, points, 0.0, 1.0, samples))
        file.write(np.ascontiguousarray(positions, "<f4").tobytes())
    return path


class _UsdStage:
    """One USD stage in memory, a prim per body, time samples added frame by frame; saved
    (atomically) by save()."""

    @staticmethod
    def check_available() -> None:
        """ImportError, saying how to install it, without usd-core."""
        try:
            import pxr  # noqa: F401
        except ImportError as err:
            raise ImportError("USD export needs Pixar's usd-core: pip install 'ti_cloth[usd]'") from err

    def __init__(self, path: Path, name: str, bodies, fps: float):
        from pxr import Sdf, Usd, UsdGeom

        self.path, self.UsdGeom, self.Sdf = path, UsdGeom, Sdf
        self.stage = Usd.Stage.CreateInMemory()
        self.stage.SetTimeCodesPerSecond(fps)
        self.stage.SetFramesPerSecond(fps)
        self.stage.SetStartTimeCode(0)
        UsdGeom.SetStageUpAxis(self.stage, UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(self.stage, 1.0)
        root = "/" + (Sdf.Path.IsValidIdentifier(name) and name or "scene")
        self.root = root
        self.stage.SetDefaultPrim(UsdGeom.Xform.Define(self.stage, root).GetPrim())
        self.prims, self.torn_before = {}, {}
        for body in bodies:
            prim_path = f"{root}/{body.name}"
            if len(body.triangles):
                mesh = UsdGeom.Mesh.Define(self.stage, prim_path)
                mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
                mesh.CreateDoubleSidedAttr(True)
                self._faces(mesh, body.triangles, None)
                st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
                    "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
                st.Set(np.asarray(body.uvs, np.float32))
                mesh.CreateNormalsAttr()
                mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
            else:
                mesh = UsdGeom.BasisCurves.Define(self.stage, prim_path)
                mesh.CreateTypeAttr(UsdGeom.Tokens.linear)
                mesh.CreateCurveVertexCountsAttr([2] * len(body.segments))
                mesh.CreateWidthsAttr([0.002])
                mesh.SetWidthsInterpolation(UsdGeom.Tokens.constant)
            self.prims[body.name] = mesh
            self.torn_before[body.name] = np.zeros(len(body.triangle_index), bool)

    def _faces(self, mesh, triangles: np.ndarray, time) -> None:
        counts = [3] * len(triangles)
        indices = np.asarray(triangles, np.int32).ravel().tolist()
        if time is None:
            mesh.CreateFaceVertexCountsAttr(counts)
            mesh.CreateFaceVertexIndicesAttr(indices)
        else:
            mesh.GetFaceVertexCountsAttr().Set(counts, time)
            mesh.GetFaceVertexIndicesAttr().Set(indices, time)

    def add(self, body, frame: int, points: np.ndarray, torn: np.ndarray) -> None:
        """The body's points (and, when its torn triangles changed, its faces) at `frame`."""
        from pxr import Vt

        prim = self.prims[body.name]
        if len(body.triangles):
            if (torn != self.torn_before[body.name]).any():
                if not self.torn_before[body.name].any():      # the intact faces until now
                    self._faces(prim, body.triangles, 0)
                self._faces(prim, body.triangles[~torn], frame)
                self.torn_before[body.name] = torn.copy()
            positions = points
            normals = vertex_normals(np.asarray(points, np.float64), body.triangles[~torn])
            prim.GetNormalsAttr().Set(Vt.Vec3fArray.FromNumpy(normals.astype(np.float32)), frame)
        else:
            positions = points[body.segments.ravel()]          # two points per segment
        prim.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(np.array(positions, np.float32)),
                                 frame)

    PLANE_SIZE = 20.0       # m: the side of the square an infinite collider plane is written as

    def add_collider(self, index: int, collider, times: np.ndarray) -> None:
        """Collider `index` (of contact.colliders) at the frames' times [s], told apart by
        what it holds: a `mesh`, a plane's normal, a sphere's centre, a box's lo and hi, or a
        capsule's a and b."""
        from pxr import Gf, Vt

        UsdGeom = self.UsdGeom
        path = f"{self.root}/colliders/collider{index}"
        placed = [collider.placed(float(t)) for t in times]
        first = placed[0]
        moving = any(p is not collider for p in placed)
        if hasattr(first, "mesh") or hasattr(first, "normal"):
            mesh = UsdGeom.Mesh.Define(self.stage, path)
            mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
            if hasattr(first, "normal"):          # a square of PLANE_SIZE (Blender reads no Plane)
                mesh.CreateDoubleSidedAttr(True)
                self._faces(mesh, np.array([[0, 1, 2], [0, 2, 3]]), None)
            else:
                self._faces(mesh, first.mesh.triangles, None)
            points = mesh.CreatePointsAttr()
            for frame, shape in enumerate(placed if moving else placed[:1]):
                vertices = (self._square(shape) if hasattr(shape, "normal")
                            else shape.mesh.vertices)
                points.Set(Vt.Vec3fArray.FromNumpy(vertices.astype(np.float32)),
                           frame if moving else _unvarying())
            return
        if hasattr(first, "centre"):
            prim = UsdGeom.Sphere.Define(self.stage, path)
            prim.CreateRadiusAttr(first.radius)
            where = lambda shape: np.asarray(shape.centre)            # noqa: E731
        elif hasattr(first, "lo"):
            prim = UsdGeom.Cube.Define(self.stage, path)
            prim.CreateSizeAttr(1.0)
            where = lambda shape: 0.5 * (np.asarray(shape.lo) + np.asarray(shape.hi))  # noqa: E731
        else:
            prim = UsdGeom.Capsule.Define(self.stage, path)
            axis = np.subtract(first.b, first.a)
            prim.CreateAxisAttr(UsdGeom.Tokens.y)
            prim.CreateHeightAttr(float(np.linalg.norm(axis)))
            prim.CreateRadiusAttr(first.radius)
            where = lambda shape: 0.5 * (np.asarray(shape.a) + np.asarray(shape.b))  # noqa: E731
        translate = prim.AddTranslateOp()
        if hasattr(first, "lo"):
            prim.AddScaleOp().Set(Gf.Vec3f(*np.subtract(first.hi, first.lo).tolist()))
        if hasattr(first, "a"):                                 # +Y turned onto the axis
            prim.AddOrientOp().Set(_quaternion_from_y(axis))
        for frame, shape in enumerate(placed if moving else placed[:1]):
            translate.Set(Gf.Vec3d(*where(shape).tolist()), frame if moving else _unvarying())

    def _square(self, plane) -> np.ndarray:
        """The corners (4, 3) of a PLANE_SIZE square of `plane` round its point, counter-
        clockwise seen from the side its normal points to."""
        n = np.asarray(plane.normal, np.float64)
        u = np.cross(n, np.eye(3)[np.argmin(np.abs(n))])
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        half = 0.5 * self.PLANE_SIZE
        return np.asarray(plane.point) + half * np.array([-u - v, u - v, u + v, -u + v])

    def save(self, frames: int) -> Path:
        self.stage.SetEndTimeCode(max(frames - 1, 0))
        with atomic_path(self.path) as tmp:
            self.stage.Export(str(tmp))
        return self.path


def _unvarying():
    """USD's default time code: an attribute's value that does not change over time."""
    from pxr import Usd
    return Usd.TimeCode.Default()


def _quaternion_from_y(axis: np.ndarray):
    """The unit quaternion (a Gf.Quatf) turning +Y onto `axis` by the shortest arc."""
    from pxr import Gf

    axis = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    y = np.array([0.0, 1.0, 0.0])
    cross, cosine = np.cross(y, axis), float(y @ axis)
    if cosine < -1.0 + 1e-12:                   # straight down: half a turn about x
        return Gf.Quatf(0.0, 1.0, 0.0, 0.0)
    w = 1.0 + cosine
    q = np.array([w, *cross]) / np.linalg.norm([w, *cross])
    return Gf.Quatf(float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def read_pc2(path) -> tuple[dict, np.ndarray]:
    """(header {"points", "start", "rate", "samples"}, points (samples, points, 3) float32) of a
    PC2 file."""
    data = Path(path).read_bytes()
    magic, version, points, start, rate, samples = PC2_HEADER.unpack_from(data)
    require(magic == b"POINTCACHE2\0" and version == 1, "PC2 header", magic, "POINTCACHE2, version 1")
    body = np.frombuffer(data, "<f4", offset=PC2_HEADER.size, count=samples * points * 3)
    return ({"points": points, "start": start, "rate": rate, "samples": samples},
            body.reshape(samples, points, 3))
