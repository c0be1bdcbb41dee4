"""The renderer behind a small interface: begin a frame, draw things, end it as an image.

    renderer = Renderer(1280, 720, camera=Camera.fit(cloth), supersample=2)
    renderer.begin()
    renderer.draw_plane(point=(0, -1, 0))
    renderer.draw_simulation(sim, SurfaceStyle(checker=0.1))
    image = renderer.end()            # (720, 1280, 3) uint8, top-left origin

`NullRenderer` has the same methods and draws nothing (tests, benchmarks). The simulation never
imports this module; `draw_simulation` only reads a Simulation's public methods.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, fields

import numpy as np
import taichi as ti

from ..body.material import SpringKind
from ..body.mesh import vertex_triangles
from ..contact.colliders.animated_mesh import AnimatedMeshCollider
from ..contact.colliders.mesh_collider import MeshCollider
from ..contact.colliders.shapes import BOX, CAPSULE, SPHERE, Box, Capsule, Plane, Sphere
from ..inputs import limits
from ..inputs.validation import (
    as_array,
    finite_number,
    in_range,
    integer,
    keyword_only,
    require,
)
from ..runtime import backend
from ..runtime.backend import taichi_dtype
from . import raster, shapes
from .camera import Camera
from .image import from_taichi
from .strain import vertex_strain

COLLIDER_COLOUR = (0.62, 0.66, 0.72)
# Colliders and the ground are drawn this fraction of their depth further away than they are
# (a polygon offset): cloth resting on them, a contact thickness or less away, is drawn in
# front instead of fighting them for the pixels (5 mm at 2.5 m from the camera).
COLLIDER_DEPTH_BIAS = 2e-3
# The ground's shadow (Renderer.cast_shadows): the light's view of the bodies and their
# colliders in a SHADOW_SIZE^2 depth map over their bounds, the ground darkened by
# SHADOW_DARKNESS where it is covered, its edge softened over a texel (bilinear
# percentage-closer filtering). It costs a frame about 3 ms for the map and 6 ms on the
# ground at 960 x 540 (the live viewer draws none).
SHADOW_SIZE = 256
SHADOW_DARKNESS = 0.35
SHADOW_BIAS = 1e-3          # m: what lies nearer the light by less does not shade
SCRATCH_BUFFERS = 64        # scratch ndarrays a renderer keeps (Renderer._buffer)


def _colour(field: str, value) -> tuple:
    rgb = as_array(field, value, np.float64, (3,))
    require(bool(((rgb >= 0) & (rgb <= 1)).all()), field, tuple(rgb), "an RGB triple in [0, 1]")
    return tuple(float(c) for c in rgb)


def _unit(field: str, value) -> tuple:
    v = as_array(field, value, np.float64, (3,))
    require(np.linalg.norm(v) > 0, field, tuple(v), "a non-zero vector")
    return tuple(v / np.linalg.norm(v))


def _validate_colours(instance) -> None:
    for f in fields(instance):
        if f.name.endswith("colour") or f.name in ("front", "back", "top", "bottom"):
            object.__setattr__(instance, f.name, _colour(f"{type(instance).__name__}.{f.name}",
                                                          getattr(instance, f.name)))


@keyword_only
@dataclass(frozen=True, kw_only=True)
class Light:
    """A directional light. direction: towards the light (world, need not be unit).
    ambient: the fraction of the colour shown with no light at all, in [0, 1]."""

    direction: tuple = (0.35, 1.0, 0.55)
    ambient: float = 0.35

    def __post_init__(self):
        object.__setattr__(self, "direction", _unit("Light.direction", self.direction))
        ambient = finite_number("Light.ambient", self.ambient, 0.0)
        require(ambient <= 1.0, "Light.ambient", ambient, "a number in [0, 1]")
        object.__setattr__(self, "ambient", ambient)


@keyword_only
@dataclass(frozen=True, kw_only=True)
class Background:
    """Vertical gradient behind everything: `top` at the top row, `bottom` at the bottom."""

    top: tuple = (0.96, 0.97, 0.99)
    bottom: tuple = (0.70, 0.75, 0.83)

    def __post_init__(self):
        _validate_colours(self)


@keyword_only
@dataclass(frozen=True, kw_only=True)
class SurfaceStyle:
    """How a body is drawn.

    front, back: colours of the two sides (front = counter-clockwise triangle winding as seen).
    checker: cell size [m] of a checker on the rest coordinates (0: off; None: a tenth of the
        body's largest rest extent); checker_contrast in [0, 1].
    strain: colour by per-particle strain instead of front/back, blue (0) to red (strain_max).
    wireframe: triangle edge width [pixels] (0: off). particles: dot radius [pixels] (0: off),
        pinned particles in pin_colour. line_width: [pixels] for bodies without triangles
        (strings, hair), drawn in front colour.
    """

    front: tuple = (0.80, 0.27, 0.22)
    back: tuple = (0.95, 0.78, 0.42)
    checker: float | None = None
    checker_contrast: float = 0.3
    strain: bool = False
    strain_max: float = 0.1
    wireframe: float = 0.0
    wire_colour: tuple = (0.15, 0.15, 0.18)
    particles: float = 0.0
    particle_colour: tuple = (0.1, 0.1, 0.12)
    pin_colour: tuple = (0.9, 0.2, 0.2)
    line_width: float = 2.0

    def __post_init__(self):
        _validate_colours(self)
        if self.checker is not None:
            object.__setattr__(self, "checker", finite_number("SurfaceStyle.checker", self.checker,
                                                              0.0, unit="m"))
        contrast = finite_number("SurfaceStyle.checker_contrast", self.checker_contrast, 0.0)
        require(contrast <= 1.0, "SurfaceStyle.checker_contrast", contrast, "a number in [0, 1]")
        require(isinstance(self.strain, bool), "SurfaceStyle.strain", self.strain, "True or False")
        finite_number("SurfaceStyle.strain_max", self.strain_max, 0.0, strict=True)
        for name in ("wireframe", "particles", "line_width"):
            in_range(f"SurfaceStyle.{name}", getattr(self, name), limits.LINE_WIDTH)
        require(self.line_width > 0, "SurfaceStyle.line_width", self.line_width, "> 0 pixels")


COLLIDER_STYLE = SurfaceStyle(checker=0.0)   # mesh colliders: plain, in COLLIDER_COLOUR


class _Topology:
    """A triangle list uploaded once, with the vertex -> triangle lists the normal gather reads."""

    def __init__(self, triangles: np.ndarray, vertex_count: int):
        t = as_array("triangles", triangles, np.int64, (None, 3))
        if len(t):
            require(t.min() >= 0 and t.max() < vertex_count, "triangles",
                    (int(t.min()), int(t.max())), f"vertex indices in [0, {vertex_count - 1}]")
        start, adjacent = vertex_triangles(t, vertex_count)
        self.vertex_count, self.triangle_count = vertex_count, len(t)
        self.triangles = _device(t.astype(np.int32) if len(t) else np.zeros((1, 3), np.int32))
        self.vertex_start = _device(start.astype(np.int32))
        self.vertex_triangles = _device(adjacent.astype(np.int32) if len(t)
                                        else np.zeros(1, np.int32))


def _device(array: np.ndarray):
    """A Taichi ndarray holding a copy of `array`."""
    nd = ti.ndarray(taichi_dtype(array.dtype), array.shape)
    nd.from_numpy(np.ascontiguousarray(array))
    return nd


class Renderer:
    """Rasterises bodies, lines, particles, a ground plane and collider shapes into an image of
    width x height pixels, supersampled `supersample` x `supersample` times per pixel (box
    filter). Runs on whatever arch ti_cloth was initialised with; needs no window or display."""

    def __init__(self, width: int = 1280, height: int = 720, camera: Camera | None = None, *,
                 supersample: int = 2, light: Light = Light(), background: Background = Background()):
        for name, value, top in (("width", width, 16384), ("height", height, 16384),
                                 ("supersample", supersample, 8)):
            integer(name, value, 1, top)
        require(width * height * supersample**2 <= limits.SAMPLES, "width x height x supersample^2",
                width * height * supersample**2, f"<= {limits.SAMPLES:_} samples")
        require(camera is None or isinstance(camera, Camera), "camera", camera, "a Camera or None")
        require(isinstance(light, Light), "light", light, "a Light")
        require(isinstance(background, Background), "background", background, "a Background")
        self.width, self.height, self.supersample = int(width), int(height), int(supersample)
        self.camera, self.light, self.background = camera, light, background
        self._samples = ti.ndarray(ti.i64, (self.width * supersample, self.height * supersample))
        self._shadow = None              # the light's depth map, made on first cast_shadows
        self._ground = None              # the samples of the last frame's first plane (draw_plane)
        self._ground_key = None          # what they were drawn from
        self._light_cam = None           # its camera, packed, while this frame has shadows
        self._image = np.empty((self.width, self.height, 3), np.uint8)   # written by resolve
        self._scratch: dict[tuple, object] = {}
        self._topologies: dict[int, tuple] = {}
        self._cam = None
        self._open = True
        backend.close_at_init(self)

    def __enter__(self) -> Renderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- frame ------------------------------------------------------------------------------

    def begin(self, camera: Camera | None = None) -> None:
        """Start a frame (clears it), optionally with a new camera."""
        require(self._open, "renderer", "closed", "open (begin called after close)")
        if camera is not None:
            require(isinstance(camera, Camera), "camera", camera, "a Camera")
            self.camera = camera
        require(self.camera is not None, "camera", None, "set (pass camera= or Camera.fit(...))")
        self._cam_packed = self.camera.packed(self.width * self.supersample,
                                              self.height * self.supersample)
        self._cam = self._upload("camera", self._cam_packed)
        self._uncleared = True             # a first draw_plane clears as it goes
        self._light_cam = None
        self._planes = []                  # (normal, offset) of the planes drawn this frame

    def _require_frame(self) -> None:
        require(self._cam is not None, "renderer", "not drawing", "inside begin() ... end()")

    def _samples_ready(self):
        """The sample buffer, cleared if nothing has been drawn this frame."""
        self._require_frame()
        if self._uncleared:
            raster.clear(self._samples)
            self._uncleared = False
        return self._samples

    def end(self) -> np.ndarray:
        """Finish the frame: (height, width, 3) uint8 RGB, row 0 at the top."""
        return from_taichi(self.end_window())

    def end_window(self) -> np.ndarray:
        """Finish the frame as a window takes it (ti.GUI.set_image): (width, height, 3) uint8
        RGB, origin bottom-left, the renderer's own buffer (valid until the next frame ends).
        It skips the copy into image layout that end() makes (1.5 ms at 960 x 540)."""
        samples = self._samples_ready()
        bg = self.background
        raster.resolve(samples, self._image, bg.top, bg.bottom, self.supersample)
        self._cam = None
        return self._image

    def close(self) -> None:
        """Release the buffers; the renderer cannot be used after. ti_cloth.init calls it:
        the buffers belong to the runtime init ends."""
        self._scratch.clear()
        self._topologies.clear()
        self._samples = self._image = self._cam = self._shadow = self._light_cam = None
        self._ground = self._ground_key = None
        self._open = False

    # -- bodies -----------------------------------------------------------------------------

    def draw_mesh(self, positions, triangles, *, rest_positions=None, hidden=None, strain=None,
                  colours=None, style: SurfaceStyle = SurfaceStyle(),
                  collider: bool = False) -> None:
        """Triangles over `positions` [m] (N, 3); collider: drawn as a collider, pushed back
        by COLLIDER_DEPTH_BIAS. rest_positions (N, 3) carry the checker
        (without them an explicit style.checker follows the current positions, an automatic
        one is off);
        hidden: triangle indices or an (T,) bool mask not to draw (torn triangles);
        strain: (N,) per-particle strain when style.strain; colours: (N, 3) per-vertex RGB
        for both sides instead of style.front/back. `triangles` is taken as fixed
        topology: it is uploaded once per array object."""
        self._require_frame()
        x = as_array("positions", positions, np.float32, (None, 3))
        topology = self._topology(triangles, len(x))
        if topology.triangle_count == 0:
            return
        visible = np.ones(topology.triangle_count, np.int32)
        if hidden is not None:
            hidden = np.asarray(hidden)
            if hidden.dtype == bool:
                visible[as_array("hidden", hidden, bool, (topology.triangle_count,))] = 0
            else:
                hidden = as_array("hidden", hidden, np.int64, (None,))
                require(len(hidden) == 0 or (hidden.min() >= 0 and hidden.max() < len(visible)),
                        "hidden", hidden.tolist()[:5], f"triangle indices in [0, {len(visible) - 1}]")
                visible[hidden] = 0
        checker, rest = style.checker, None
        if rest_positions is not None:
            rest = as_array("rest_positions", rest_positions, np.float32, (len(x), 3))
            if checker is None:
                checker = float(np.ptp(rest, axis=0).max()) / 10
        elif checker:                   # asked for, but no rest shape: the current one
            rest = x
        if rest is None or not checker:
            rest, checker = np.zeros((1, 3), np.float32), 0.0
        if style.strain:
            require(strain is not None, "strain", None, "an (N,) array when style.strain is on")
            strain = as_array("strain", strain, np.float32, (len(x),))
        else:
            strain = np.zeros(1, np.float32)
        per_vertex = colours is not None
        colours = (self._colours("colours", colours, len(x)) if per_vertex
                   else np.zeros((1, 3), np.float32))
        position = self._upload("position", x)
        visible = self._upload("visible", visible)
        screen = self._buffer("screen", (len(x), 4))
        normal = self._buffer("normal", (len(x), 3))
        raster.vertex_stage(self._cam, position, topology.triangles, visible, topology.vertex_start,
                            topology.vertex_triangles, screen, normal)
        light, ss = self.light, self.supersample
        raster.raster_triangles(
            self._samples_ready(), self._cam, topology.triangles, visible, screen, normal,
            self._upload("rest", rest), self._upload("strain", strain),
            self._upload("vertex_colour", colours), style.front, style.back, style.wire_colour,
            light.direction, light.ambient, max(checker, 1e-9), style.checker_contrast,
            style.strain_max, style.wireframe * ss, 1.0 + COLLIDER_DEPTH_BIAS * collider,
            per_vertex, checker > 0, style.strain, style.wireframe > 0)

    def draw_lines(self, positions, segments, *, width: float = 2.0, colour=(0.25, 0.2, 0.15)) -> None:
        """Segments between `positions` [m] (N, 3), `width` pixels wide, lit as fibres;
        colour: one RGB or (N, 3) per vertex (interpolated along each segment)."""
        self._require_frame()
        x = as_array("positions", positions, np.float32, (None, 3))
        segments = as_array("segments", segments, np.int32, (None, 2))
        if len(segments) == 0:
            return
        require(segments.min() >= 0 and segments.max() < len(x), "segments",
                (int(segments.min()), int(segments.max())), f"indices in [0, {len(x) - 1}]")
        width = finite_number("width", width, 0.0, strict=True, unit="pixels")
        raster.raster_segments(self._samples_ready(), self._cam, self._upload("position", x),
                               self._upload("segments", segments),
                               self._upload("colour", self._colours("colour", colour, len(x))),
                               width * self.supersample, self.light.direction, self.light.ambient)

    def draw_points(self, positions, *, radius: float = 3.0, colour=(0.1, 0.1, 0.12)) -> None:
        """Flat discs `radius` pixels wide at `positions` [m]; colour: one RGB or (N, 3)."""
        self._require_frame()
        x = as_array("positions", positions, np.float32, (None, 3))
        radius = finite_number("radius", radius, 0.0, strict=True, unit="pixels")
        if len(x):
            raster.raster_discs(self._samples_ready(), self._cam, self._upload("position", x),
                                self._upload("colour", self._colours("colour", colour, len(x))),
                                radius * self.supersample, 1e-3)

    def draw_simulation(self, sim, style: SurfaceStyle = SurfaceStyle()) -> None:
        """The body of a Simulation at its current time: its triangles (torn ones dropped),
        and the stretch springs of particles on no triangle (strings, hair) as lines; plus
        particles. The checker follows the rest shape (a garment's: its flat pattern, as a print
        on the fabric). Ghost particles (cloth.ghost) and their springs are never drawn."""
        self._require_frame()
        cloth, x = sim.cloth, sim.positions()
        alive = sim.spring_alive()
        triangles = cloth.mesh.triangles
        if len(triangles):
            strain = (vertex_strain(x, cloth.spring_indices, cloth.spring_rest_length, alive)
                      if style.strain else None)
            self.draw_mesh(x, triangles, rest_positions=cloth.rest_position,
                           hidden=sim.torn_triangles(), strain=strain, style=style)
        on_surface = np.zeros(cloth.particle_count, bool)
        on_surface[triangles.ravel()] = True
        i, j = cloth.spring_indices.T
        shown = ~on_surface & ~cloth.ghost
        lines = alive & (cloth.spring_kind == SpringKind.STRETCH) & shown[i] & shown[j]
        if lines.any():
            self.draw_lines(x, cloth.spring_indices[lines], width=style.line_width, colour=style.front)
        if style.particles > 0:
            colours = np.where(sim.pinned()[:, None], style.pin_colour, style.particle_colour)
            drawn = ~cloth.ghost
            self.draw_points(x[drawn], radius=style.particles, colour=colours[drawn])

    # -- ground and colliders ---------------------------------------------------------------

    def cast_shadows(self, sim) -> None:
        """Let the bodies of `sim` and its colliders (not its planes) shade the ground and the
        planes drawn after this in the frame: the light's orthographic view of their bounds
        as a SHADOW_SIZE^2 depth map (drawn with this renderer's own passes)."""
        self._require_frame()
        solids = [c for c in sim.collider_shapes() if not isinstance(c, Plane)]
        x = sim.positions()[~sim.cloth.ghost]
        corners = [x] + [c.bounds() for c in solids]
        lo = np.min([c.min(axis=0) for c in corners if len(c)], axis=0)
        hi = np.max([c.max(axis=0) for c in corners if len(c)], axis=0)
        centre, radius = (lo + hi) / 2, max(float(np.linalg.norm(hi - lo)) / 2, 1e-3)
        towards = np.asarray(self.light.direction)
        up = np.eye(3)[np.argmin(np.abs(towards))]
        light = Camera(position=tuple(centre + 2 * radius * towards), target=tuple(centre),
                       up=tuple(up), orthographic=True, height=2.02 * radius, near=radius / 10)
        if self._shadow is None:
            self._shadow = ti.ndarray(ti.i64, (SHADOW_SIZE, SHADOW_SIZE))
        frame = (self._samples, self._cam, self._uncleared)
        self._samples, self._uncleared = self._shadow, True
        self._cam = self._upload("light camera", light.packed(SHADOW_SIZE, SHADOW_SIZE))
        try:
            if len(sim.cloth.mesh.triangles):
                self.draw_mesh(sim.positions(), sim.cloth.mesh.triangles,
                               hidden=sim.torn_triangles())
            self._draw_shapes(solids)
            self._samples_ready()
        finally:
            light_cam = self._cam
            self._samples, self._cam, self._uncleared = frame
        self._light_cam = light_cam

    def draw_colliders(self, sim) -> None:
        """Every collider of a Simulation where its path has it at the simulation's time; a
        plane collider in a plane drawn already this frame (the scene's ground, which is that
        plane) is not drawn again."""
        self._require_frame()
        self._draw_shapes(sim.collider_shapes())

    def _draw_shapes(self, colliders) -> None:
        for c in colliders:
            if isinstance(c, Plane):
                if not self._plane_drawn(c.point, c.normal):
                    self.draw_plane(c.point, c.normal)
            elif isinstance(c, Sphere):
                self.draw_sphere(c.centre, c.radius)
            elif isinstance(c, Box):
                self.draw_box(c.lo, c.hi)
            elif isinstance(c, Capsule):
                self.draw_capsule(c.a, c.b, c.radius)
            elif isinstance(c, (MeshCollider, AnimatedMeshCollider)):
                self.draw_mesh(c.mesh.vertices, c.mesh.triangles, colours=COLLIDER_COLOUR,
                               style=COLLIDER_STYLE, collider=True)

    def draw_plane(self, point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), *,
                   colour=(0.86, 0.87, 0.89), checker: float = 0.25, contrast: float = 0.12,
                   fade: float = 30.0) -> None:
        """The infinite plane through `point` [m] with `normal`; a checker of `checker` metres
        (0: plain) whose contrast fades to nothing at depth `fade` [m] (no moire at the horizon)."""
        self._require_frame()
        n = np.asarray(_unit("normal", normal))
        point = as_array("point", point, np.float64, (3,))
        helper = np.eye(3)[np.argmin(np.abs(n))]
        u = np.cross(n, helper)
        u /= np.linalg.norm(u)
        checker = finite_number("checker", checker, 0.0, unit="m")
        contrast = finite_number("contrast", contrast, 0.0)
        require(contrast <= 1, "contrast", contrast, "a number in [0, 1]")
        colour = _colour("colour", colour)
        fade = finite_number("fade", fade, 0.0, strict=True, unit="m")
        clear_first, self._uncleared = self._uncleared, False
        self._planes.append((n, float(n @ point)))
        shaded = self._light_cam is not None
        # A frame's first, unshaded plane fills every sample, from nothing but the camera,
        # the plane and the light: when they are the last such frame's, its samples are
        # copied instead of ray-cast again (the live viewer's ground, camera at rest).
        reusable = clear_first and not shaded
        key = (tuple(self._samples.shape), self._cam_packed.tobytes(), point.tobytes(),
               n.tobytes(), colour, checker, contrast, fade, self.light) if reusable else None
        if key is not None and key == self._ground_key:
            raster.copy(self._ground, self._samples)
            return
        shadow = self._shadow if shaded else self._samples
        shapes.raster_plane(self._samples, self._cam, point, n, u, np.cross(n, u), colour, checker,
                            contrast, fade, self.light.direction, self.light.ambient,
                            1.0 + COLLIDER_DEPTH_BIAS, shadow,
                            self._light_cam if shaded else self._cam, SHADOW_DARKNESS,
                            SHADOW_BIAS, shaded, clear_first)
        if key is not None:
            if self._ground is None or self._ground.shape != self._samples.shape:
                self._ground = ti.ndarray(ti.i64, self._samples.shape)
            raster.copy(self._samples, self._ground)
            self._ground_key = key

    def _plane_drawn(self, point, normal) -> bool:
        """Whether the plane through `point` with `normal` was drawn this frame (either side
        up; to 1e-9 m and 1e-9 in its normal)."""
        n = np.asarray(_unit("normal", normal))
        offset = float(n @ np.asarray(point, np.float64))
        return any(abs(abs(float(n @ m)) - 1.0) <= 1e-9 and abs(offset - float(n @ m) * c) <= 1e-9
                   for m, c in self._planes)

    def draw_sphere(self, centre, radius: float, *, colour=COLLIDER_COLOUR) -> None:
        """A sphere of `radius` [m] at `centre` [m]."""
        self._require_frame()
        centre = as_array("centre", centre, np.float64, (3,))
        self._draw_solid(SPHERE, centre, centre,
                         finite_number("radius", radius, 0.0, strict=True, unit="m"), colour)

    def draw_box(self, lo, hi, *, colour=COLLIDER_COLOUR) -> None:
        """The axis-aligned box between corners `lo` and `hi` [m]."""
        self._require_frame()
        lo, hi = as_array("lo", lo, np.float64, (3,)), as_array("hi", hi, np.float64, (3,))
        require(bool((hi > lo).all()), "hi", tuple(hi), f"greater than lo {tuple(lo)} on every axis")
        self._draw_solid(BOX, lo, hi, 0.0, colour)

    def draw_capsule(self, a, b, radius: float, *, colour=COLLIDER_COLOUR) -> None:
        """The capsule around segment a-b [m] with `radius` [m]."""
        self._require_frame()
        self._draw_solid(CAPSULE, as_array("a", a, np.float64, (3,)),
                         as_array("b", b, np.float64, (3,)),
                         finite_number("radius", radius, 0.0, strict=True, unit="m"), colour)

    def _draw_solid(self, shape: int, a, b, radius: float, colour) -> None:
        shapes.raster_solid(self._samples_ready(), self._cam, shape, a, b, radius,
                            _colour("colour", colour), self.light.direction, self.light.ambient,
                            1.0 + COLLIDER_DEPTH_BIAS)

    # -- buffers ----------------------------------------------------------------------------

    def _colours(self, field: str, colour, n: int) -> np.ndarray:
        c = np.asarray(colour, np.float64)
        if c.shape == (3,):
            c = np.broadcast_to(_colour(field, c), (n, 3))
        else:
            c = as_array(field, c, np.float64, (n, 3))
            require(bool(((c >= 0) & (c <= 1)).all()), field, "out of range", "RGB values in [0, 1]")
        return c.astype(np.float32)

    def _buffer(self, name: str, shape: tuple, dtype=ti.f32):
        """A scratch ndarray kept by name, shape and type: a frame that draws two meshes (a
        cloth and a mesh collider) reuses each one's buffers frame after frame instead of
        making new ones (about 0.3 ms each). At most SCRATCH_BUFFERS are kept."""
        key = (name, tuple(shape), dtype)
        nd = self._scratch.get(key)
        if nd is None:
            if len(self._scratch) >= SCRATCH_BUFFERS:
                self._scratch.clear()
            nd = self._scratch[key] = ti.ndarray(dtype, shape)
        return nd

    def _upload(self, name: str, array: np.ndarray):
        array = np.ascontiguousarray(array)
        nd = self._buffer(name, array.shape, taichi_dtype(array.dtype))
        nd.from_numpy(array)
        return nd

    def _topology(self, triangles, vertex_count: int) -> _Topology:
        key = (id(triangles), vertex_count)
        cached = self._topologies.get(key)
        if cached is not None and cached[0]() is triangles:
            return cached[1]
        topology = _Topology(triangles, vertex_count)
        self._topologies = {k: v for k, v in self._topologies.items() if v[0]() is not None}
        try:
            self._topologies[key] = (weakref.ref(triangles), topology)
        except TypeError:          # lists and tuples cannot be weakly referenced: no caching
            pass
        return topology


class NullRenderer:
    """The Renderer interface doing nothing: for tests and benchmarks that must not pay for
    drawing. `end` returns None; `frames` counts the frames begun and ended."""

    def __init__(self, width: int = 1280, height: int = 720, camera: Camera | None = None, *,
                 supersample: int = 2, light: Light = Light(), background: Background = Background()):
        self.width, self.height, self.camera = width, height, camera
        self.frames = 0

    def __enter__(self) -> NullRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def begin(self, camera: Camera | None = None) -> None:
        self.camera = camera or self.camera

    def end(self) -> None:
        self.frames += 1

    def end_window(self) -> None:
        self.frames += 1

    def close(self) -> None:
        pass

    def draw_mesh(self, positions, triangles, *, rest_positions=None, hidden=None, strain=None,
                  colours=None, style: SurfaceStyle = SurfaceStyle(),
                  collider: bool = False) -> None:
        pass

    def draw_lines(self, positions, segments, *, width: float = 2.0, colour=(0.25, 0.2, 0.15)) -> None:
        pass

    def draw_points(self, positions, *, radius: float = 3.0, colour=(0.1, 0.1, 0.12)) -> None:
        pass

    def draw_simulation(self, sim, style: SurfaceStyle = SurfaceStyle()) -> None:
        pass

    def cast_shadows(self, sim) -> None:
        pass

    def draw_colliders(self, sim) -> None:
        pass

    def draw_plane(self, point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), *,
                   colour=(0.86, 0.87, 0.89), checker: float = 0.25, contrast: float = 0.12,
                   fade: float = 30.0) -> None:
        pass

    def draw_sphere(self, centre, radius: float, *, colour=COLLIDER_COLOUR) -> None:
        pass

    def draw_box(self, lo, hi, *, colour=COLLIDER_COLOUR) -> None:
        pass

    def draw_capsule(self, a, b, radius: float, *, colour=COLLIDER_COLOUR) -> None:
        pass
