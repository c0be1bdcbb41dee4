"""The rasteriser against closed forms: pixel coverage under the documented fill rule, depth
order, faces, layout, supersampling, perspective-correct interpolation and the ray-cast shapes.

Most scenes use a pixel-aligned orthographic camera (world x, y in metres = screen x, y in
pixels, bottom-left origin), no supersampling, and ambient light 1 so every colour is exact.
"""

import imageio.v3 as iio
import numpy as np
import pytest
from helpers import report

import ti_cloth as tc
from ti_cloth.render import Background, Camera, Light, Renderer, SurfaceStyle, write_png

RED, GREEN, BLUE = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
FLAT = Light(ambient=1.0)
BLACK = Background(top=(0.0, 0.0, 0.0), bottom=(0.0, 0.0, 0.0))


def pixel_camera(width, height, z=10.0):
    """Orthographic, looking down -z: world (x, y) lands on screen pixel coordinates (x, y)."""
    return Camera(position=(width / 2, height / 2, z), target=(width / 2, height / 2, 0.0),
                  orthographic=True, height=float(height))


def flat_renderer(width, height, supersample=1, camera=None):
    return Renderer(width, height, camera or pixel_camera(width, height), supersample=supersample,
                    light=FLAT, background=BLACK)


def style(front=RED, back=BLUE):
    return SurfaceStyle(front=front, back=back, checker=0.0)


def draw(renderer, *meshes):
    """meshes: (vertices (N, 3), triangles, style); returns the image with y up: [y, x]."""
    renderer.begin()
    for vertices, triangles, s in meshes:
        renderer.draw_mesh(np.asarray(vertices, float), np.asarray(triangles), style=s)
    return renderer.end()[::-1]


def mask(image_y_up, colour):
    return np.all(image_y_up == np.round(np.asarray(colour) * 255).astype(np.uint8), axis=2)


def test_one_triangle_covers_the_pixels_the_fill_rule_says(f32):
    # right triangle with legs of 4 px from (1, 1): centres (x + .5, y + .5) are strictly inside
    # for x' + y' <= 2 (6 pixels); the 4 centres with x' + y' = 3 lie on the hypotenuse, a right
    # edge: not drawn. The mirror triangle has it as a left edge: its 10 pixels include them.
    r = flat_renderer(8, 8)
    lower = [[1, 1, 0], [5, 1, 0], [1, 5, 0]]
    upper = [[5, 1, 0], [5, 5, 0], [1, 5, 0]]
    a = mask(draw(r, (lower, [[0, 1, 2]], style())), RED)
    b = mask(draw(r, (upper, [[0, 1, 2]], style())), RED)
    y, x = np.mgrid[0:8, 0:8] - 1
    square = (x >= 0) & (x < 4) & (y >= 0) & (y < 4)
    report("pixels", (int(a.sum()), int(b.sum())), (6, 10))
    assert np.array_equal(a, square & (x + y <= 2))
    assert np.array_equal(b, square & (x + y >= 3))
    both = mask(draw(r, (lower + upper, [[0, 1, 2], [3, 4, 5]], style())), RED)
    assert np.array_equal(both, square)


def test_a_triangle_covers_what_its_back_face_covers(f32):
    r = flat_renderer(8, 8)
    front = mask(draw(r, ([[1, 1, 0], [5, 1, 0], [1, 5, 0]], [[0, 1, 2]], style())), RED)
    back = mask(draw(r, ([[1, 1, 0], [5, 1, 0], [1, 5, 0]], [[0, 2, 1]], style())), BLUE)
    assert front.sum() == 6 and np.array_equal(front, back)


def jittered_grid(n, size, seed):
    """A triangulated n x n grid over [2, 2 + size]^2 px; interior vertices moved randomly,
    a third of them snapped onto pixel centres so many samples lie exactly on edges."""
    mesh = tc.grid_mesh(n, n, size=(size, size), plane="xy", origin=(2.0, 2.0, 0.0))
    v = mesh.vertices.copy()
    rng = np.random.default_rng(seed)
    interior = np.flatnonzero((v[:, 0] > 2) & (v[:, 0] < 2 + size) & (v[:, 1] > 2) & (v[:, 1] < 2 + size))
    v[interior, :2] += rng.uniform(-0.3, 0.3, (len(interior), 2)) * size / (n - 1)
    snap = interior[::3]
    v[snap, :2] = np.floor(v[snap, :2]) + 0.5
    return v, mesh.triangles


