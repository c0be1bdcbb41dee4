"""Scene files: a TOML description of bodies, forces, colliders, integrator, camera and output,
read strictly (scene_file.Table) into a Scene that builds a Simulation. Only what a scene lists
is built, so only that is compiled. The keys, units and defaults are listed in the README's
"Scene files" section; the demos in demos/*.toml are examples.
"""

from __future__ import annotations

import inspect
import math
import re
import warnings
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from ..body.mesh import Mesh
from ..body.topology import Cloth
from ..contact.colliders.animated_mesh import AnimatedMeshCollider
from ..contact.colliders.animation_files import read_animation
from ..contact.colliders.mesh_collider import MeshCollider
from ..contact.colliders.shapes import Box, Capsule, Collider, Plane, Sphere
from ..contact.self_collision import SelfCollision
from ..inputs import limits
from ..inputs.scene_file import SceneError, Table, argument_default, load_toml
from ..integrators import INTEGRATORS, make_integrator
from ..physics.sewing import Sewing
from ..physics.strain_limit import StrainLimit
from ..physics.wind import Wind
from ..render.camera import Camera
from ..runtime import backend
from ..simulation import Simulation
from ..stability import auto_substeps
from .scene_bodies import DIMENSION, build_bodies, read_body, read_mesh_file, read_path
from .scene_output import Output, read_camera, read_output
from .scene_preview import previewed

COLLIDER_TYPES = {"plane": Plane, "sphere": Sphere, "box": Box, "capsule": Capsule,
                  "mesh": MeshCollider, "animated_mesh": AnimatedMeshCollider}
NAME_FORBIDDEN = r"[^\w .-]"
GUARD_SIZES = 100.0   # a run has diverged once a coordinate is this many body sizes out
ADVICE_WINDOW = 1.0   # s: integrator = "auto" advises on at most this much of the scene by default


@dataclass(frozen=True)
class AdviceRequest:
    """integrator = "auto" in [simulation]: the largest error accepted (`tolerance`, a fraction
    of the cloth size, in `metric`), over the first `window` seconds, among `integrators`
    (None: all), `precisions` and `resolutions` (None: the scene's own)."""

    tolerance: float
    metric: str
    window: float
    integrators: tuple | None
    precisions: tuple
    resolutions: tuple | None = None


