"""Whole frames: golden images, torn triangles, cameras that frame a body, the null renderer,
and rendering with no display."""

import inspect
import os
import subprocess
import sys

import numpy as np
import pytest
from helpers import assert_matches_golden, report

import ti_cloth as tc
from ti_cloth.render import Background, Camera, Light, NullRenderer, Renderer, SurfaceStyle


def draped_sheet(n=16):
    """An n x n sheet over [-1, 1]^2 lifted by a bump; its front edge curls up and back over
    itself (radius 0.15 m), so the back side shows."""
    mesh = tc.grid_mesh(n, n, size=(2.0, 2.0), plane="xz", origin=(-1.0, 0.0, -1.0))
    x = mesh.vertices.copy()
    x[:, 1] = 0.1 + 0.7 * np.exp(-2.5 * (x[:, 0] ** 2 + np.minimum(x[:, 2], 0.6) ** 2))
    curl = x[:, 2] > 0.6
    arc = (x[curl, 2] - 0.6) / 0.15
    x[curl, 2] = 0.6 + 0.15 * np.sin(arc)
    x[curl, 1] += 0.15 * (1 - np.cos(arc))
    return mesh, x


def render_drape():
    mesh, x = draped_sheet()
    camera = Camera(position=(1.6, 1.5, 2.6), target=(0.0, 0.3, 0.0), fov=40.0)
    with Renderer(96, 64, camera, supersample=2) as r:
        r.begin()
        r.draw_plane(point=(0.0, 0.0, 0.0), checker=0.5)
        r.draw_sphere((0.0, 0.35, 0.0), 0.3)
        r.draw_mesh(x, mesh.triangles, rest_positions=mesh.vertices, style=SurfaceStyle(checker=0.25))
        return r.end()


def render_hair_and_wire():
    mesh, x = draped_sheet(8)
    strands = np.array([[0.5 + 0.1 * s, 1.2 - 0.15 * k, 0.1 * np.sin(k + s)]
                        for s in range(5) for k in range(6)])
    segments = np.array([[s * 6 + k, s * 6 + k + 1] for s in range(5) for k in range(5)])
    cloth = tc.Cloth(mesh, tc.Material())
    strain = tc.render.vertex_strain(x, cloth.spring_indices, cloth.spring_rest_length)
    camera = Camera.fit(np.concatenate([x, strands]), orthographic=True, aspect=96 / 64)
    with Renderer(96, 64, camera, supersample=2, light=Light(ambient=0.5),
                  background=Background(top=(1.0, 1.0, 1.0), bottom=(0.8, 0.8, 0.8))) as r:
        r.begin()
        r.draw_box((-1.2, -0.3, -1.2), (-0.6, 0.2, -0.6))
        r.draw_capsule((0.6, 0.0, -0.8), (1.1, 0.3, -0.8), 0.12)
        r.draw_mesh(x, mesh.triangles, strain=strain,
                    style=SurfaceStyle(strain=True, strain_max=0.5, wireframe=0.6))
        r.draw_lines(strands, segments, width=1.5, colour=(0.3, 0.2, 0.1))
        r.draw_points(x[::7], radius=1.5)
        return r.end()


@pytest.mark.parametrize("name, scene", [("drape", render_drape), ("hair_and_wire", render_hair_and_wire)])
def test_golden_image(f32, tmp_path, name, scene):
    assert_matches_golden(scene(), name, tmp_path)


def test_golden_comparison_fails_on_a_changed_image_and_writes_a_diff(f32, tmp_path):
    image = render_drape().copy()
    image[20:30, 40:50] = 255 - image[20:30, 40:50]        # 100 of 6144 pixels: 1.6 %
    with pytest.raises(AssertionError, match="diff image"):
        assert_matches_golden(image, "drape", tmp_path)
    assert (tmp_path / "drape.diff.png").exists() and (tmp_path / "drape.actual.png").exists()
    assert_matches_golden(np.clip(render_drape().astype(int) + 1, 0, 255).astype(np.uint8),
                          "drape", tmp_path / "ok")      # one level everywhere is within tolerance


