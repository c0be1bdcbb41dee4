"""A scene file's [[bodies]] tables, read into Body specs that build their Cloth at any
resolution (body/refine.py): at 1 the body as the file describes it, at f every body f times
finer with the file's particles first and in order (particle i of the scene is particle i of
every refinement, new particles after all of them), pins, hems and handles carried over.

Named particle sets ("bottom", "start", "roots", "boundary") are found again on the refined
body; particles given by index are carried with the new particles of every coarse edge whose
two ends they hold (a pinned edge stays pinned along its length); a ball takes the particles
inside it at every resolution. Spring constants are rebuilt for the modulus they stand for
(refine.springs_at); a Fabric is resolution-free already.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..body import bodies as builders
from ..body import refine
from ..body.fabric import PRESETS as FABRICS
from ..body.fabric import Fabric
from ..body.material import DAMPING_MODELS, PRESETS, Material, SpringParams, preset_name
from ..body.mesh import PLANES, Mesh, grid_mesh, load_mesh
from ..body.panels import Garment, panel
from ..body.topology import Cloth
from ..contact.colliders.attachment import Attachment
from ..contact.colliders.shapes import Collider
from ..inputs import limits
from ..inputs.limits import Range
from ..inputs.scene_file import Table, argument_default, quoted
from ..physics.handles import Handle
from ..physics.paths import INTERPOLATIONS, Keyframes, Oscillation

BODY_TYPES = ("grid", "mesh", "garment", "string", "hair", "tet_block")
SPRING_KEYS = {"string": ("stretch", "bend"), "hair": ("stretch", "bend", "twist", "altitude"),
               "tet_block": ("stretch",)}
DIMENSION = {"string": 1, "hair": 1, "tet_block": 3}


@dataclass(frozen=True)
class Selection:
    """Particles a scene file names on a body: `names` of its named sets, coarse `indices`,
    a `ball` (centre, radius) [m]."""

    names: tuple = ()
    indices: tuple = ()
    ball: tuple | None = None

    def resolve(self, named: dict, positions: np.ndarray, refinement) -> np.ndarray:
        """The particles of the refined body (its builder's numbering) this selection is."""
        chosen = [refinement.carry(self.indices)] + [np.asarray(named[n]) for n in self.names]
        if self.ball is not None:
            centre, radius = self.ball
            chosen.append(np.flatnonzero(np.linalg.norm(positions - centre, axis=1) <= radius))
        return np.unique(np.concatenate(chosen).astype(np.int64))


@dataclass(frozen=True)
class HandleSpec:
    """A [[bodies.handles]] table (its `path`) or a [[bodies.attachments]] one (its
    `collider`), read."""

    particles: Selection
    path: object = None
    release: float | None = None
    collider: Collider | None = None

    def make(self, particles: np.ndarray) -> Handle | Attachment:
        """The Handle or Attachment holding `particles` of the built body."""
        if self.collider is not None:
            return Attachment(particles, self.collider, self.release)
        return Handle(particles, self.path, self.release)


@dataclass(frozen=True)
class Body:
    """One [[bodies]] table, read: its `kind`, its builder's arguments as the file gives them
    (`options`), what it is made of, which particles are pinned, hemmed and held."""

    kind: str
    options: dict
    material: Material | Fabric | None = None
    mesh: Mesh | None = None
    pinned: Selection | None = None
    hem: Selection | None = None
    warp: dict = field(default_factory=dict)
    handles: tuple = ()

    def make(self, factor: int = 1) -> tuple[Cloth, refine.Refinement, dict]:
        """(the body `factor` times finer in its builder's numbering, how it refines the
        file's body, its named particle sets in that numbering)."""
        return getattr(self, f"_{self.kind}")(factor)

    def held(self, cloth: Cloth, refinement, names: dict) -> list:
        """Its handles and attachments on `cloth` (made by make()) as (particles, spec)."""
        return [(h.particles.resolve(names, cloth.particle_position, refinement), h)
                for h in self.handles]

    def _surface(self, mesh: Mesh, refinement, names: dict, factor: int, seams=None,
                 rest=None):
        everything = mesh.named_vertices() | names
        hem = None if self.hem is None else self.hem.resolve(everything, mesh.vertices, refinement)
        cloth = Cloth(mesh, refine.material_at(self.material, factor),
                      pinned=self.pinned.resolve(everything, mesh.vertices, refinement), hem=hem,
                      seams=seams, rest=rest, **self.warp)
        return cloth, refinement, names

    def _grid(self, factor: int):
        rows, cols = (self.options[k] for k in ("rows", "cols"))
        geometry = {k: v for k, v in self.options.items() if k not in ("rows", "cols")}
        mesh = grid_mesh((rows - 1) * factor + 1, (cols - 1) * factor + 1, **geometry)
        return self._surface(mesh, refine.grid_refinement(rows, cols, factor), grid_names(mesh),
                             factor)

    def _mesh(self, factor: int):
        mesh, refinement = refine.subdivide(self.mesh, factor)
        return self._surface(mesh, refinement, {}, factor)

    def _garment(self, factor: int):
        garment = self.options["garment"]
        mesh, refinement = refine.subdivide(garment.mesh, factor)
        names = {k: refinement.carry(v) for k, v in garment_names(garment).items()}
        return self._surface(mesh, refinement, names, factor,
                             seams=refine.seams_at(garment.seam_pairs, refinement,
                                                   mesh.vertices), rest="uv")

    def _refined_options(self, factor: int) -> dict:
        builder = getattr(builders, self.kind)
        options = dict(self.options)
        for key in SPRING_KEYS[self.kind]:
            value = options.get(key, argument_default(builder, key))
            options[key] = refine.springs_at(value, factor, DIMENSION[self.kind])
        return options

    def _string(self, factor: int):
        options = self._refined_options(factor)
        n = (options.pop("n") - 1) * factor + 1
        cloth = builders.string(n, **options)
        return (cloth, refine.chain_refinement(1, self.options["n"] - 1, factor, False),
                {"start": [0], "end": [n - 1]})

    def _hair(self, factor: int):
        options = self._refined_options(factor)
        segments = options.pop("segments")
        cloth = builders.hair(options.pop("strands"), segments * factor, **options)
        return (cloth, refine.chain_refinement(self.options["strands"], segments, factor,
                                               options.get("ghosts", True)),
                {"roots": np.flatnonzero(cloth.pinned)})

    def _tet_block(self, factor: int):
        options = self._refined_options(factor)
        cells = np.asarray(options.pop("cells", argument_default(builders.tet_block, "cells")))
        cloth = builders.tet_block(cells * factor, **options)
        return cloth, refine.tet_refinement(cells.astype(np.int64), factor), {}


def grid_names(mesh: Mesh) -> dict:
    """A grid's named vertex sets a scene's pins and handles may use (all but "boundary")."""
    return {k: v for k, v in mesh.named_vertices().items() if k != "boundary"}


def garment_names(garment: Garment) -> dict:
    """A garment's named particle sets: "panel<p>" (a whole panel) and "panel<p>_edge<e>"
    (outline edge e of panel p: a waistband, a hem)."""
    names = {}
    for p, piece in enumerate(garment.panels):
        names[f"panel{p}"] = garment.particles(p)
        for e in range(len(piece.edges)):
            names[f"panel{p}_edge{e}"] = garment.particles(p, e)
    return names


def build_bodies(bodies, factor: int = 1, made=None) -> tuple[Cloth, list[Handle], int]:
    """The scene's bodies `factor` times finer as one Cloth (the file's particles first, in
    the file's order, then the new particles of each body in turn), their handles and the
    number of the file's particles. made: each body's make(factor), when already made."""
    made = made or [body.make(factor) for body in bodies]
    clothes = [cloth for cloth, _, _ in made]
    cloth = clothes[0] if len(clothes) == 1 else Cloth.combine(clothes)
    offsets = np.cumsum([0] + [c.particle_count for c in clothes])
    orders = [refinement.order + offset for (_, refinement, _), offset in zip(made, offsets)]
    coarse = [len(refinement.coarse) for _, refinement, _ in made]
    order = np.concatenate([o[:n] for o, n in zip(orders, coarse)]
                           + [o[n:] for o, n in zip(orders, coarse)])
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    if not np.array_equal(order, np.arange(len(order))):
        cloth = cloth.renumbered(order)
    handles = [spec.make(np.sort(rank[particles + offset]))
               for body, m, offset in zip(bodies, made, offsets)
               for particles, spec in body.held(*m)]
    return cloth, handles, sum(coarse)


def read_body(table: Table, folder: Path, colliders=()) -> tuple[Body, tuple]:
    """One [[bodies]] table -> (its Body, its make(1): built as the file describes it);
    `colliders`: the scene's, which its attachments name by index."""
    kind = table.string("type", choices=BODY_TYPES)
    options = {}
    if kind in ("grid", "mesh", "garment"):
        if kind == "grid":
            options["rows"] = table.integer("rows", 16, within=limits.GRID_SIDE)
            options["cols"] = table.integer("cols", 16, within=limits.GRID_SIDE)
            table.optional(options, "size", "vector", length=2, unit="m")
            table.optional(options, "plane", "string", choices=sorted(PLANES))
            table.optional(options, "origin", "vector", unit="m", within=limits.COORDINATE)
            mesh = table.build(grid_mesh, **options)
            names = grid_names(mesh)
        elif kind == "mesh":
            mesh, names = read_mesh_file(table, folder), {}
        else:
            options["garment"] = _garment(table)
            mesh, names = options["garment"].mesh, garment_names(options["garment"])
        table.allow("hem", "material", "fabric")
        warp = {}
        table.optional(warp, "warp", lambda k: "uv" if table.value(k) == "uv" else table.vector(k))
        hem = (_selection(table, "hem", mesh.vertex_count, mesh.named_vertices() | names,
                          mesh.vertices) if table.has("hem") else None)
        body = Body(kind, options, _material(table), mesh if kind == "mesh" else None,
                    _selection(table, "pinned", mesh.vertex_count, names, mesh.vertices), hem, warp)
    elif kind == "string":
        options["n"] = table.integer("n", 20, within=limits.CHAIN)
        options["length"] = table.number("length", 1.0, unit="m")
        table.optional(options, "mass", unit="kg")
        _spring_options(table, options, "stretch", "bend")
        table.optional(options, "start", "vector", unit="m")
        table.optional(options, "direction", "vector")
        table.optional(options, "fixed", "string", choices=builders.STRING_ENDS)
        table.optional(options, "end_mass", "string", choices=builders.END_MASSES)
        body = Body(kind, options)
    elif kind == "hair":
        options["strands"] = table.integer("strands", 64, within=limits.STRANDS)
        options["segments"] = table.integer("segments", 12, within=limits.SEGMENTS)
        options["length"] = table.number("length", 0.3, unit="m")
        table.optional(options, "anchor", "vector", unit="m")
        table.optional(options, "radius", unit="m")
        table.optional(options, "mass", unit="kg")
        table.optional(options, "ghosts", "boolean")
        table.optional(options, "curl", "vector", length=2, unit="m")
        _spring_options(table, options, "stretch", "bend", "twist")
        table.optional(options, "altitude", _altitude_springs(table))
        body = Body(kind, options)
    else:
        table.optional(options, "cells", "vector", unit="cubes")
        table.optional(options, "size", "vector", unit="m")
        table.optional(options, "origin", "vector", unit="m", within=limits.COORDINATE)
        table.optional(options, "density", unit="kg/m^3")
        _spring_options(table, options, "stretch")
        body = Body(kind, options)
    made = table.build(body.make)
    cloth, refinement, names = made
    specs = []
    for h in table.tables("handles"):
        particles = _selection(h, "particles", cloth.particle_count, names)
        if not (particles.names or particles.indices):
            h.fail(f"{h.path('particles')} must list at least one particle")
        release = {}
        h.optional(release, "release", unit="s")
        spec = HandleSpec(particles, read_path(h.table("path", True)), release.get("release"))
        h.build(spec.make, particles.resolve(names, cloth.particle_position, refinement))
        specs.append(spec)
        h.finish()
    for a in table.tables("attachments"):
        particles = _selection(a, "particles", cloth.particle_count, names,
                               cloth.particle_position)
        if not (particles.names or particles.indices or particles.ball):
            a.fail(f"{a.path('particles')} must list at least one particle")
        if not colliders:
            a.fail(f"{a.path('collider')}: a body's attachments need [[colliders]] to attach "
                   "to (none in this scene)")
        index = a.integer("collider", within=Range(0, len(colliders) - 1, "",
                                                      "the index of a [[colliders]] table"))
        release = {}
        a.optional(release, "release", unit="s")
        spec = HandleSpec(particles, release=release.get("release"), collider=colliders[index])
        attachment = a.build(spec.make, particles.resolve(names, cloth.particle_position,
                                                           refinement))
        a.build(attachment.handle, cloth.particle_position)
        specs.append(spec)
        a.finish()
    table.finish()
    return replace(body, handles=tuple(specs)), made


def _garment(table: Table) -> Garment:
    """A garment body's [[bodies.panels]] (outline, edge_length, wrap, flare, gather, rotate,
    translate) and
    `seams` ([panel_a, edge_a, panel_b, edge_b] each)."""
    pieces = []
    for p in table.tables("panels"):
        piece = p.build(panel, p.value("outline"), p.number("edge_length", unit="m",
                                                            within=limits.LENGTH))
        if p.has("wrap"):
            piece = p.build(piece.wrapped, p.number("wrap", unit="m", within=limits.LENGTH),
                            p.number("flare", 0.0, minimum=0.0),
                            p.number("gather", 1.0, within=limits.GATHER))
        piece = p.build(piece.moved, p.vector("translate", (0.0, 0.0, 0.0), unit="m",
                                              within=limits.COORDINATE),
                        p.vector("rotate", (0.0, 0.0, 0.0), unit="rad"))
        p.finish()
        pieces.append(piece)
    if not pieces:
        table.fail(f"{table.path('panels')}: a garment needs at least one [[bodies.panels]] "
                   "table")
    seams = table.value("seams", [])
    if not isinstance(seams, list):
        table.bad("seams", seams, "a list of [panel_a, edge_a, panel_b, edge_b]")
    return table.build(Garment, pieces, seams)


def _springs(table: Table | None, default: SpringParams | None) -> SpringParams | None:
    if table is None:
        return default
    params = table.build(SpringParams, k=table.number("k", unit="N/m"),
                         kd=table.number("kd", 0.0, unit="kg/s"))
    table.finish()
    return params


def _spring_options(table: Table, options: dict, *keys: str) -> None:
    """Spring constants tables ({ k, kd }) among `keys`, into options (absent: the builder's)."""
    for key in keys:
        table.optional(options, key, lambda k: _springs(table.table(k), None))


def _altitude_springs(table: Table):
    """Reads a hair's `altitude` key: true (the twist constants), false (none) or { k, kd }."""
    def read(key):
        value = table.value(key, None)
        if isinstance(value, bool):
            return value
        if not isinstance(value, dict):
            table.fail(f"{table.path(key)} must be true, false or a table {{ k, kd }}, "
                       f"got {quoted(value)}")
        return _springs(table.table(key), None)
    return read


def _material(owner: Table) -> Material | Fabric:
    """A surface body's `material` (Stuyck's springs: a preset name or a table) or `fabric`
    (a measured fabric: a preset name or a [bodies.fabric] table of `preset` and any of
    Fabric's fields), at most one of them; default Material()."""
    if owner.has("fabric"):
        if owner.has("material"):
            owner.bad("fabric", owner.value("fabric"),
                      "absent when `material` is given (a body is made of springs or of a fabric)")
        return _fabric(owner)
    value = owner.value("material", None)
    if value is None:
        return Material()
    if isinstance(value, str):
        name = preset_name(value)            # a former name warns once, here
        if name not in PRESETS:
            fabric = (f" ({value!r} is a measured fabric: fabric = {value!r})"
                      if value.lower() in FABRICS else "")
            owner.bad("material", value, f"a table or one of the presets {sorted(PRESETS)}"
                      f"{fabric}", PRESETS)
        return Material.preset(name)
    table = Table(value, owner.path("material"), owner.source)
    table.allow("preset", "density", "hem_mass", "stretch", "shear", "bend", "damping")
    preset = (_preset(table, PRESETS, preset_name(table.value("preset")))
              if table.has("preset") else None)
    base = Material.preset(preset) if preset else Material()
    changes = {}
    for key in ("density", "hem_mass"):
        if table.has(key):
            changes[key] = table.number(key, unit="kg/m^2" if key == "density" else "kg")
    for key in ("stretch", "shear", "bend"):
        if table.has(key):
            changes[key] = _springs(table.table(key), None)
    if table.has("damping"):
        changes["damping"] = table.string("damping", choices=DAMPING_MODELS)
    table.finish()
    return table.build(lambda: Material(**{**base.__dict__, **changes}))


def _preset(table: Table, presets, name=None) -> str:
    """A table's `preset`: one of `presets`, in any letter case (returned in lower case);
    name: the value as the presets spell it, when that is not merely its lower case."""
    value = table.value("preset")
    name = value.lower() if name is None and isinstance(value, str) else name
    if not (isinstance(name, str) and name in presets):
        table.bad("preset", value, f"one of {sorted(presets)}", presets)
    return name


def _fabric(owner: Table) -> Fabric:
    """`fabric = "denim"`, or a [bodies.fabric] table: `preset` plus any of density [kg/m^2],
    stretch and bending (a number or [warp, weft]; N/m, N m), shear [N/m], twist [N m],
    bending_curve (an inline table of BendingCurve's fields: rigidities sampled at
    curvatures), poisson, compression, damping [s], hem_mass [kg]."""
    value = owner.value("fabric")
    if isinstance(value, str):
        if value.lower() not in FABRICS:
            owner.bad("fabric", value, f"a table or one of the fabrics {sorted(FABRICS)}",
                      FABRICS)
        return Fabric.preset(value)
    if not isinstance(value, dict):
        owner.bad("fabric", value, f"a table or one of the fabrics {sorted(FABRICS)}")
    table = Table(value, owner.path("fabric"), owner.source)
    table.allow("preset", "density", "shear", "poisson", "compression", "damping", "hem_mass",
                "stretch", "bending", "twist", "bending_curve")
    preset = _preset(table, FABRICS) if table.has("preset") else None
    changes = {}
    for key, unit in (("density", "kg/m^2"), ("shear", "N/m"), ("poisson", ""),
                      ("compression", ""), ("damping", "s"), ("hem_mass", "kg"), ("twist", "N m")):
        if table.has(key):
            changes[key] = table.number(key, unit=unit)
    for key, unit in (("stretch", "N/m"), ("bending", "N m")):
        if table.has(key):
            pair = isinstance(table.value(key), list)
            changes[key] = (tuple(table.vector(key, length=2, unit=unit)) if pair
                            else table.number(key, unit=unit))
    if table.has("bending_curve"):
        curve = table.value("bending_curve")
        if not isinstance(curve, dict):
            table.bad("bending_curve", curve, "a table { curvature = [...] (1/m, from 0), "
                      "warp = [...], weft = [...], bias = [...] (optional) } of rigidities [N m]")
        changes["bending_curve"] = curve
    table.finish()
    if preset:
        return table.build(Fabric.preset, preset, **changes)
    return table.build(Fabric, **changes)


def _selection(table: Table, key: str, count: int, named: dict | None = None,
               positions: np.ndarray | None = None) -> Selection:
    """Particles given as indices and names, or (a surface body: `positions`, its rest
    positions) as a ball, { centre = [x, y, z], radius = r }: the particles within it."""
    value = table.value(key, [])
    if isinstance(value, dict) and positions is not None:
        ball = table.table(key)
        centre = np.array(ball.vector("centre", unit="m", within=limits.COORDINATE))
        radius = ball.number("radius", minimum=0.0, unit="m")
        ball.finish()
        if not (np.linalg.norm(positions - centre, axis=1) <= radius).any():
            table.bad(key, value, "a ball holding at least one particle")
        return Selection(ball=(centre, radius))
    names, indices = [], []
    for item in value if isinstance(value, list) else [value]:
        if isinstance(item, str) and named and item in named:
            names.append(item)
        elif isinstance(item, int) and not isinstance(item, bool) and 0 <= item < count:
            indices.append(item)
        else:
            names_text = f" or one of {list(named)}" if named else ""
            ball = ", or a ball { centre = [x, y, z], radius = r }" if positions is not None else ""
            table.bad(key, item, f"particle indices in [0, {count - 1}]{names_text}{ball}")
    return Selection(tuple(dict.fromkeys(names)), tuple(sorted(set(indices))))


def read_mesh_file(table: Table, folder: Path) -> Mesh:
    """The mesh of a `path` key, relative to the scene file's folder, scaled by `scale` and
    then moved by `translate` [m]."""
    path = folder / table.string("path")
    if not path.is_file():
        table.fail(f"{table.path('path')}: no mesh file at {path} (OBJ, PLY, STL, ... anything "
                   "meshio reads, relative to the scene file)")
    try:
        mesh = load_mesh(path)
    except ValueError as err:
        table.fail(f"{table.path('path')}: {err}")
    scale = table.number("scale", 1.0, within=limits.SCALE)
    translate = np.asarray(table.vector("translate", (0.0, 0.0, 0.0), unit="m",
                                       within=limits.COORDINATE))
    return Mesh(mesh.vertices * scale + translate, mesh.triangles, uvs=mesh.uvs)


def read_path(table: Table):
    """A handle's or collider's `path` table: keyframes or an oscillation."""
    kind = table.string("type", choices=("keyframes", "oscillation"))
    if kind == "keyframes":
        path = table.build(Keyframes, table.value("times"), table.value("values"),
                           table.string("interpolation", "linear", INTERPOLATIONS))
    else:
        path = table.build(Oscillation, table.vector("amplitude", unit="m"),
                           table.number("frequency", unit="Hz"), table.number("phase", 0.0),
                           table.number("start", 0.0, unit="s"))
    table.finish()
    return path

