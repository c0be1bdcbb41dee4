"""The rasteriser: Taichi kernels that turn triangles, line segments and discs into samples.

Every sample holds one 64-bit key, (depth bits << 32) | packed RGB, and every primitive writes
with an atomic minimum: the nearest fragment wins whatever the order of submission (ties go to
the smaller colour, so a frame is the same bits every time). Depth is the distance along the
viewing direction [m]; a positive f32 orders like its bit pattern. Buffers are Taichi ndarrays, so
each kernel compiles once per process, whatever the resolution or the body.

Coverage (fill rule): a sample is covered when its centre (x + 0.5, y + 0.5) lies strictly
inside the triangle, or exactly on a top or left edge (the Direct3D/OpenGL top-left rule, in
screen terms: y up, so a left edge runs downwards and a top edge runs leftwards around the
counter-clockwise triangle). Each edge function is evaluated from the edge's lexicographically
smaller end, so the two triangles sharing an edge compute exactly opposite values: no sample
along a shared edge is skipped or drawn twice.

Triangles and segments with a vertex behind the camera's near plane are skipped, not clipped:
keep the camera outside the bodies it looks at.
"""

import taichi as ti

from ..runtime import backend

INF_BITS = 0x7F800000             # the bit pattern of f32 +inf
EMPTY = INF_BITS << 32             # +inf depth, black: "nothing drawn here"

ndarray_f32_1 = ti.types.ndarray(dtype=ti.f32, ndim=1)
ndarray_f32_2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
ndarray_i32_1 = ti.types.ndarray(dtype=ti.i32, ndim=1)
ndarray_i32_2 = ti.types.ndarray(dtype=ti.i32, ndim=2)
samples_type = ti.types.ndarray(dtype=ti.i64, ndim=2)


@ti.func
def row3(a: ti.template(), i):
    return ti.Vector([a[i, 0], a[i, 1], a[i, 2]])


@ti.func
def interpolate(a: ti.template(), ia, ib, ic, mu):
    """Rows ia, ib, ic of `a` (N, 3) weighted by the barycentric weights mu."""
    return mu[0] * row3(a, ia) + mu[1] * row3(a, ib) + mu[2] * row3(a, ic)


@ti.func
def camera_basis(cam: ti.template()):
    """eye, right, up, forward, as packed by Camera.packed."""
    return (ti.Vector([cam[0], cam[1], cam[2]]), ti.Vector([cam[3], cam[4], cam[5]]),
            ti.Vector([cam[6], cam[7], cam[8]]), ti.Vector([cam[9], cam[10], cam[11]]))


@ti.func
def project(cam: ti.template(), p):
    """World point -> (screen x, screen y, depth, 1/w) in samples, as Camera.project."""
    eye, right, up, forward = camera_basis(cam)
    v = p - eye
    depth = v.dot(forward)
    inv_w = 1.0 / depth if cam[15] == 0 else 1.0
    s = cam[12] * inv_w
    return ti.Vector([cam[13] + s * v.dot(right), cam[14] + s * v.dot(up), depth, inv_w])


@ti.func
def pack(depth, colour):
    """The sample key of a fragment at `depth` [m] with `colour` (RGB in [0, 1])."""
    rgb = ti.cast(ti.math.clamp(colour, 0.0, 1.0) * 255.0 + 0.5, ti.i64)
    bits = ti.cast(ti.bit_cast(ti.cast(depth, ti.f32), ti.i32), ti.i64)
    return (bits << 32) | rgb[0] | (rgb[1] << 8) | (rgb[2] << 16)


@ti.func
def lambert(albedo, normal, light, ambient):
    """Ambient plus diffuse (Lambert) shading; `light` points towards the light."""
    return albedo * (ambient + (1.0 - ambient) * ti.max(normal.dot(light), 0.0))


@ti.func
def drawable(depth, near) -> ti.i32:
    """In front of the near plane and finite (NaN fails both comparisons)."""
    return depth > near and depth < 3.0e38