def test_a_torn_triangle_disappears(f32):
    # a 3 x 3 sheet facing the camera, every particle pinned; a handle pulls corner 0 straight
    # away from the (orthographic) camera, so nothing moves on screen, until its springs tear
    mesh = tc.grid_mesh(3, 3, size=(2.0, 2.0), plane="xy")
    cloth = tc.Cloth(mesh, tc.Material(), pinned=range(1, 9))
    pull = tc.Handle([0], lambda t: (0.0, 0.0, -10.0 * t))
    sim = tc.Simulation(cloth, dt=1e-3, tearing=0.2, handles=[pull])
    camera = Camera(position=(1.0, 1.0, 10.0), target=(1.0, 1.0, 0.0), orthographic=True, height=3.0)
    r = Renderer(60, 60, camera, supersample=1, light=Light(ambient=1.0),
                 background=Background(top=(0.0, 0.0, 0.0), bottom=(0.0, 0.0, 0.0)))
    red = SurfaceStyle(front=(1.0, 0.0, 0.0), back=(1.0, 0.0, 0.0), checker=0.0)

    def frame(hidden_by_tearing=True):
        r.begin()
        if hidden_by_tearing:
            r.draw_simulation(sim, red)
        else:
            r.draw_mesh(sim.positions(), mesh.triangles, style=red)
        return r.end()[::-1]                    # y up: 20 px per metre, world (0, 0) at (10, 10)

    quad0, quad1 = (20, 20), (20, 40)           # centres of the first and second cell (y, x)
    before = frame()
    assert before[quad0].tolist() == [255, 0, 0] and before[quad1].tolist() == [255, 0, 0]
    sim.step(100)                               # 0.7 m out of plane: strain 0.22 > 0.2
    report("torn triangles", sim.torn_triangles().tolist(), [0, 1])
    assert sim.torn_triangles().tolist() == [0, 1]
    after = frame()
    assert after[quad0].tolist() == [0, 0, 0] and after[quad1].tolist() == [255, 0, 0]
    assert frame(hidden_by_tearing=False)[quad0].tolist() == [255, 0, 0]   # still there untorn


@pytest.mark.parametrize("orthographic", [False, True])
@pytest.mark.parametrize("aspect", [16 / 9, 9 / 16])
@pytest.mark.parametrize("direction", [(0.55, 0.4, 1.0), (0.0, 1.0, 0.01), (-1.0, 0.5, 0.3)])
def test_camera_fit_frames_the_whole_body(orthographic, aspect, direction):
    mesh = tc.grid_mesh(5, 7, size=(3.0, 1.0), plane="xz", origin=(10.0, 2.0, -4.0))
    width, height = (160, 90) if aspect > 1 else (90, 160)
    camera = Camera.fit(mesh, direction=direction, orthographic=orthographic, aspect=aspect)
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    screen, depth = camera.project(corners, width, height)
    extent = (screen.max(axis=0) - screen.min(axis=0)) / [width, height]
    report("screen box", (screen.min(axis=0).round(1), screen.max(axis=0).round(1)), (width, height))
    assert np.all(depth > camera.near)
    assert np.all(screen >= 0) and np.all(screen <= [width, height])
    assert extent.max() > 0.25                   # framed, not a speck


@pytest.mark.parametrize("kwargs, field", [
    (dict(position=(0, 0, 0), target=(0, 0, 0)), "Camera.target"),
    (dict(position=(0, 0, 1), target=(0, 0, 0), up=(0, 0, 1)), "Camera.up"),
    (dict(fov=180.0), "Camera.fov"), (dict(orthographic=True, height=0.0), "Camera.height"),
    (dict(position=(0, np.nan, 1)), r"Camera.position\[1\]"),
])
def test_camera_rejects_bad_input_by_name(kwargs, field):
    with pytest.raises(ValueError, match=field):
        Camera(**kwargs)


def parameters(function):
    return list(inspect.signature(function).parameters.values())


