"""Geometry out of a run, frame by frame, for Blender, Houdini, Omniverse and numpy: OBJ / PLY
files per frame and body (through meshio), a PC2 point cache per body with its rest-pose OBJ
(Blender's Mesh Cache modifier), one USD stage (Pixar's usd-core, the optional extra `[usd]`)
and an npz of positions and velocities.

    with tc.Exporter("out", ["obj", "pc2"], name="drape", fps=30, cloth=cloth) as export:
        for frame in range(frames):
            export.write(sim)              # frame 0 first: the state as it is now
            sim.step(substeps)

Only what a body shows is written: ghost particles (hair) never are, and a torn triangle
leaves the frame's OBJ / PLY from the frame it tore in (a PC2 cache keeps the rest topology).
Bodies without triangles (strings, hair) are written as line segments (their stretch
springs) in PLY, as points in OBJ (meshio's OBJ has no lines) and in full in the PC2 and npz.
Every file is written under a temporary name and renamed, so a run stopped by Ctrl-C, SIGTERM
or a divergence keeps every finished frame, and its PC2 caches hold those frames.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from ._validate import finite_number, require
from .files import atomic_path, temporary_name
from .material import SpringKind

FORMATS = ("obj", "ply", "pc2", "npz", "usd")
PC2_HEADER = struct.Struct("<12siiffi")   # "POINTCACHE2\0", version 1, points, start, rate, samples


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
    Bodies are named body0, body1, ... in the order the Cloth joined them."""

    def __init__(self, folder, formats, *, name: str, cloth, fps: float,
                 usd_suffix: str = ".usdc"):
        formats = [formats] if isinstance(formats, str) else list(formats)
        for f in formats:
            require(f in FORMATS, "export format", f, f"one of {FORMATS}")
        require(usd_suffix in (".usdc", ".usda"), "usd_suffix", usd_suffix, '".usdc" or ".usda"')
        self.folder, self.formats, self.name = Path(folder), formats, name
        self.fps = finite_number("fps", fps, 0.0, strict=True, unit="frames/s")
        self.cloth = cloth
        self.bodies = [_Body(cloth, b) for b in range(len(cloth.body_offsets) - 1)]
        self._shown = np.concatenate([body.points for body in self.bodies])   # npz order
        self.frames = 0
        self.paths: list[Path] = []
        self.folder.mkdir(parents=True, exist_ok=True)
        for ext in {"obj", "ply"} & set(formats):      # frames of an earlier, longer run
            for stale in self.folder.glob(f"{name}_body*_[0-9][0-9][0-9][0-9][0-9].{ext}"):
                stale.unlink()
        self._caches = {}
        self._samples = {"positions": [], "velocities": [], "time": []}
        if "pc2" in formats:
            for body in self.bodies:
                rest = self.folder / f"{name}_{body.name}_rest.obj"
                _write_mesh(rest, cloth.particle_position[body.points], body.triangles, ())
                self.paths.append(rest)
                self._caches[body.name] = _PointCache(self.folder / f"{name}_{body.name}.pc2",
                                                      len(body.points))
        self._stage = (_UsdStage(self.folder / f"{name}{usd_suffix}", name, self.bodies, self.fps)
                       if "usd" in formats else None)

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
                                body.segments[alive[body.segment_index]] if ext == "ply" else ())
                    written.append(path)
            if "pc2" in self.formats:
                self._caches[body.name].append(x[body.points])
            if self._stage is not None:
                self._stage.add(body, self.frames, x[body.points], torn[body.triangle_index])
        if "npz" in self.formats:
            self._samples["positions"].append(x[self._shown])
            self._samples["velocities"].append(sim.velocities()[self._shown])
            self._samples["time"].append(sim.time)
        self.frames += 1
        self.paths += written
        return written

    def close(self) -> list[Path]:
        """Finish the PC2 caches, write the USD stage and the npz; returns every file this
        exporter wrote."""
        for cache in self._caches.values():
            self.paths.append(cache.close())
        self._caches = {}
        if self._stage is not None:
            self.paths.append(self._stage.save(self.frames))
            self._stage = None
        if "npz" in self.formats and self._samples["time"]:
            path = self.folder / f"{self.name}.npz"
            with atomic_path(path) as tmp:
                np.savez(tmp, positions=np.stack(self._samples["positions"]),
                         velocities=np.stack(self._samples["velocities"]),
                         time=np.asarray(self._samples["time"]), particle=self._shown,
                         body=np.concatenate([np.full(len(body.points), b)
                                              for b, body in enumerate(self.bodies)]))
            self.paths.append(path)
            self._samples = {key: [] for key in self._samples}
        return self.paths