@ti.func
def edge(p, q, x):
    """Twice the signed area of (p, q, x), evaluated from the smaller of p, q (see module doc)."""
    result = 0.0
    if p[0] < q[0] or (p[0] == q[0] and p[1] < q[1]):
        result = (q[0] - p[0]) * (x[1] - p[1]) - (q[1] - p[1]) * (x[0] - p[0])
    else:
        result = -((p[0] - q[0]) * (x[1] - q[1]) - (p[1] - q[1]) * (x[0] - q[0]))
    return result


@ti.func
def covers(w, p, q) -> ti.i32:
    """Edge p -> q of a counter-clockwise triangle covers a centre with edge value w."""
    d = q - p
    return w > 0 or (w == 0 and (d[1] < 0 or (d[1] == 0 and d[0] < 0)))


@ti.func
def bounding_box(lo, hi, samples: ti.template()):
    """Sample index ranges [x0, x1) x [y0, y1) whose centres can lie in [lo, hi]."""
    x0 = ti.max(ti.cast(ti.floor(lo[0] - 0.5), ti.i32), 0)
    y0 = ti.max(ti.cast(ti.floor(lo[1] - 0.5), ti.i32), 0)
    x1 = ti.min(ti.cast(ti.ceil(hi[0] - 0.5), ti.i32) + 1, samples.shape[0])
    y1 = ti.min(ti.cast(ti.ceil(hi[1] - 0.5), ti.i32) + 1, samples.shape[1])
    return x0, x1, y0, y1


@backend.kernel
def clear(samples: samples_type):
    for i in range(samples.shape[0]):        # columns in parallel, rows in a serial loop
        for j in range(samples.shape[1]):
            samples[i, j] = ti.i64(EMPTY)


@backend.kernel
def copy(source: samples_type, target: samples_type):
    for i in range(source.shape[0]):
        for j in range(source.shape[1]):
            target[i, j] = source[i, j]


@backend.kernel
def vertex_stage(cam: ndarray_f32_1, position: ndarray_f32_2, triangles: ndarray_i32_2,
                 visible: ndarray_i32_1, vertex_start: ndarray_i32_1,
                 vertex_triangles: ndarray_i32_1, screen: ndarray_f32_2, normal: ndarray_f32_2):
    """Project every vertex; its normal is the area-weighted sum of its visible triangles'
    normals, gathered (not scattered) so it is the same bits on every run."""
    for v in range(position.shape[0]):
        s = project(cam, row3(position, v))
        for k in ti.static(range(4)):
            screen[v, k] = s[k]
        n = ti.Vector([0.0, 0.0, 0.0])
        for k in range(vertex_start[v], vertex_start[v + 1]):
            t = vertex_triangles[k]
            if visible[t] != 0:
                a = row3(position, triangles[t, 0])
                n += (row3(position, triangles[t, 1]) - a).cross(row3(position, triangles[t, 2]) - a)
        length = n.norm()
        if length > 0:
            n /= length
        for k in ti.static(range(3)):
            normal[v, k] = n[k]


@ti.func
def checker_factor(rest_point, size, contrast):
    """1 on even cells of a 3-D checker of cell `size` [m], 1 - contrast on odd ones. A flat
    rest shape often lies on a cell boundary (a sheet at y = 0.7 with 0.1 m cells): nudged by
    1e-4 cell, such a plane falls in one cell instead of flickering between two sample by
    sample with the rounding of the interpolated rest point."""
    cell = ti.cast(ti.floor(rest_point / size + 1e-4), ti.i32)
    return 1.0 - contrast * ((cell[0] + cell[1] + cell[2]) & 1)


@ti.func
def strain_ramp(strain, strain_max):
    """Blue (unstretched) -> yellow (half of strain_max) -> red (strain_max and beyond)."""
    t = ti.math.clamp(strain / strain_max, 0.0, 1.0)
    cold, warm, hot = ti.Vector([0.2, 0.35, 0.85]), ti.Vector([0.95, 0.85, 0.25]), ti.Vector([0.85, 0.1, 0.1])
    return ti.math.mix(cold, warm, 2 * t) if t < 0.5 else ti.math.mix(warm, hot, 2 * t - 1)


