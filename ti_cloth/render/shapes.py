"""Ground plane and collider shapes, ray-cast per sample instead of tessellated: exact
silhouettes, an infinite plane up to the horizon, and depths comparable with the rasterised
cloth (both are distances along the viewing direction), merged by the same minimum of keys.
Each sample belongs to one thread here, so a plain minimum replaces the atomic one."""

import taichi as ti

from ..contact.colliders.shapes import BOX, SPHERE
from ..runtime import backend
from .raster import EMPTY, camera_basis, lambert, ndarray_f32_1, pack, project, samples_type

MISS = -1.0


@ti.func
def camera_values(cam: ti.template()):
    """The packed camera (Camera.packed) as a local vector: read once per column of samples,
    where the loop over them would read the ndarray again for every sample (the compiler
    cannot assume the samples written do not alias it)."""
    return ti.Vector([cam[k] for k in ti.static(range(17))])


@ti.func
def camera_ray(cam: ti.template(), x, y):
    """Ray through the centre of sample (x, y): origin and direction, scaled so that its
    component along the viewing direction is 1 (t is then the depth)."""
    eye, right, up, forward = camera_basis(cam)
    u = (x + 0.5 - cam[13]) / cam[12]
    v = (y + 0.5 - cam[14]) / cam[12]
    origin, direction = eye, forward + u * right + v * up
    if cam[15] != 0:
        origin, direction = eye + u * right + v * up, forward
    return origin, direction


@ti.func
def unit_camera_ray(cam: ti.template(), x, y):
    """camera_ray with a unit direction, and the depth per unit of its parameter t."""
    origin, direction = camera_ray(cam, x, y)
    length = direction.norm()
    return origin, direction / length, 1.0 / length


@ti.func
def hit_sphere(o, d, centre, radius):
    """Nearest t >= 0 where o + t d (|d| = 1) meets the sphere, else MISS; with the normal."""
    oc = o - centre
    b = oc.dot(d)
    h = b * b - (oc.norm_sqr() - radius * radius)
    t = MISS
    if h >= 0:
        t = -b - ti.sqrt(h)
    return t, (o + t * d - centre) / radius


@ti.func
def hit_box(o, d, lo, hi):
    """Slab test against the axis-aligned box [lo, hi]; t of entry (or MISS) and its normal."""
    inv = 1.0 / ti.select(ti.abs(d) > 1e-12, d, 1e-12)
    t1, t2 = (lo - o) * inv, (hi - o) * inv
    t_min, t_max = ti.min(t1, t2), ti.max(t1, t2)
    entry, leave = ti.max(t_min[0], t_min[1], t_min[2]), ti.min(t_max[0], t_max[1], t_max[2])
    normal = ti.Vector([0.0, 0.0, 0.0])
    for k in ti.static(range(3)):
        if t_min[k] == entry:
            normal = ti.Vector([0.0, 0.0, 0.0])
            normal[k] = -1.0 if d[k] > 0 else 1.0
    return ti.select(entry <= leave and entry >= 0, entry, MISS), normal


@ti.func
def hit_capsule(o, d, a, b, radius):
    """Ray against the capsule of segment a-b and `radius` (Quilez's closed form): the body's
    quadratic, then the nearer end sphere; t (or MISS) and the normal."""
    ba, oa = b - a, o - a
    baba, bard, baoa = ba.dot(ba), ba.dot(d), ba.dot(oa)
    k2 = baba - bard * bard
    k1 = baba * oa.dot(d) - baoa * bard
    k0 = baba * oa.dot(oa) - baoa * baoa - radius * radius * baba
    t = MISS
    h = k1 * k1 - k2 * k0
    if h >= 0 and k2 > 1e-12:
        t_body = (-k1 - ti.sqrt(h)) / k2
        along = baoa + t_body * bard
        if along > 0 and along < baba:
            t = t_body
    if t == MISS:
        end_a, _ = hit_sphere(o, d, a, radius)
        end_b, _ = hit_sphere(o, d, b, radius)
        t = ti.select(end_a >= 0 and (end_b < 0 or end_a < end_b), end_a, end_b)
    p = o + t * d - a
    normal = (p - ba * ti.math.clamp(p.dot(ba) / ti.max(baba, 1e-12), 0.0, 1.0)) / radius
    return t, normal


@ti.func
def hit_key(t, depth_per_t, near, colour):
    """The sample key of a hit at ray parameter t (EMPTY for a miss or a hit behind `near`)."""
    key = ti.i64(EMPTY)
    depth = t * depth_per_t
    if t >= 0 and depth > near:
        key = pack(depth, colour)
    return key


@ti.func
def plot_hit(samples: ti.template(), x, y, t, depth_per_t, near, colour):
    samples[x, y] = ti.min(samples[x, y], hit_key(t, depth_per_t, near, colour))