@dataclass
class Scene:
    """A scene file, read and checked; `build()` makes its Simulation (after ti_cloth.init)."""

    name: str
    source: Path
    description: str
    cloth: Cloth
    integrator: object
    fps: float
    frames: int
    substeps: int | str
    precision: str
    gravity: tuple
    drag: float
    wind: Wind | None
    tearing: float | None
    strain_limit: StrainLimit | None
    self_collision: SelfCollision | None
    handles: list
    colliders: list
    camera: Camera | None
    camera_fit: dict
    output: Output
    advice: AdviceRequest | None = None   # integrator = "auto": what the advisor is asked
    bodies: tuple = ()                    # the [[bodies]] read (scene_bodies.Body)
    resolution: int = 1                   # `cloth` is the bodies refined this many times
    file_particles: int = 0               # particles of the bodies as the file gives them
    sewing: Sewing | None = None          # how a garment's seams close ([simulation.sewing])
    preview: tuple = ()                   # what a preview changed, in words (scene_preview.py)

    @property
    def own_particles(self) -> np.ndarray:
        """The particles of the scene file (the first file_particles at every resolution)
        that are drawn (not hair's ghosts): where the study measures errors."""
        count = self.file_particles or self.cloth.particle_count
        return np.flatnonzero(~self.cloth.ghost[:count])

    def refined(self, resolution: int) -> "Scene":
        """This scene with every body `resolution` times as fine as the file gives it
        (scene_bodies: the file's particles first, pins, hems and handles carried over); the
        same scene when it is at that resolution already."""
        if not (isinstance(resolution, (int, np.integer)) and not isinstance(resolution, bool)
                and limits.RESOLUTION.low <= resolution <= limits.RESOLUTION.high):
            raise ValueError(f"resolution must be an integer {limits.RESOLUTION.text()}, "
                             f"got {resolution!r}")
        if resolution == self.resolution:
            return self
        if not self.bodies:
            raise ValueError("resolution: this scene keeps no body descriptions to refine "
                             "(read it with load_scene)")
        # the bodies grow as the resolution to their dimension: refused before a refinement
        # that would not fit in memory is computed (an interrupt is not heard inside numpy)
        scale = (resolution / self.resolution) ** max(DIMENSION.get(body.kind, 2)
                                                      for body in self.bodies)
        try:
            limits.check_memory("resolution", resolution, int(self.cloth.particle_count * scale),
                                int(self.cloth.spring_count * scale))
            cloth, handles, _ = build_bodies(self.bodies, int(resolution))
        except ValueError as err:
            said = str(err) if str(err).startswith(f"resolution = {resolution} ") else \
                f"resolution = {resolution}: {err}"
            raise SceneError(f"{self.source}: {said}") from None
        return replace(self, cloth=cloth, handles=handles, resolution=int(resolution))

    @property
    def automatic(self) -> bool:
        """integrator = "auto": the advisor picks the integrator, step and precision before a
        run (app/advisor.py: resolve)."""
        return self.advice is not None

    @property
    def size(self) -> float:
        """The bodies' size [m]: the diagonal of their rest bounding box."""
        x = self.cloth.particle_position
        return float(np.linalg.norm(x.max(axis=0) - x.min(axis=0)))

    def motion_bounds(self) -> np.ndarray:
        """Where the scene's motion happens, (2, 3) corners [m], for a camera fitted to it:
        the bodies at rest; the room they move in: a particle of a held body (pins, handles,
        attachments) swings below and beside the holds no further than its rest distance
        from each, a free body falls at most its own size; the colliders of finite size (an animated
        mesh over all its samples); nothing below the ground (the output's, or a level
        plane under the bodies)."""
        x = self.cloth.particle_position
        lo, hi = x.min(axis=0), x.max(axis=0)
        held = self.cloth.pinned.copy()
        for handle in self.handles:
            held[np.asarray(handle.particles)] = True
        if held.any():
            # particle i stays within |x_i - h| of every hold h (its rest distance, as far
            # as the cloth between them can stretch out straight): its box is the overlap of
            # those spheres' boxes, below the holds (gravity)
            holds = x[held][:: max(1, int(held.sum()) // 64)]
            top = np.full(3, -np.inf)
            for start in range(0, len(x), 4096):          # (4096, 64, 3) at a time
                reach = np.linalg.norm(x[start:start + 4096, None] - holds[None], axis=2)
                lo = np.minimum(lo, (holds[None] - reach[:, :, None]).max(axis=1).min(axis=0))
                top = np.maximum(top, (holds[None] + reach[:, :, None]).min(axis=1).max(axis=0))
            hi = np.maximum(hi, (top[0], hi[1], top[2]))
        else:
            lo = lo - (0.0, self.size, 0.0)
        floors = [p.point[1] for p in self.colliders if isinstance(p, Plane)
                  and np.allclose(np.asarray(p.normal) / np.linalg.norm(p.normal), (0, 1, 0))]
        floors += [self.output.ground] if self.output.ground is not None else []
        for c in self.colliders:
            box = c.bounds()
            if box is not None:
                lo, hi = np.minimum(lo, box[0]), np.maximum(hi, box[1])
        under = [f for f in floors if f <= x[:, 1].min()]
        if under:
            lo[1] = max(lo[1], max(under))
        return np.array([lo, hi])

    @property
    def frame_dt(self) -> float:
        return 1.0 / self.fps

    def resolved_substeps(self) -> int:
        """Steps per frame; "auto": stability.auto_substeps (dt <= min(stable_dt / 2, 1/240 s))."""
        if self.automatic:
            raise SceneError(f"{self.source}: integrator = \"auto\" is chosen by the advisor "
                             "first (ti_cloth.app.advisor.resolve)")
        if self.substeps != "auto":
            return self.substeps
        try:
            return auto_substeps(self.cloth, self.integrator, self.frame_dt, self.drag)
        except ValueError as err:
            raise SceneError(f"{self.source}: {err}") from None

    def work(self, frames: int | None = None) -> limits.Work:
        """What running `frames` frames (default: all) will take: steps, spring updates (each
        pbd/xpbd pass and strain-limit pass a sweep over the springs)."""
        steps = (self.frames if frames is None else frames) * self.resolved_substeps()
        passes = getattr(self.integrator, "iterations", 1)
        passes += self.strain_limit.passes if self.strain_limit is not None else 0
        return limits.work(self.cloth.particle_count, limits.spring_equivalents(self.cloth),
                           steps, passes)

    def build(self, integrator=None, dt: float | None = None, resolution: int | None = None,
              **options) -> Simulation:
        """The Simulation of this scene (call ti_cloth.init first); `integrator` and `dt`
        replace the scene's (the speed/accuracy study sweeps them), `resolution` its bodies'
        (refined(): particle i of the scene file is particle i of the simulation); options:
        further Simulation arguments. The divergence guard's box (position_limit) reaches
        GUARD_SIZES body sizes beyond the rest positions: anything further has left the
        scene. Self-collision in the solve (SelfCollision.in_solve) is xpbd's: another
        integrator (the study's reference, its sweep) takes the contacts after its step."""
        if resolution is not None and resolution != self.resolution:
            return self.refined(resolution).build(integrator, dt, **options)
        options.setdefault("position_limit", GUARD_SIZES * self.size
                           + float(np.abs(self.cloth.particle_position).max()))
        integrator = self.integrator if integrator is None else integrator
        dt = self.frame_dt / self.resolved_substeps() if dt is None else dt
        contact = self.self_collision
        if contact is not None and contact.in_solve and make_integrator(integrator).name != "xpbd":
            contact = replace(contact, in_solve=False)
        return Simulation(self.cloth, integrator=integrator, dt=dt, gravity=self.gravity,
                          drag=self.drag, wind=self.wind, tearing=self.tearing,
                          handles=self.handles, colliders=self.colliders,
                          strain_limit=self.strain_limit, self_collision=contact,
                          sewing=self.sewing, **options)


def load_scene(path, note=None, preview: bool = False) -> Scene:
    """Read a scene file; raises SceneError naming the key, the value and what is allowed.
    note(message), when given, hears before a slow step of loading begins (a body of more than
    limits.LARGE_BODY springs: its stable-step analysis takes seconds to a minute). preview:
    the file's preview instead (scene_preview.py: coarser garment panels, longer
    position-based steps; Scene.preview says what changed), named `<name>_preview`, its
    output folder beside the file's with that suffix."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"scene file not found: {path}")
    raw, changes = load_toml(path), ()
    if preview:
        raw, changes = previewed(raw)
    root = Table(raw, "", str(path))
    meta = root.table("scene") or Table({}, "scene", str(path))
    name = _name(meta, path.stem)
    description = meta.string("description", "")
    meta.finish()

    sim = root.table("simulation") or Table({}, "simulation", str(path))
    automatic = sim.value("integrator", None) == "auto"
    integrator = "auto" if automatic else _integrator(sim)
    fps = sim.number("fps", limits.FPS_DEFAULT, within=limits.FPS)
    frames = round(sim.number("duration", 3.0, within=limits.DURATION) * fps)
    substeps = sim.value("substeps", "auto")
    if substeps != "auto":
        substeps = sim.integer("substeps", within=limits.SUBSTEPS)
    if sim.has("dt"):
        if sim.has("substeps"):
            sim.fail("simulation: give either dt or substeps, not both")
        dt = sim.number("dt", within=limits.DT)
        substeps = max(1, math.ceil(1.0 / fps / dt - 1e-9))
        if substeps > limits.SUBSTEPS.high:
            sim.bad("dt", dt, f">= {1.0 / fps / limits.SUBSTEPS.high:.3g} s at fps = {fps:g} "
                     f"(at most {limits.SUBSTEPS.high:_} steps per frame)")
    advice = _advice_request(sim, fps, frames) if automatic else None
    precision = sim.string("precision", argument_default(backend.init, "precision"),
                           sorted(backend.PRECISIONS))
    if automatic:
        if sim.has("substeps") or sim.has("dt"):
            sim.fail("simulation: integrator = \"auto\" picks the step too; leave out "
                     "substeps and dt")
        advice = replace(advice, precisions=(precision,) if sim.has("precision")
                         else tuple(sorted(backend.PRECISIONS, reverse=True)))
    resolution = sim.integer("resolution", 1, within=limits.RESOLUTION)
    tearing = sim.number("tearing", 0.0, 0.0, strict=True) if sim.has("tearing") else None
    limit = sim.table("strain_limit")
    strain_limit = None
    if limit is not None:
        options = {}
        limit.optional(options, "max_strain")
        limit.optional(options, "passes", "integer", minimum=1)
        limit.optional(options, "kinds", "value")
        strain_limit = limit.build(StrainLimit, **options)
        limit.finish()
    contact = sim.table("self_collision")
    self_collision = None
    if contact is not None:
        options = {}
        contact.optional(options, "thickness", unit="m")
        contact.optional(options, "friction")
        contact.optional(options, "iterations", "integer", minimum=1)
        contact.optional(options, "never_through", "boolean")
        contact.optional(options, "keep_thickness", "boolean")
        contact.optional(options, "in_solve", "boolean")
        self_collision = contact.build(SelfCollision, **options)
        contact.finish()
    sewing_table = sim.table("sewing")
    sewing = None
    if sewing_table is not None:
        options = {}
        sewing_table.optional(options, "speed", unit="m/s")
        sewing = sewing_table.build(Sewing, **options)
        sewing_table.finish()
    sim.finish()

    forces = root.table("forces") or Table({}, "forces", str(path))
    gravity = forces.vector("gravity", argument_default(Simulation, "gravity"),
                            within=limits.ACCELERATION)
    drag = forces.number("drag", argument_default(Simulation, "drag"), within=limits.DRAG)
    wind_table = forces.table("wind")
    wind = _wind(wind_table) if wind_table is not None else None
    forces.finish()

    colliders = [_collider(t, path.parent) for t in root.tables("colliders")]
    body_tables = root.tables("bodies")
    if not body_tables:
        root.fail("bodies: a scene needs at least one [[bodies]] table")
    bodies, made = zip(*(read_body(table, path.parent, colliders) for table in body_tables))
    try:
        cloth, handles, file_particles = build_bodies(bodies, resolution,
                                                      made if resolution == 1 else None)
    except ValueError as err:      # bodies that cannot join, or cannot be refined
        (root.fail(f"bodies: {err}") if resolution == 1
         else sim.fail(f"simulation.resolution = {resolution}: {err}"))

    camera_table = root.table("camera")
    camera, camera_fit = read_camera(camera_table) if camera_table is not None else (None, {})
    output = read_output(root.table("output") or Table({}, "output", str(path)), name, colliders)
    root.finish()
    scene = Scene(name=name, source=path, description=description, cloth=cloth,
                  integrator=integrator, fps=fps, frames=max(frames, 1), substeps=substeps,
                  precision=precision, gravity=gravity, drag=drag, wind=wind, tearing=tearing,
                  strain_limit=strain_limit, self_collision=self_collision, handles=handles,
                  colliders=colliders, camera=camera,
                  camera_fit=camera_fit, output=output, advice=advice, bodies=bodies,
                  resolution=resolution, file_particles=file_particles, sewing=sewing,
                  preview=changes)
    if changes:               # its frames and states are not the file's scene's
        folder = output.folder
        folder = folder.with_name(f"{folder.name}_preview") if folder.name else folder / "preview"
        scene = replace(scene, name=f"{name}_preview", output=replace(output, folder=folder))
    if note is not None and cloth.spring_count > limits.LARGE_BODY:
        note(f"'{name}' has {cloth.particle_count:,} particles and {cloth.spring_count:,} "
             "springs: finding its stable step takes a while")
    if scene.size > limits.CENTIMETRE_SIZE:       # said once: to `note`, else as a warning
        message = (f"{path}: the bodies are {scene.size:.4g} m across; scene files are in "
                   "metres (a size in centimetres? divide it by 100)")
        if note is not None:
            note(message)
        else:
            warnings.warn(message, stacklevel=2)
    check_runnable(scene, root)
    return scene


def _advice_request(sim: Table, fps: float, frames: int) -> AdviceRequest:
    """The [simulation] keys of integrator = "auto": tolerance (required), metric, window,
    integrators (the candidates)."""
    if not sim.has("tolerance"):
        sim.fail('simulation: integrator = "auto" needs tolerance = the largest error accepted '
                 "(a fraction of the cloth size, e.g. 1e-3)")
    tolerance = sim.number("tolerance", minimum=0.0, strict=True)
    metric = sim.string("metric", "max_error", ("max_error", "rms_error",
                                                   "observable_error"))
    duration = frames / fps
    window = sim.number("window", min(ADVICE_WINDOW, duration), minimum=0.0, strict=True, unit="s")
    if window > duration:
        sim.bad("window", window, f"<= the duration, {duration:g} s")
    candidates = sim.value("integrators", None)
    if candidates is not None and (not isinstance(candidates, list) or not candidates
                                   or not set(candidates) <= set(INTEGRATORS)):
        sim.bad("integrators", candidates, f"a list of some of {sorted(INTEGRATORS)}")
    resolutions = sim.value("resolutions", None)
    if resolutions is not None and (
            not isinstance(resolutions, list) or not resolutions
            or not all(isinstance(f, int) and not isinstance(f, bool)
                       and limits.RESOLUTION.low <= f <= limits.RESOLUTION.high
                       for f in resolutions)):
        sim.bad("resolutions", resolutions,
                f"a list of resolutions, integers {limits.RESOLUTION.text()} (e.g. [1, 2, 4])")
    return AdviceRequest(tolerance, metric, window,
                         tuple(candidates) if candidates is not None else None, (),
                         tuple(resolutions) if resolutions is not None else None)


def _name(meta: Table, stem: str) -> str:
    """scene.name (it names the GIF/MP4 and the default folder): letters, digits, spaces and
    _ - . , at most limits.NAME_LENGTH long, not starting with "."; the default is the file's
    stem with other characters replaced by "_"."""
    if not meta.has("name"):
        return re.sub(NAME_FORBIDDEN, "_", stem.lstrip("."))[:limits.NAME_LENGTH] or "scene"
    name = meta.string("name")
    if not (0 < len(name) <= limits.NAME_LENGTH and not name.startswith(".")
            and not re.search(NAME_FORBIDDEN, name)):
        meta.bad("name", name, f"1 to {limits.NAME_LENGTH} letters, digits, spaces, '_', '-' or "
                  "'.' (it names files), not starting with '.'")
    return name


def check_runnable(scene: Scene, root: Table) -> None:
    """What only the whole scene decides, checked before anything runs: the wind has triangles
    to act on, the step count per frame and per run, and the camera can frame the body."""
    if scene.wind is not None and scene.cloth.mesh.triangle_count == 0:
        root.fail("forces.wind: wind acts on triangles, and these bodies have none (strings and "
                  "hair: use forces.drag)")
    if (scene.cloth.fabric and not scene.automatic
            and not getattr(scene.integrator, "runs_fabric", True)):
        able = sorted(name for name, cls in INTEGRATORS.items() if cls.runs_fabric)
        root.fail(f"simulation.integrator = {scene.integrator.name!r} cannot step a body made "
                  f"of a fabric (its springs only); use one of {able} (xpbd is pbd with the "
                  "fabric's moduli)")
    if scene.sewing is not None and not len(scene.cloth.seam_indices):
        root.fail("simulation.sewing: no body has seams to sew (a garment body's `seams`)")
    substeps = 1 if scene.automatic else scene.resolved_substeps()   # "auto": the advisor's
    if substeps > limits.SUBSTEPS.high:
        root.fail(f"simulation.substeps = \"auto\" needs {substeps:_} steps per frame (a stable "
                  f"step of {scene.frame_dt / substeps:.3g} s for these springs and masses), more "
                  f"than {limits.SUBSTEPS.high:_}: soften the stiffest springs or raise the "
                  "density (limits: README)")
    if scene.frames * substeps > limits.STEPS.high:
        root.fail(f"simulation.duration: {scene.frames:_} frames x {substeps:_} steps is more "
                  f"than {limits.STEPS.high:_} steps")
    if scene.camera is None:
        out = scene.output
        try:
            Camera.fit(scene.motion_bounds(), aspect=out.width / out.height,
                       **scene.camera_fit)
        except ValueError as err:
            root.fail(f"camera: {err}")


def _integrator(sim: Table):
    spec = sim.value("integrator", argument_default(Simulation, "integrator"))
    if isinstance(spec, str):
        spec = {"name": spec}
    table = Table(spec, sim.path("integrator"), sim.source)
    name = table.string("name", choices=sorted(INTEGRATORS))
    accepted = inspect.signature(INTEGRATORS[name]).parameters
    options = {k: table.value(k) for k in list(table.data) if k in accepted}
    table.finish(also=accepted)
    return table.build(INTEGRATORS[name], **options)


def _collider(table: Table, folder: Path):
    """One [[colliders]] table. A mesh's `path` is its file (relative to the scene file, as
    for mesh bodies), so its motion is `motion`; an animated mesh's `path` is its animation
    file (npz, PC2 with its `rest` mesh, "name_*.obj", USD: animation_files.py); other shapes
    move along `path`."""
    kind = table.string("type", choices=sorted(COLLIDER_TYPES))
    options = {}
    table.optional(options, "thickness", unit="m")
    table.optional(options, "static_friction")
    table.optional(options, "kinetic_friction")
    if kind == "mesh":
        mesh = read_mesh_file(table, folder)
        motion = {}
        table.optional(motion, "motion", lambda k: read_path(table.table(k)))
        options |= {"path": motion["motion"]} if motion else {}
        table.optional(options, "rotation", lambda k: read_path(table.table(k)))
        table.optional(options, "resolution", "integer", within=limits.SDF_RESOLUTION)
        table.optional(options, "solid", "boolean")
        collider = table.build(MeshCollider, mesh, **options)
    elif kind == "animated_mesh":
        files = {"path": folder / table.string("path")}
        table.optional(files, "rest", lambda k: folder / table.string(k))
        table.optional(files, "fps", unit="frames/s")
        table.optional(files, "prim", "string")
        table.optional(options, "edge_contact", table.switch)
        mesh, samples, fps = table.build(read_animation, **files)
        scale = table.number("scale", 1.0, within=limits.SCALE)
        translate = np.asarray(table.vector("translate", (0.0, 0.0, 0.0), unit="m",
                                               within=limits.COORDINATE))
        collider = table.build(AnimatedMeshCollider, Mesh(mesh.vertices * scale + translate,
                                                          mesh.triangles),
                               samples * scale + translate, fps=fps, **options)
    else:
        table.optional(options, "path", lambda k: read_path(table.table(k)))
        shape = COLLIDER_TYPES[kind]
        common = {f.name for f in fields(Collider)}
        for f in fields(shape):
            if f.name not in common:
                table.optional(options, f.name,
                               "vector" if isinstance(f.default, tuple) else "number")
        collider = table.build(shape, **options)
    table.finish()
    return collider


def _wind(table: Table) -> Wind:
    options = {"velocity": table.vector("velocity", (0.0, 0.0, 0.0), unit="m/s")}
    for key in ("gust", "gust_period", "turbulence", "turbulence_scale", "air_density",
                "drag_coefficient", "lift_coefficient", "friction_coefficient"):
        if table.has(key):
            options[key] = table.number(key)
    if table.has("seed"):
        options["seed"] = table.integer("seed", minimum=0)
    wind = table.build(Wind, **options)
    table.finish()
    return wind