@backend.kernel
def raster_triangles(samples: samples_type, cam: ndarray_f32_1, triangles: ndarray_i32_2,
                     visible: ndarray_i32_1, screen: ndarray_f32_2, normal: ndarray_f32_2,
                     rest: ndarray_f32_2, strain: ndarray_f32_1, vertex_colour: ndarray_f32_2,
                     front: ti.math.vec3, back: ti.math.vec3, wire: ti.math.vec3,
                     light: ti.math.vec3, ambient: float, checker_size: float,
                     checker_contrast: float, strain_max: float, wire_width: float,
                     depth_scale: float, use_colours: ti.template(), use_checker: ti.template(),
                     use_strain: ti.template(), use_wire: ti.template()):
    """Shade and depth-test every covered sample of every visible triangle. Counter-clockwise
    on screen is the front face; back faces get `back` and their normal flipped to the viewer.
    The base colour is front/back, or per-vertex colours, or the strain ramp; the checker
    darkens it; wireframe replaces it near edges; depths are taken times `depth_scale` (a
    collider's: renderer.COLLIDER_DEPTH_BIAS). Attributes are interpolated
    perspective-correctly."""
    for t in range(triangles.shape[0]):
        if visible[t] != 0:
            ia, ib, ic = triangles[t, 0], triangles[t, 1], triangles[t, 2]
            sa, sb, sc = ti.Vector([screen[ia, 0], screen[ia, 1]]), ti.Vector(
                [screen[ib, 0], screen[ib, 1]]), ti.Vector([screen[ic, 0], screen[ic, 1]])
            area = (sb - sa).cross(sc - sa)
            near = cam[16]
            if (drawable(screen[ia, 2], near) and drawable(screen[ib, 2], near)
                    and drawable(screen[ic, 2], near) and area != 0):
                facing = 1.0
                albedo = front
                if area < 0:                       # back face: make it counter-clockwise
                    ib, ic = ic, ib
                    sb, sc = sc, sb
                    area, facing, albedo = -area, -1.0, back
                x0, x1, y0, y1 = bounding_box(ti.min(sa, sb, sc), ti.max(sa, sb, sc), samples)
                for x in range(x0, x1):
                    for y in range(y0, y1):
                        centre = ti.Vector([x + 0.5, y + 0.5])
                        wa = edge(sb, sc, centre)
                        wb, wc = edge(sc, sa, centre), edge(sa, sb, centre)
                        if covers(wa, sb, sc) and covers(wb, sc, sa) and covers(wc, sa, sb):
                            q = ti.Vector([wa * screen[ia, 3], wb * screen[ib, 3],
                                           wc * screen[ic, 3]])
                            mu = q / q.sum()
                            depth = mu.dot(ti.Vector([screen[ia, 2], screen[ib, 2],
                                                      screen[ic, 2]]))
                            n = interpolate(normal, ia, ib, ic, mu)
                            # opposite normals at a crease: 0
                            n *= facing / ti.max(n.norm(), 1e-12)
                            colour = albedo
                            if ti.static(use_colours):
                                colour = interpolate(vertex_colour, ia, ib, ic, mu)
                            if ti.static(use_strain):
                                corners = ti.Vector([strain[ia], strain[ib], strain[ic]])
                                colour = strain_ramp(mu.dot(corners), strain_max)
                            if ti.static(use_checker):
                                colour *= checker_factor(interpolate(rest, ia, ib, ic, mu),
                                                         checker_size, checker_contrast)
                            colour = lambert(colour, n, light, ambient)
                            if ti.static(use_wire):    # distance to the nearest edge, in samples
                                dist = ti.min(wa / (sc - sb).norm(), wb / (sa - sc).norm(),
                                              wc / (sb - sa).norm())
                                if dist < wire_width / 2:
                                    colour = wire
                            ti.atomic_min(samples[x, y], pack(depth * depth_scale, colour))