@pytest.mark.parametrize("seed", [0, 1])
def test_triangles_sharing_edges_leave_no_crack_and_no_double_cover(f32, seed):
    v, triangles = jittered_grid(5, 20.0, seed)
    r = flat_renderer(24, 24)
    images = [draw(r, (v, [t], style())) for t in triangles]
    count = sum(mask(i, RED).astype(int) + mask(i, BLUE).astype(int) for i in images)
    y, x = np.mgrid[0:24, 0:24]
    inside = (x >= 2) & (x < 22) & (y >= 2) & (y < 22)   # centres strictly inside the outline
    report("coverage counts inside / outside", (np.unique(count[inside]), np.unique(count[~inside])),
           ([1], [0]))
    assert np.all(count[inside] == 1) and np.all(count[~inside] == 0)
    whole = draw(r, (v, triangles, style()))
    assert np.array_equal(mask(whole, RED) | mask(whole, BLUE), inside)


@pytest.mark.parametrize("camera", ["orthographic", "perspective"])
def test_nearer_triangle_wins_whatever_the_order(f32, camera):
    cam = pixel_camera(16, 16) if camera == "orthographic" else Camera(
        position=(8, 8, 30), target=(8, 8, 0), fov=40.0)
    r = flat_renderer(16, 16, camera=cam)
    far = ([[2, 2, 0], [14, 2, 0], [2, 14, 0]], [[0, 1, 2]], style(RED, RED))
    near = ([[4, 4, 1], [15, 6, 1], [6, 15, 1]], [[0, 1, 2]], style(GREEN, GREEN))
    one_call = [[2, 2, 0], [14, 2, 0], [2, 14, 0], [4, 4, 1], [15, 6, 1], [6, 15, 1]]
    colours = [RED] * 3 + [GREEN] * 3                     # per-vertex colours, one draw call
    images = [draw(r, far, near), draw(r, near, far)]
    assert np.array_equal(images[0], images[1])
    overlap = mask(draw(r, far), RED) & mask(draw(r, near), GREEN)
    assert overlap.sum() > 10 and mask(images[0], GREEN)[overlap].all()
    for triangles in ([[0, 1, 2], [3, 4, 5]], [[3, 4, 5], [0, 1, 2]]):
        r.begin()
        r.draw_mesh(np.array(one_call, float), triangles, colours=colours, style=style())
        assert np.array_equal(r.end()[::-1], images[0])


def test_back_face_gets_the_back_colour_and_front_face_the_front(f32):
    r = flat_renderer(8, 8)
    ccw = draw(r, ([[1, 1, 0], [7, 1, 0], [1, 7, 0]], [[0, 1, 2]], style(RED, BLUE)))
    cw = draw(r, ([[1, 1, 0], [7, 1, 0], [1, 7, 0]], [[0, 2, 1]], style(RED, BLUE)))
    assert mask(ccw, RED).sum() > 0 and not mask(ccw, BLUE).any()
    assert mask(cw, BLUE).sum() == mask(ccw, RED).sum() and not mask(cw, RED).any()


def test_back_face_is_lit_with_its_normal_flipped_towards_the_viewer(f32):
    light = Light(direction=(0.0, 0.0, 1.0), ambient=0.2)    # towards the camera
    r = Renderer(8, 8, pixel_camera(8, 8), supersample=1, light=light, background=BLACK)
    for triangle in ([0, 1, 2], [0, 2, 1]):
        r.begin()
        r.draw_mesh(np.array([[1, 1, 0], [7, 1, 0], [1, 7, 0.0]]), [triangle], style=style(RED, RED))
        pixel = r.end()[::-1][2, 2]
        report(f"winding {triangle}", pixel.tolist(), [255, 0, 0])
        assert pixel.tolist() == [255, 0, 0]        # fully lit from the viewer's side, both ways