def test_null_renderer_has_the_renderer_interface_and_draws_nothing(f32):
    public = [name for name in vars(Renderer) if not name.startswith("_")]
    for name in public:
        assert parameters(getattr(Renderer, name)) == parameters(getattr(NullRenderer, name)), name
    assert parameters(Renderer.__init__) == parameters(NullRenderer.__init__)
    with NullRenderer(64, 64, Camera()) as r:
        for _ in range(3):
            r.begin()
            r.draw_sphere((0, 0, 0), 1.0)
            assert r.end() is None
    assert r.frames == 3


@pytest.mark.reinitialises
def test_simulation_never_imports_the_renderer():
    code = ("import sys, ti_cloth as tc; tc.init('cpu'); "
            "sim = tc.Simulation(tc.Cloth(tc.grid_mesh(3, 3), tc.Material())); sim.step(2); "
            "assert 'ti_cloth.render' not in sys.modules, 'renderer imported'")
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.reinitialises
def test_renders_with_no_display_and_opens_no_window(tmp_path):
    # no DISPLAY / WAYLAND_DISPLAY, and Taichi's window classes replaced by ones that raise
    code = f"""
import taichi as ti
def no_window(*args, **kwargs):
    raise RuntimeError("a window was opened")
ti.ui.Window = no_window
ti.GUI.show = no_window
import numpy as np, ti_cloth as tc
from ti_cloth.render import Camera, Renderer, SpringView, write_png
tc.init("cpu")
cloth = tc.Cloth(tc.grid_mesh(4, 4), tc.Material(), pinned=[0, 3])
sim = tc.Simulation(cloth, dt=1e-4)
sim.step(5)
with Renderer(64, 48, Camera.fit(cloth)) as r:
    r.begin(); r.draw_plane(point=(0, -0.5, 0)); r.draw_simulation(sim); image = r.end()
write_png({str(tmp_path / "frame.png")!r}, image)
view = SpringView(bounds=((0, 0), (1, 1)), res=(32, 32))
write_png({str(tmp_path / "springs.png")!r},
          view.render(sim.positions(), cloth.spring_indices, cloth.spring_kind, cloth.pinned))
"""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    subprocess.run([sys.executable, "-c", code], check=True, env=env, timeout=300)
    assert (tmp_path / "frame.png").exists() and (tmp_path / "springs.png").exists()


def test_a_flat_sheet_on_a_checker_boundary_renders_as_one_just_above_it(f32):
    """A sheet lying at y = 0.7 with 0.1 m checker cells sits on a cell boundary: its samples
    fall in one cell, as for the same sheet 3 cm higher seen from 3 cm higher (before, the
    rounding of interpolated rest points flickered between two cells: a grainy checker)."""
    images = []
    for height in (0.7, 0.73):
        mesh = tc.grid_mesh(8, 8, size=(1.0, 1.0), plane="xz", origin=(-0.5, height, -0.5))
        camera = Camera(position=(0.8, height + 0.6, 1.0), target=(0.0, height, 0.0))
        with Renderer(96, 64, camera, supersample=2) as r:
            r.begin()
            r.draw_mesh(mesh.vertices, mesh.triangles, rest_positions=mesh.vertices,
                        style=SurfaceStyle(checker=0.1))
            images.append(r.end().astype(int))
    differing = np.abs(images[0] - images[1]).max(axis=2) > 2
    report("pixels differing", int(differing.sum()), 0)
    assert differing.sum() == 0


def _drape(collider, height, steps, thickness=None):
    """A 20 x 20 sheet of 1 m dropped from `height` onto `collider` (its thickness: given, or
    the default, the cloth's), stepped `steps` x 1/240 s with xpbd."""
    mesh = tc.grid_mesh(20, 20, size=(1.0, 1.0), plane="xz", origin=(-0.5, height, -0.5))
    if thickness is not None:
        collider = type(collider)(**{**collider.__dict__, "thickness": thickness})
    sim = tc.Simulation(tc.Cloth(mesh, tc.Material()), integrator=tc.XPBD(iterations=10),
                        dt=1 / 240, colliders=[collider])
    sim.step(steps)
    return sim


