"""Deforming meshes from files, for AnimatedMeshCollider.load: what Blender, Houdini or a
script hands over for a moving character.

    npz            `triangles` (T, 3), `positions` (samples, V, 3) [m], `fps` (optional)
    PC2 + rest     a point cache (Blender's, ours: export.py) and the mesh file it deforms
    OBJ sequence   "walk_*.obj": one file per sample, ordered by the number in the name
    USD            a Mesh prim's time-sampled points, in world space, at every time code
                   (metres; a z-up stage, as Blender writes, turned to ti_cloth's y up)

Every sample must give a position for each vertex of the first (or rest) mesh; a file that
cannot be read is a ValueError naming it and what is wrong.
"""

from __future__ import annotations

import re
import struct
import zipfile
from pathlib import Path

import numpy as np

from ...body.mesh import Mesh, load_mesh
from ...export import read_pc2
from ...inputs import limits
from ...inputs.validation import in_range, require

USD_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")


def read_animation(path, rest=None, fps: float | None = None, prim: str | None = None
                   ) -> tuple[Mesh, np.ndarray, float]:
    """(the mesh at its first sample, its positions (samples, V, 3) [m], samples per second)
    of an animation file. rest: the mesh file a PC2 cache deforms. prim: the USD Mesh prim
    (needed when a stage holds several animated meshes). fps: frames per second of the
    animation; required for a PC2 cache (which counts frames, not seconds: one sample every
    `sample rate` frames of its header) and an OBJ sequence (a sample per frame); given for
    an npz or a USD stage, it replaces the rate the file states."""
    text = str(path)
    if fps is not None:
        fps = in_range("fps", fps, limits.FPS)
    if "*" in Path(text).name:
        require(rest is None and prim is None, "rest" if rest is not None else "prim",
                rest if rest is not None else prim, "not given with an OBJ sequence")
        mesh, samples = _obj_sequence(Path(text))
        return mesh, samples, _needed(fps, "an OBJ sequence (a sample per frame)")
    path = Path(text)
    require(path.is_file(), "path", text, "an existing animation file (npz, pc2 with its rest "
            "mesh, a 'name_*.obj' sequence, or USD)")
    suffix = path.suffix.lower()
    require(rest is None or suffix == ".pc2", "rest", rest, "given only with a PC2 cache")
    require(prim is None or suffix in USD_SUFFIXES, "prim", prim, "given only with a USD stage")
    if suffix == ".pc2":
        require(rest is not None, "rest", rest, "the mesh file the PC2 cache deforms (its "
                "triangles and vertex order)")
        mesh, samples, frames_per_sample = _pc2(path, Path(rest))
        fps = _needed(fps, "a PC2 cache (it counts frames, not seconds)")
        return mesh, samples, in_range(f"{path.name}: samples per second", fps /
                                       frames_per_sample, limits.FPS)
    if suffix == ".npz":
        mesh, samples, stated = _npz(path)
    elif suffix in USD_SUFFIXES:
        mesh, samples, stated = _usd(path, prim)
    else:
        raise ValueError(f"path: {text!r} is not an animation file this reads: npz, pc2, a "
                         f"'name_*.obj' sequence or USD ({', '.join(USD_SUFFIXES)})")
    if fps is None:
        fps = in_range(f"{path.name}: fps", _needed(stated, f"{path.name}, which states no "
                                                    "rate"), limits.FPS)
    return mesh, samples, fps


def _needed(fps: float | None, what: str) -> float:
    require(fps is not None, "fps", None, f"the animation's frames per second, for {what}")
    return fps


def _real(name: str, values: np.ndarray) -> np.ndarray:
    """`values` as float64 when they are real numbers (not complex, text or objects)."""
    require(values.dtype != bool and (np.issubdtype(values.dtype, np.floating)
                                      or np.issubdtype(values.dtype, np.integer)),
            name, f"an array of {values.dtype}", "real numbers (float or integer positions)")
    return values.astype(np.float64)


def _checked(name: str, samples: np.ndarray, vertices: int) -> np.ndarray:
    require(samples.ndim == 3 and samples.shape[1:] == (vertices, 3), name,
            f"positions of shape {samples.shape}",
            f"positions (samples, {vertices}, 3) for the rest mesh's {vertices} vertices")
    return _real(name, samples)


def _npz(path: Path):
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = {"triangles", "positions"} - set(data.files)
            require(not missing, f"{path.name}", sorted(data.files),
                    "an npz holding 'triangles' (T, 3) and 'positions' (samples, V, 3) "
                    f"(missing: {', '.join(sorted(missing))})")
            stored = data.zip.getinfo("positions.npy").file_size     # before reading it
            require(stored <= 8 * limits.MOTION_VALUES + 1024, f"{path.name}: positions",
                    f"{stored:,} bytes", f"at most {limits.MOTION_VALUES:,} numbers")
            positions = data["positions"]
            triangles, fps = data["triangles"], data["fps"] if "fps" in data.files else None
    except (OSError, zipfile.BadZipFile, EOFError) as err:
        raise ValueError(f"path: {path} is not a readable npz file ({err})") from None
    require(positions.ndim == 3 and positions.shape[0] > 0, f"{path.name}: positions",
            f"an array of shape {positions.shape}", "(samples, V, 3), at least one sample")
    mesh = Mesh(_real(f"{path.name}: positions", positions[0]), triangles)
    if fps is not None:
        require(fps.shape == () and np.issubdtype(fps.dtype, np.number), f"{path.name}: fps",
                fps, "one number of samples per second")
        fps = float(fps)
    return mesh, _checked(f"{path.name}: positions", positions, mesh.vertex_count), fps