def test_top_left_of_the_view_is_the_top_left_of_the_array_and_the_png(f32, tmp_path):
    w, h = 40, 30
    r = flat_renderer(w, h)
    r.begin()
    r.draw_mesh(np.array([[0, h, 0], [8, h, 0], [0, h - 6, 0.0]]), [[0, 2, 1]], style=style(RED, RED))
    image = r.end()                                   # top-left origin, as numpy shows it
    rows, cols = np.nonzero(mask(image, RED))
    report("red rows, cols", (rows.min(), rows.max(), cols.min(), cols.max()), "rows < 6, cols < 8")
    assert image.shape == (h, w, 3) and rows.min() == 0 and cols.min() == 0
    assert rows.max() < 6 and cols.max() < 8
    png = iio.imread(write_png(tmp_path / "frame.png", image))
    assert np.array_equal(png, image)


def test_supersampling_averages_a_half_covered_pixel(f32):
    # a square with its right edge at x = 2.5: with 2 x 2 samples per pixel, pixel 2 has
    # sample centres at 2.25 (inside) and 2.75 (outside): exactly half red
    r = flat_renderer(5, 4, supersample=2)
    image = draw(r, ([[0, 0, 0], [2.5, 0, 0], [2.5, 4, 0], [0, 4, 0]], [[0, 1, 2], [0, 2, 3]],
                     style(RED, RED)))
    report("pixels 1, 2, 3 of row 1", image[1, 1:4, 0].tolist(), [255, 128, 0])
    assert image[1, 1, 0] == 255 and image[1, 3, 0] == 0
    assert abs(int(image[1, 2, 0]) - 127.5) <= 0.5 and image[1, 2, 1] == 0