class _Body:
    """One body of a Cloth as exported: its shown (non-ghost) particles, its triangles and its
    stretch springs renumbered to them, and which of the Cloth's triangles / springs they are."""

    def __init__(self, cloth, b: int):
        lo, hi = cloth.body_offsets[b], cloth.body_offsets[b + 1]
        self.name = f"body{b}"
        self.points = np.flatnonzero(~cloth.ghost[lo:hi]) + lo
        local = np.full(cloth.particle_count, -1, np.int64)
        local[self.points] = np.arange(len(self.points))
        triangles = cloth.mesh.triangles
        self.triangle_index = np.flatnonzero(np.all((triangles >= lo) & (triangles < hi), axis=1)
                                             & np.all(local[triangles] >= 0, axis=1))
        self.triangles = local[triangles[self.triangle_index]]
        springs = cloth.spring_indices
        mine = (np.all(local[springs] >= 0, axis=1) & np.all((springs >= lo) & (springs < hi), axis=1)
                & (cloth.spring_kind == SpringKind.STRETCH))
        self.segment_index = np.flatnonzero(mine) if not len(self.triangle_index) else np.zeros(0, int)
        self.segments = local[springs[self.segment_index]]


def _write_mesh(path: Path, points: np.ndarray, triangles: np.ndarray, segments) -> None:
    """An OBJ / PLY of `points` with `triangles` and (PLY) line `segments`, atomically."""
    import meshio

    cells = []
    if len(triangles):
        cells.append(("triangle", np.asarray(triangles, np.int32)))
    if len(segments):
        cells.append(("line", np.asarray(segments, np.int32)))
    with atomic_path(path) as tmp:
        meshio.write_points_cells(tmp, np.asarray(points, np.float64), cells)


class _PointCache:
    """A PC2 file written as frames come, under a temporary name; close() sets the sample count
    in the header and renames it."""

    def __init__(self, path: Path, points: int):
        self.path, self.points, self.samples = path, points, 0
        self.tmp = temporary_name(path)
        self.file = open(self.tmp, "wb")
        self.file.write(PC2_HEADER.pack(b"POINTCACHE2\0", 1, points, 0.0, 1.0, 0))

    def append(self, positions: np.ndarray) -> None:
        self.file.write(np.ascontiguousarray(positions, "<f4").tobytes())
        self.samples += 1

    def close(self) -> Path:
        self.file.seek(0)
        self.file.write(PC2_HEADER.pack(b"POINTCACHE2\0", 1, self.points, 0.0, 1.0, self.samples))
        self.file.close()
        self.tmp.replace(self.path)
        return self.path


class _UsdStage:
    """One USD stage in memory, a prim per body, time samples added frame by frame; saved
    (atomically) by save()."""

    def __init__(self, path: Path, name: str, bodies, fps: float):
        try:
            from pxr import Sdf, Usd, UsdGeom
        except ImportError as err:
            raise ImportError("USD export needs Pixar's usd-core: pip install 'ti_cloth[usd]'") from err
        self.path, self.UsdGeom, self.Sdf = path, UsdGeom, Sdf
        self.stage = Usd.Stage.CreateInMemory()
        self.stage.SetTimeCodesPerSecond(fps)
        self.stage.SetFramesPerSecond(fps)
        self.stage.SetStartTimeCode(0)
        UsdGeom.SetStageUpAxis(self.stage, UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(self.stage, 1.0)
        root = "/" + (Sdf.Path.IsValidIdentifier(name) and name or "scene")
        self.stage.SetDefaultPrim(UsdGeom.Xform.Define(self.stage, root).GetPrim())
        self.prims, self.torn_before = {}, {}
        for body in bodies:
            prim_path = f"{root}/{body.name}"
            if len(body.triangles):
                mesh = UsdGeom.Mesh.Define(self.stage, prim_path)
                mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
                mesh.CreateDoubleSidedAttr(True)
                self._faces(mesh, body.triangles, None)
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
        else:
            positions = points[body.segments.ravel()]          # two points per segment
        prim.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(np.asarray(positions, np.float32)),
                                 frame)

    def save(self, frames: int) -> Path:
        self.stage.SetEndTimeCode(max(frames - 1, 0))
        with atomic_path(self.path) as tmp:
            self.stage.Export(str(tmp))
        return self.path


def read_pc2(path) -> tuple[dict, np.ndarray]:
    """(header {"points", "start", "rate", "samples"}, points (samples, points, 3) float32) of a
    PC2 file."""
    data = Path(path).read_bytes()
    magic, version, points, start, rate, samples = PC2_HEADER.unpack_from(data)
    require(magic == b"POINTCACHE2\0" and version == 1, "PC2 header", magic, "POINTCACHE2, version 1")
    body = np.frombuffer(data, "<f4", offset=PC2_HEADER.size, count=samples * points * 3)
    return ({"points": points, "start": start, "rate": rate, "samples": samples},
            body.reshape(samples, points, 3))