@backend.kernel
def raster_segments(samples: samples_type, cam: ndarray_f32_1, position: ndarray_f32_2,
                    segments: ndarray_i32_2, colour: ndarray_f32_2, width: float,
                    light: ti.math.vec3, ambient: float):
    """Line segments `width` samples wide (round caps), coloured per vertex and lit as thin
    fibres (Kajiya-Kay diffuse: the sine of the angle between the segment and the light)."""
    for s in range(segments.shape[0]):
        i, j = segments[s, 0], segments[s, 1]
        pa, pb = row3(position, i), row3(position, j)
        a, b = project(cam, pa), project(cam, pb)
        near = cam[16]
        if drawable(a[2], near) and drawable(b[2], near):
            sa, sb = ti.Vector([a[0], a[1]]), ti.Vector([b[0], b[1]])
            tangent = (pb - pa).normalized()
            fibre = ti.sqrt(ti.max(1.0 - tangent.dot(light) ** 2, 0.0))
            half = width / 2
            x0, x1, y0, y1 = bounding_box(ti.min(sa, sb) - half, ti.max(sa, sb) + half, samples)
            d = sb - sa
            for x in range(x0, x1):
                for y in range(y0, y1):
                    centre = ti.Vector([x + 0.5, y + 0.5])
                    u = 0.0
                    if d.norm_sqr() > 0:
                        u = ti.math.clamp((centre - sa).dot(d) / d.norm_sqr(), 0.0, 1.0)
                    if (centre - sa - u * d).norm_sqr() <= half * half:
                        q = ti.Vector([(1 - u) * a[3], u * b[3]])
                        mu = q / q.sum()
                        c = mu[0] * row3(colour, i) + mu[1] * row3(colour, j)
                        shaded = c * (ambient + (1.0 - ambient) * fibre)
                        ti.atomic_min(samples[x, y], pack(mu[0] * a[2] + mu[1] * b[2], shaded))


@backend.kernel
def raster_discs(samples: samples_type, cam: ndarray_f32_1, position: ndarray_f32_2,
                 colour: ndarray_f32_2, radius: float, depth_bias: float):
    """Flat discs of `radius` samples at points, pulled `depth_bias` (a fraction of their
    depth) towards the camera so particles on a surface stay visible."""
    for i in range(position.shape[0]):
        p = project(cam, row3(position, i))
        if drawable(p[2], cam[16]):
            s = ti.Vector([p[0], p[1]])
            x0, x1, y0, y1 = bounding_box(s - radius, s + radius, samples)
            key = pack(p[2] * (1.0 - depth_bias), row3(colour, i))
            for x in range(x0, x1):
                for y in range(y0, y1):
                    if (ti.Vector([x + 0.5, y + 0.5]) - s).norm_sqr() <= radius * radius:
                        ti.atomic_min(samples[x, y], key)


@backend.kernel
def resolve(samples: samples_type, image: ti.types.ndarray(dtype=ti.u8, ndim=3),
            top: ti.math.vec3, bottom: ti.math.vec3, supersample: ti.i32):
    """Average supersample x supersample samples per pixel (a box filter); empty samples show
    the vertical background gradient. Writes (width, height, 3) uint8, origin bottom-left."""
    for x in range(image.shape[0]):           # columns in parallel, rows in a serial loop
        for y in range(image.shape[1]):
            background = ti.math.mix(bottom, top, (y + 0.5) / image.shape[1])
            total = ti.Vector([0.0, 0.0, 0.0])
            for i in range(supersample):
                for j in range(supersample):
                    key = samples[x * supersample + i, y * supersample + j]
                    if (key >> 32) == INF_BITS:
                        total += background
                    else:
                        total += ti.Vector([key & 255, (key >> 8) & 255, (key >> 16) & 255]) / 255.0
            rgb = total / (supersample * supersample)
            for k in ti.static(range(3)):
                image[x, y, k] = ti.cast(ti.math.clamp(rgb[k], 0.0, 1.0) * 255.0 + 0.5, ti.u8)