def test_checker_is_interpolated_perspective_correctly(f32):
    # a floor receding from the camera, chequered in 1 m cells on its rest coordinates; the
    # middle column sees world x = 0.5 at every depth, so its colour flips exactly on the rows
    # where the lines z = 0, -1, ... project (screen-space interpolation would miss them)
    cam = Camera(position=(0.5, 1.0, 2.0), target=(0.5, 0.0, -2.0), fov=60.0)
    w, h = 64, 48
    r = Renderer(w, h, cam, supersample=1, light=FLAT, background=BLACK)
    floor = np.array([[-2, 0, 0.5], [3, 0, 0.5], [3, 0, -5.5], [-2, 0, -5.5]], float)
    r.begin()
    r.draw_mesh(floor, [[0, 1, 2], [0, 2, 3]], rest_positions=floor,
                style=SurfaceStyle(front=GREEN, back=GREEN, checker=1.0, checker_contrast=0.5))
    green = r.end()[::-1][:, w // 2, 1].astype(int)
    on_floor = green > 0
    flips = [y for y in range(1, h) if on_floor[y - 1] and on_floor[y] and green[y] != green[y - 1]]
    boundary_rows = cam.project([[0.5, 0.0, -k] for k in range(6)], w, h)[0][:, 1]
    expected = [int(np.floor(y + 0.5)) for y in boundary_rows if 1 <= y + 0.5 < h]
    report("colour flips at rows", flips, expected)
    assert flips == expected


def test_ray_cast_sphere_and_rasterised_triangle_share_one_depth(f32):
    # a sphere of radius 6 px centred on a triangle's plane: inside its silhouette the sphere's
    # front half is nearer; outside, the triangle shows
    r = flat_renderer(24, 24)
    r.begin()
    r.draw_mesh(np.array([[0, 0, 0], [24, 0, 0], [0, 24, 0], [24, 24, 0.0]]), [[0, 1, 2], [1, 3, 2]],
                style=style(RED, RED))
    r.draw_sphere((12.0, 12.0, 0.0), 6.0, colour=GREEN)
    image = r.end()[::-1]
    y, x = np.mgrid[0:24, 0:24] + 0.5
    disc = (x - 12) ** 2 + (y - 12) ** 2 <= 36
    report("sphere pixels", int(mask(image, GREEN).sum()), int(disc.sum()))
    assert np.array_equal(mask(image, GREEN), disc) and np.array_equal(mask(image, RED), ~disc)


def test_box_and_capsule_silhouettes(f32):
    r = flat_renderer(32, 32)
    r.begin()
    r.draw_box((4.0, 4.0, -3.0), (12.0, 20.0, 3.0), colour=RED)
    r.draw_capsule((20.0, 8.0, 0.0), (20.0, 24.0, 0.0), 4.0, colour=GREEN)
    image = r.end()[::-1]
    y, x = np.mgrid[0:32, 0:32] + 0.5
    box = (x > 4) & (x < 12) & (y > 4) & (y < 20)
    capsule = (np.abs(x - 20) ** 2 + np.maximum(np.maximum(8 - y, y - 24), 0) ** 2) <= 16
    report("box, capsule pixels", (int(mask(image, RED).sum()), int(mask(image, GREEN).sum())),
           (int(box.sum()), int(capsule.sum())))
    assert np.array_equal(mask(image, RED), box)
    assert np.array_equal(mask(image, GREEN), capsule)


def test_ground_plane_meets_the_horizon_at_the_middle_row(f32):
    # eye 1 m above the plane y = 0, looking horizontally: the horizon is the image's middle;
    # below it every pixel is ground, above it every pixel is background
    cam = Camera(position=(0.0, 1.0, 0.0), target=(0.0, 1.0, -1.0), fov=60.0)
    r = Renderer(32, 24, cam, supersample=1, light=FLAT, background=BLACK)
    r.begin()
    r.draw_plane(point=(0.0, 0.0, 0.0), colour=GREEN, checker=0.0)
    image = r.end()[::-1]
    assert mask(image[:12], GREEN).all() and not image[12:].any()


def test_lines_have_their_width_in_pixels_and_discs_their_radius(f32):
    r = flat_renderer(32, 32)
    r.begin()
    r.draw_lines(np.array([[4.0, 10.5, 0], [28.0, 10.5, 0]]), [[0, 1]], width=3.0, colour=RED)
    r.draw_points(np.array([[16.0, 24.0, 0]]), radius=4.0, colour=GREEN)
    image = r.end()[::-1]
    y, x = np.mgrid[0:32, 0:32] + 0.5
    segment = (np.maximum(np.maximum(4 - x, x - 28), 0) ** 2 + (y - 10.5) ** 2) <= 1.5 ** 2
    disc = (x - 16) ** 2 + (y - 24) ** 2 <= 16
    report("line rows at x = 16", np.flatnonzero(mask(image, RED)[:, 16]).tolist(), [9, 10, 11])
    assert np.array_equal(mask(image, RED), segment)
    assert np.array_equal(mask(image, GREEN), disc)


def test_wireframe_marks_edges_and_leaves_interiors(f32):
    r = flat_renderer(24, 24)
    wire = (0.0, 0.0, 1.0)
    r.begin()
    r.draw_mesh(np.array([[2, 2, 0], [22, 2, 0], [2, 22, 0.0]]), [[0, 1, 2]],
                style=SurfaceStyle(front=RED, checker=0.0, wireframe=2.0, wire_colour=wire))
    image = r.end()[::-1]
    assert mask(image, wire)[2, 10] and mask(image, wire)[10, 2]     # on the legs
    assert mask(image, RED)[6, 6]                                     # 4 px from every edge


def test_strain_colour_map_shows_a_stretched_region(f32):
    # a 2 x 4 strip of 10 px cells whose last column is pulled out to 1.1 x: per-column strain
    # is the largest of its springs': 0 (untouched), 0.05 (a bend spring reaches the last
    # column), 0.1, 0.1; the last cell is strain_max (red), the first almost unstretched (blue)
    mesh = tc.grid_mesh(2, 4, size=(30.0, 10.0), plane="xy", origin=(2.0, 2.0, 0.0))
    cloth = tc.Cloth(mesh, tc.Material())
    x = mesh.vertices.copy()
    x[x[:, 0] > 30, 0] = 22 + 10 * 1.1
    strain = tc.render.vertex_strain(x, cloth.spring_indices, cloth.spring_rest_length)
    report("strain per column", strain[:4].round(6).tolist(), [0.0, 0.05, 0.1, 0.1])
    assert np.allclose(strain[:4], [0.0, 0.05, 0.1, 0.1], atol=1e-6)
    r = flat_renderer(40, 16)
    r.begin()
    r.draw_mesh(x, mesh.triangles, strain=strain,
                style=SurfaceStyle(strain=True, strain_max=0.1, checker=0.0))
    image = r.end()[::-1].astype(int)
    cold, hot = image[6, 2], image[6, 28]
    report("left, right colours", (cold.tolist(), hot.tolist()), ("blue", [217, 26, 26]))
    assert hot.tolist() == [217, 26, 26]
    assert cold[2] > 150 and cold[0] < 100


def test_renderer_rejects_bad_input_by_name(f32):
    r = flat_renderer(8, 8)
    with pytest.raises(ValueError, match="inside begin"):
        r.draw_sphere((0, 0, 0), 1.0)
    r.begin()
    with pytest.raises(ValueError, match="triangles"):
        r.draw_mesh(np.zeros((3, 3)), [[0, 1, 3]])
    with pytest.raises(ValueError, match=r"positions\[1, 0\]"):
        r.draw_mesh(np.array([[0, 0, 0], [np.nan, 0, 0], [0, 1, 0]]), [[0, 1, 2]])
    with pytest.raises(ValueError, match="radius"):
        r.draw_sphere((0, 0, 0), -1.0)
    with pytest.raises(ValueError, match="hi"):
        r.draw_box((0, 0, 0), (1, -1, 1))
    with pytest.raises(ValueError, match="strain"):
        r.draw_mesh(np.zeros((3, 3)), [[0, 1, 2]], style=SurfaceStyle(strain=True))
    with pytest.raises(ValueError, match="supersample"):
        Renderer(8, 8, supersample=0)
    with pytest.raises(ValueError, match="SurfaceStyle.front"):
        SurfaceStyle(front=(2.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="Light.ambient"):
        Light(ambient=1.5)


def test_string_draws_as_lines_with_pins_as_dots(f32):
    # a body without triangles (the lecture's string): its stretch springs become lines
    x = np.array([[4.0, 16.5, 0.0], [12.0, 16.5, 0.0], [20.0, 16.5, 0.0], [28.0, 16.5, 0.0]])
    body = tc.Cloth.from_particles(x, [0.1] * 4, [[0, 1], [1, 2], [2, 3]], pinned=[0])
    sim = tc.Simulation(body, gravity=(0.0, 0.0, 0.0))
    r = flat_renderer(32, 32)
    r.begin()
    r.draw_simulation(sim, SurfaceStyle(front=RED, line_width=3.0, particles=2.0,
                                        particle_colour=GREEN, pin_colour=BLUE))
    image = r.end()[::-1]
    line = mask(image, RED) | mask(image, GREEN) | mask(image, BLUE)
    report("rows covered at x = 8", np.flatnonzero(line[:, 8]).tolist(), [15, 16, 17])
    assert np.flatnonzero(line[:, 8]).tolist() == [15, 16, 17]
    assert mask(image, BLUE)[16, 4] and mask(image, GREEN)[16, 20] and mask(image, RED)[16, 8]


def test_empty_frame_shows_the_background_gradient(f32):
    top, bottom = (1.0, 1.0, 1.0), (0.0, 0.0, 1.0)
    r = Renderer(4, 10, pixel_camera(4, 10), supersample=1, background=Background(top=top, bottom=bottom))
    r.begin()
    image = r.end().astype(float)          # row k from the top: centre (9.5 - k) / 10 of the way up
    expected_red = [255 * (9.5 - k) / 10 for k in range(10)]
    report("red channel down the image", image[:, 0, 0].tolist(), [round(v) for v in expected_red])
    assert np.allclose(image[:, 0, 0], expected_red, atol=0.51) and np.all(image[..., 2] == 255)


def test_checker_cells_sit_on_the_rest_coordinates(f32):
    # a 16 x 16 px quad, 4 px cells: cell (i, j) is darkened when i + j is odd. With rest
    # positions shifted by one cell the pattern inverts; without any, it follows the positions
    quad = np.array([[0, 0, 0], [16, 0, 0], [16, 16, 0], [0, 16, 0]], float)
    r = flat_renderer(16, 16)

    def red(rest):
        r.begin()
        r.draw_mesh(quad, [[0, 1, 2], [0, 2, 3]], rest_positions=rest,
                    style=SurfaceStyle(front=RED, checker=4.0, checker_contrast=0.5))
        return r.end()[::-1][..., 0].astype(int)

    y, x = np.mgrid[0:16, 0:16]
    odd = ((x // 4 + y // 4) % 2).astype(bool)
    expected = np.where(odd, 128, 255)
    assert np.array_equal(red(None), expected)
    assert np.array_equal(red(quad), expected)
    assert np.array_equal(red(quad + [4.0, 0.0, 0.0]), np.where(odd, 255, 128))


def test_colliders_of_a_simulation_are_drawn_where_their_paths_put_them(f32):
    sphere = tc.Sphere(centre=(8.0, 8.0, 0.0), radius=4.0, path=lambda t: (8.0 * t, 0.0, 0.0))
    sim = tc.Simulation(tc.Cloth.from_particles([[0.0, 30.0, 0.0]], [1.0], np.zeros((0, 2), int)),
                        dt=0.125, gravity=(0.0, 0.0, 0.0), colliders=[sphere])
    sim.step(8)                                       # t = 1 s: the centre is at (16, 8)
    r = Renderer(32, 32, pixel_camera(32, 32), supersample=1, light=FLAT, background=BLACK)
    r.begin()
    r.draw_colliders(sim)
    drawn = r.end()[::-1].any(axis=2)
    y, x = np.mgrid[0:32, 0:32] + 0.5
    assert np.array_equal(drawn, (x - 16) ** 2 + (y - 8) ** 2 <= 16)


def ground_frame(renderer, camera=None, point=(0.0, 0.0, 0.0), sim=None, **plane):
    """A frame of the ground (a 0.5 m checker, as scene files draw it) and, with `sim`, its
    colliders; plane: more of draw_plane's arguments."""
    renderer.begin(camera)
    renderer.draw_plane(point=point, checker=0.5, **plane)
    if sim is not None:
        renderer.draw_colliders(sim)
    return renderer.end().copy()


def test_a_plane_collider_in_the_grounds_plane_is_drawn_once(f32):
    # The ground of a scene file is its plane collider's plane: drawing both used to put two
    # checkers (0.5 and 0.25 m) in one set of samples, the darker winning each tie
    cam = Camera(position=(0.3, 1.0, 2.0), target=(0.0, 0.0, 0.0), fov=60.0)

    def sim_with(plane):
        return tc.Simulation(tc.Cloth.from_particles([[0.0, 3.0, 0.0]], [1.0],
                                                     np.zeros((0, 2), int)),
                             dt=0.01, colliders=[plane])

    r = Renderer(48, 32, cam, supersample=1)
    alone = ground_frame(r)
    for normal in ((0.0, 1.0, 0.0), (0.0, -1.0, 0.0)):       # either side up: one plane
        same = sim_with(tc.Plane(point=(2.0, 0.0, -1.0), normal=normal))
        assert np.array_equal(ground_frame(r, sim=same), alone)
    higher = sim_with(tc.Plane(point=(0.0, 0.2, 0.0)))        # another plane is drawn
    assert not np.array_equal(ground_frame(r, sim=higher), alone)


def test_the_last_frames_ground_is_reused_only_for_the_same_camera_plane_and_light(f32):
    # A frame's first unshaded plane is copied from the last frame when nothing it depends
    # on changed: every frame must be the bits a fresh renderer draws
    cams = [Camera(position=(0.3, 1.0, 2.0), target=(0.0, 0.0, 0.0), fov=60.0),
            Camera(position=(0.35, 1.0, 2.0), target=(0.0, 0.0, 0.0), fov=60.0)]
    frames = [(cams[0], (0.0, 0.0, 0.0), GREEN), (cams[0], (0.0, 0.0, 0.0), GREEN),
              (cams[1], (0.0, 0.0, 0.0), GREEN), (cams[1], (0.0, 0.1, 0.0), GREEN),
              (cams[1], (0.0, 0.1, 0.0), RED), (cams[0], (0.0, 0.0, 0.0), GREEN)]
    kept = Renderer(48, 32, cams[0], supersample=2)
    images = []
    for camera, point, colour in frames:
        got = ground_frame(kept, camera, point, colour=colour, contrast=0.5)
        fresh = ground_frame(Renderer(48, 32, camera, supersample=2), point=point,
                             colour=colour, contrast=0.5)
        assert np.array_equal(got, fresh)
        images.append(got)
    assert all(not np.array_equal(a, b) for a, b in zip(images[1:], images[2:]))
    kept.light = Light(direction=(0.0, 1.0, 0.0))         # a new light: the ground is lit anew
    lit = ground_frame(kept, cams[0], colour=GREEN, contrast=0.5)
    assert np.array_equal(lit, ground_frame(Renderer(48, 32, cams[0], supersample=2,
                                                     light=Light(direction=(0.0, 1.0, 0.0))),
                                            colour=GREEN, contrast=0.5))
    assert not np.array_equal(lit, images[-1])