def _collider_pixels(sim, camera, size, supersample, covered):
    """Pixels of the cloth's silhouette (its triangles `covered` alone, drawn red with no
    shading) that show anything but the cloth once the colliders are drawn too."""
    red = SurfaceStyle(front=(1.0, 0.0, 0.0), back=(1.0, 0.0, 0.0), checker=0.0)
    triangles = sim.cloth.mesh.triangles
    with Renderer(size, size, camera, supersample=supersample, light=Light(ambient=1.0),
                  background=Background(top=(0.0, 0.0, 0.0), bottom=(0.0, 0.0, 0.0))) as r:
        r.begin()
        r.draw_mesh(sim.positions(), triangles, hidden=~covered, style=red)
        alone = r.end()
        r.begin()
        r.draw_colliders(sim)
        r.draw_mesh(sim.positions(), triangles, style=red)
        both = r.end()
    inside = (alone == (255, 0, 0)).all(axis=-1)
    return int((inside & ~(both == (255, 0, 0)).all(axis=-1)).sum()), int(inside.sum())


@pytest.mark.parametrize("shape", ["sphere", "plane"])
def test_a_collider_never_shows_through_the_cloth_resting_on_it(f32, shape, monkeypatch):
    """A sheet draped on a sphere (seen from straight above: its triangles above the sphere's
    centre lie over the cap, nothing of the sphere is in front of them) and a sheet lying on
    the ground (seen from the side): with the default contact thickness and the colliders'
    depth offset, no collider pixel inside the cloth's silhouette at any size or
    supersampling; with neither (thickness 0, no offset) the collider fights through."""
    from ti_cloth.render import renderer
    if shape == "sphere":
        collider, height, steps = tc.Sphere(centre=(0.0, 0.0, 0.0), radius=0.3), 0.35, 240
        camera = Camera(position=(0.0, 4.0, 0.0), target=(0.0, 0.0, 0.0), up=(0.0, 0.0, -1.0),
                        orthographic=True, height=1.3)
    else:
        collider, height, steps = tc.Plane(point=(0.0, 0.0, 0.0)), 0.05, 120
        camera = Camera(position=(1.0, 0.7, 1.4), target=(0.0, 0.0, 0.0), fov=45.0)
    sim = _drape(collider, height, steps)
    assert sim.colliders.colliders[0].thickness == pytest.approx(
        tc.AUTO_THICKNESS * sim.cloth.mean_edge)
    x = sim.positions()
    covered = (x[sim.cloth.mesh.triangles][..., 1] > 0.0).all(axis=1)   # over the cap
    assert covered.sum() > 50
    counts = {(size, ss): _collider_pixels(sim, camera, size, ss, covered)
              for size, ss in ((120, 1), (480, 1), (240, 2))}
    report(f"{shape}: collider pixels in the cloth's silhouette (of)", counts, "0 each")
    assert all(shown == 0 and total > 500 for shown, total in counts.values())
    monkeypatch.setattr(renderer, "COLLIDER_DEPTH_BIAS", 0.0)
    bare = _drape(collider, height, steps, thickness=0.0)
    x = bare.positions()
    covered = (x[bare.cloth.mesh.triangles][..., 1] > -1e-3).all(axis=1)
    shown, total = _collider_pixels(bare, camera, 480, 1, covered)
    report(f"{shape}: without either", (shown, total), "> 0")
    assert shown > 0