def _pc2(path: Path, rest: Path):
    require(rest.is_file(), "rest", str(rest), "an existing mesh file (OBJ, PLY, ...)")
    mesh = load_mesh(rest)
    size = path.stat().st_size
    require(size <= 4 * limits.MOTION_VALUES + 64, f"{path.name}", f"{size:,} bytes",
            f"a cache of at most {limits.MOTION_VALUES:,} numbers")
    try:
        header, points = read_pc2(path)
    except (ValueError, struct.error) as err:     # a bad header, a truncated body
        raise ValueError(f"path: {path} is not a readable PC2 cache ({err})") from None
    require(header["points"] == mesh.vertex_count, f"{path.name}: points", header["points"],
            f"{mesh.vertex_count}, the vertex count of the rest mesh {rest.name}")
    samples = _checked(f"{path.name}", points, mesh.vertex_count)
    require(samples.shape[0] > 0, f"{path.name}: samples", 0, "at least one sample")
    rate = header["rate"]
    require(np.isfinite(rate) and rate > 0, f"{path.name}: sample rate", rate,
            "frames between samples, > 0")
    return Mesh(samples[0], mesh.triangles), samples, float(rate)


def _frame_number(path: Path) -> int:
    numbers = re.findall(r"\d+", path.stem)
    return int(numbers[-1]) if numbers else -1


def _obj_sequence(pattern: Path):
    files = sorted(pattern.parent.glob(pattern.name), key=lambda p: (_frame_number(p), p.name))
    require(len(files) > 0, "path", str(pattern), "a pattern matching at least one mesh file")
    meshes = []
    for file in files:
        mesh = load_mesh(file)
        if meshes:
            require(mesh.vertex_count == meshes[0].vertex_count, f"{file.name}: vertices",
                    mesh.vertex_count, f"{meshes[0].vertex_count}, as in {files[0].name}")
            require(np.array_equal(mesh.triangles, meshes[0].triangles),
                    f"{file.name}: triangles", "a different triangle list",
                    f"the triangles of {files[0].name} (a sequence keeps its topology)")
        meshes.append(mesh)
        require(len(meshes) * mesh.vertex_count * 3 <= limits.MOTION_VALUES, "path", str(pattern),
                f"a sequence of at most {limits.MOTION_VALUES} numbers")
    return meshes[0], np.stack([m.vertices for m in meshes])


def _usd(path: Path, prim_path: str | None):
    try:
        from pxr import Usd, UsdGeom
    except ImportError as err:
        raise ImportError("reading USD needs Pixar's usd-core: pip install 'ti_cloth[usd]'") \
            from err
    from pxr import Tf
    try:
        stage = Usd.Stage.Open(str(path))
    except Tf.ErrorException as err:       # a layer that does not parse
        where = re.search(re.escape(path.name) + r":(\d+):(\d+): (.*?)(?: in </>|'\n|$)",
                          str(err), re.S)
        reason = (f"line {where[1]}, column {where[2]}: {' '.join(where[3].split())}" if where
                  else "usd-core cannot parse it")
        raise ValueError(f"path must be a USD stage usd-core can open, got {str(path)!r} "
                         f"({reason})") from None
    require(stage is not None, "path", str(path), "a USD stage usd-core can open")
    meshes = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    if prim_path is not None:
        chosen = [p for p in meshes if str(p.GetPath()) == prim_path]
        require(chosen, "prim", prim_path,
                f"a Mesh prim of {path.name}: {[str(p.GetPath()) for p in meshes]}")
    else:
        moving = [p for p in meshes if UsdGeom.Mesh(p).GetPointsAttr().GetNumTimeSamples() > 1]
        chosen = moving or meshes
        require(len(chosen) == 1, "prim", None, f"the path of the Mesh prim to read, one of "
                f"{[str(p.GetPath()) for p in chosen]} ({path.name} holds "
                f"{len(chosen)} {'animated ' if moving else ''}meshes)")
    mesh = UsdGeom.Mesh(chosen[0])
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(0), np.int64)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(0), np.int64)
    require(len(counts) > 0 and (counts >= 3).all() and counts.sum() == len(indices),
            f"{chosen[0].GetPath()}: faces", f"{len(counts)} faces",
            "polygons of at least 3 vertices")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    triangles = np.array([(indices[s], indices[s + k], indices[s + k + 1])
                          for s, n in zip(starts, counts) for k in range(1, n - 1)])
    times = mesh.GetPointsAttr().GetTimeSamples() or [Usd.TimeCode.Default().GetValue()]
    first, last = min(times), max(times)
    codes = first + np.arange(int(np.floor(last - first)) + 1)
    vertices = len(mesh.GetPointsAttr().Get(codes[0]))
    require(len(codes) * vertices * 3 <= limits.MOTION_VALUES, "path", str(path),
            f"an animation of at most {limits.MOTION_VALUES} numbers")
    metres = UsdGeom.GetStageMetersPerUnit(stage)
    samples = []
    for code in codes:
        world = np.array(UsdGeom.XformCache(code).GetLocalToWorldTransform(chosen[0]))
        points = np.asarray(mesh.GetPointsAttr().Get(code), np.float64)
        require(points.shape == (vertices, 3), f"{chosen[0].GetPath()}: points at {code:g}",
                f"{len(points)} points", f"{vertices}, as at the first time code")
        samples.append((points @ world[:3, :3] + world[3, :3]) * metres)
    samples = np.stack(samples)
    if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z:     # Blender's default
        samples = samples[..., [0, 2, 1]] * (1.0, 1.0, -1.0)  # z up -> y up, x kept
    return Mesh(samples[0], triangles), samples, float(stage.GetTimeCodesPerSecond())