@ti.func
def shadowed(shadow: ti.template(), light_cam: ti.template(), p, bias):
    """How much of point p the light does not see: whether each of the four shadow-map
    texels round p's projection holds something nearer the light than p (by more than
    `bias` [m]), weighted bilinearly (percentage-closer filtering: a soft edge a texel
    wide). 0 outside the map."""
    s = project(light_cam, p)
    fx, fy = s[0] - 0.5, s[1] - 0.5
    x, y = ti.cast(ti.floor(fx), ti.i32), ti.cast(ti.floor(fy), ti.i32)
    hidden = 0.0
    if -1 <= x < shadow.shape[0] and -1 <= y < shadow.shape[1]:
        ax, ay = fx - x, fy - y
        for dx, dy in ti.static(ti.ndrange(2, 2)):
            u, v = x + dx, y + dy
            if 0 <= u < shadow.shape[0] and 0 <= v < shadow.shape[1]:
                depth = ti.bit_cast(ti.cast(shadow[u, v] >> 32, ti.i32), ti.f32)
                if depth < s[2] - bias:
                    hidden += (ax if dx else 1.0 - ax) * (ay if dy else 1.0 - ay)
    return hidden


@backend.kernel
def raster_plane(samples: samples_type, cam: ndarray_f32_1, point: ti.math.vec3,
                 normal: ti.math.vec3, axis_u: ti.math.vec3, axis_v: ti.math.vec3,
                 colour: ti.math.vec3, cell: float, contrast: float, fade: float,
                 light: ti.math.vec3, ambient: float, depth_scale: float,
                 shadow: samples_type, light_cam: ndarray_f32_1, darkness: float, bias: float,
                 shadows: ti.template(), clear_first: ti.template()):
    """The infinite plane through `point` with unit `normal`, lit from either side, with a
    checker of `cell` metres along axis_u, axis_v (0: plain) fading to its mean by depth
    `fade` [m] and where a sample's footprint on the plane nears a cell (no aliasing),
    its depths times `depth_scale` (> 1: behind what touches it, renderer.COLLIDER_DEPTH_BIAS).
    shadows: the light's shadow map (`shadow`, seen by `light_cam`) darkens it by `darkness`
    where it is covered (shadowed). clear_first: the frame's clear fused into this pass (one
    sweep over the samples, not two)."""
    for x in range(samples.shape[0]):      # columns in parallel, rows serially
        view, light_view = camera_values(cam), camera_values(light_cam)
        for y in range(samples.shape[1]):
            o, d = camera_ray(view, x, y)
            denominator = d.dot(normal)
            key = ti.i64(EMPTY)
            if ti.abs(denominator) > 1e-9:
                t = (point - o).dot(normal) / denominator
                if t >= 0 and t * depth_scale > view[16]:    # a hit in front: shaded
                    albedo = colour
                    if cell > 0:
                        p = o + t * d - point
                        cells = ti.cast(ti.floor(p.dot(axis_u) / cell), ti.i32) + ti.cast(
                            ti.floor(p.dot(axis_v) / cell), ti.i32)
                        # a sample's footprint on the plane [m]: its size at depth t, stretched
                        # by the grazing angle; the checker fades to its mean as the footprint
                        # nears a cell (a box filter's limit: no aliasing)
                        size = ti.select(view[15] != 0, 1.0, t) / view[12]
                        footprint = size * d.norm() / ti.abs(denominator)
                        weight = contrast * ti.max(ti.min(1.0 - t / fade, 1.0 - footprint / cell),
                                                   0.0)
                        albedo = colour * (1.0 - 0.5 * contrast + weight * (0.5 - (cells & 1)))
                    if ti.static(shadows):
                        albedo *= 1.0 - darkness * shadowed(shadow, light_view, o + t * d, bias)
                    facing = -ti.math.sign(denominator)
                    key = hit_key(t, depth_scale, view[16],
                                  lambert(albedo, normal * facing, light, ambient))
            if ti.static(clear_first):
                samples[x, y] = key
            else:
                samples[x, y] = ti.min(samples[x, y], key)


@backend.kernel
def raster_solid(samples: samples_type, cam: ndarray_f32_1, shape: ti.template(),
                 a: ti.math.vec3, b: ti.math.vec3, radius: float, colour: ti.math.vec3,
                 light: ti.math.vec3, ambient: float, depth_scale: float):
    """A sphere (centre a, radius), a box (corners a, b) or a capsule (segment a-b, radius);
    `shape` (colliders.SPHERE, BOX or CAPSULE) picks the ray test at compile time; depths
    times `depth_scale`, as raster_plane's."""
    for x in range(samples.shape[0]):      # columns in parallel, rows serially
        view = camera_values(cam)
        for y in range(samples.shape[1]):
            o, d, depth_per_t = unit_camera_ray(view, x, y)
            t, n = MISS, ti.Vector([0.0, 0.0, 0.0])
            if ti.static(shape == SPHERE):
                t, n = hit_sphere(o, d, a, radius)
            elif ti.static(shape == BOX):
                t, n = hit_box(o, d, a, b)
            else:
                t, n = hit_capsule(o, d, a, b, radius)
            plot_hit(samples, x, y, t, depth_per_t * depth_scale, view[16],
                     lambert(colour, n, light, ambient))