def test_the_ground_is_shaded_where_the_light_sees_the_cloth_over_it(f32):
    """A pinned 1 m sheet 0.5 m over the ground, the light from (0.35, 1, 0.55): ground points
    inside the sheet's outline cast along the light onto the ground (computed here, shrunk by
    the map's softening) are darker by SHADOW_DARKNESS than the same frame without shadows,
    points clear of it (grown likewise) unchanged; the cloth's own pixels are left out."""
    from ti_cloth.render import renderer as renderer_module
    mesh = tc.grid_mesh(11, 11, size=(1.0, 1.0), plane="xz", origin=(-0.5, 0.5, -0.5))
    sim = tc.Simulation(tc.Cloth(mesh, tc.Material(), pinned=range(121)), dt=1e-3,
                        colliders=[tc.Plane(point=(0.0, 0.0, 0.0))])
    camera = Camera(position=(0.0, 4.0, 2.5), target=(0.0, 0.0, -0.6), fov=50.0)
    light = Light(ambient=1.0)              # unlit colours: the cloth is exactly red
    red = SurfaceStyle(front=(1.0, 0.0, 0.0), back=(1.0, 0.0, 0.0), checker=0.0)
    images = []
    with Renderer(320, 240, camera, supersample=1, light=light) as r:
        for shaded in (False, True):
            r.begin()
            if shaded:
                r.cast_shadows(sim)
            r.draw_colliders(sim)
            r.draw_simulation(sim, red)
            images.append(r.end().astype(float))
    plain, shaded = images
    cloth = (plain == (255, 0, 0)).all(axis=-1)
    toward = np.asarray(light.direction)
    u, v = np.meshgrid(np.linspace(-1.6, 1.6, 161), np.linspace(-2.0, 1.2, 161))
    ground = np.stack([u.ravel(), np.zeros(u.size), v.ravel()], axis=1)
    # the sheet's outline cast along the light onto y = 0: a square shifted by -0.5 l / l_y
    shift = -0.5 * toward[[0, 2]] / toward[1]
    reach = np.abs(ground[:, [0, 2]] - shift).max(axis=1)       # square "radius" round it
    # the map spans the bounds' diagonal (2.02 x its half): the softening reaches a texel or
    # two, and a texel's projection onto the slanted ground is longer by 1 / l_y
    texel = 2.02 * (np.sqrt(2.0 + 0.5 ** 2) / 2) / renderer_module.SHADOW_SIZE / toward[1]
    inside, outside = reach < 0.5 - 3 * texel, reach > 0.5 + 3 * texel
    screen, depth = camera.project(ground, 320, 240)
    px = np.floor(screen).astype(int)
    seen = (px[:, 0] >= 0) & (px[:, 0] < 320) & (px[:, 1] >= 0) & (px[:, 1] < 240)
    rows, cols = 239 - px[seen, 1], px[seen, 0]
    keep = ~cloth[rows, cols]
    ratio = shaded[rows, cols].sum(axis=1) / plain[rows, cols].sum(axis=1)
    dark, clear = ratio[inside[seen] & keep], ratio[outside[seen] & keep]
    report("ground points in the cast shadow / clear of it; their brightness ratio",
           (len(dark), len(clear), float(np.median(dark)), float(clear.min())),
           f"{1 - renderer_module.SHADOW_DARKNESS} and 1")
    assert len(dark) > 100 and len(clear) > 1000
    assert np.abs(dark - (1 - renderer_module.SHADOW_DARKNESS)).max() < 0.02
    assert (clear == 1.0).all()


def test_the_ground_checker_fades_where_a_pixel_covers_a_cell_and_does_not_alias(f32):
    """A checker of 0.25 m seen at a grazing angle, its depth fade turned off (fade 1e6): near
    the camera the cells show (high contrast between neighbouring pixels); toward the horizon,
    where one pixel's footprint on the ground covers a cell, the checker has faded to its
    plain colour instead of sampling cells at random (moire): the far rows are flat, and a
    frame supersampled 4 x 4 agrees with the plain one there."""
    camera = Camera(position=(0.0, 1.0, 0.0), target=(0.0, 0.9, -10.0), fov=40.0)
    frames = {}
    for ss in (1, 4):
        with Renderer(240, 160, camera, supersample=ss) as r:
            r.begin()
            r.draw_plane(point=(0.0, 0.0, 0.0), checker=0.25, contrast=0.5, fade=1e6)
            frames[ss] = r.end().astype(float).mean(axis=-1)
    near, far = frames[1][140:160], frames[1][86:92]       # rows: bottom, just below the horizon
    report("spread of a row near / far; far rows against 4 x 4 supersampling",
           (float(near.std(axis=1).mean()), float(far.std(axis=1).max()),
            float(np.abs(frames[1][86:92] - frames[4][86:92]).max())), "high / ~0 / ~0")
    assert near.std(axis=1).mean() > 20
    assert far.std(axis=1).max() < 1
    assert np.abs(frames[1][86:92] - frames[4][86:92]).max() <= 3
