"""Every demo runs in --test mode and writes distinct, non-blank frames; the demos of a
dressed figure also keep their cloth outside it (checked with libigl's winding number)."""

import importlib.util
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import imageio.v3 as iio
import numpy as np
import pytest
from helpers import base_install, report

import ti_cloth as tc
from ti_cloth.app.scene import load_scene

# the runs here initialise Taichi in their scenes' precision, f32: among the f32 tests
# (conftest), they do not switch a worker out of f64 and back
pytestmark = pytest.mark.usefixtures("f32")

DEMOS = sorted((Path(__file__).parents[1] / "demos").glob("*.py"))
EXPECTED = {"hanging_cloth", "curtain_hem", "flag_in_wind", "tearing", "verlet_pbd_cloth",
            "string_wall", "hair", "soft_block", "stuyck_explicit", "cloth_pile", "two_layers", "tablecloth", "turntable",
            "cusick_drape", "cape", "skirt_walk"}


def test_every_system_of_the_source_texts_has_a_demo_with_a_scene_file():
    assert {d.stem for d in DEMOS} == EXPECTED
    assert all(d.with_suffix(".toml").is_file() for d in DEMOS)


@pytest.mark.parametrize("script", DEMOS, ids=[d.stem for d in DEMOS])
def test_demo_writes_frames(script, tmp_path):
    """With the modules of every extra made unimportable, as after the README's first
    command; and for the demos of a dressed figure, their own check right after, on the
    kernels the demo compiled (the same process: pool.py keeps them)."""
    demo = _load(script)
    with base_install():          # no extra: the README's first command installs none
        frames = demo.main(["--test", "--no-progress", "--out-dir", str(tmp_path)])
    images = [iio.imread(f).astype(float) for f in frames]
    assert len(images) >= 2
    for image in images:
        assert image.std() > 5.0, "blank frame"
    for a, b in zip(images, images[1:]):
        assert np.abs(a - b).mean() > 0.01, "frames identical"
    assert not list(tmp_path.glob(".*tmp*"))
    assert list(tmp_path.glob("*.gif"))
    if script.stem in FIGURE_CHECKS:
        FIGURE_CHECKS[script.stem]()


def cape_stays_on_the_shoulders_and_out_of_the_figure():
    """demos/cape.toml for 0.6 s (the figure turns one way, to its widest): in every
    frame no particle is inside the skinned figure as it is at the frame's time (libigl's
    fast winding number: not our code) and the attached top edge rides its triangles.
    Without the figure as a collider the cape swings into it (within 0.5 s). Both without
    the demo's self-collision, which keeps the cape off itself, not off the figure (and
    costs 4x the step here)."""
    import igl
    scene = load_scene(Path(__file__).parents[1] / "demos" / "cape.toml")
    scene = replace(scene, self_collision=None)
    figure = scene.colliders[0]
    (attachment,) = scene.handles
    free = np.setdiff1d(np.arange(scene.cloth.particle_count), attachment.particles)
    carried = attachment.handle(scene.cloth.particle_position).path
    runs = {}
    for name, colliders, frames in (("with", scene.colliders, 18),
                                    ("without", scene.colliders[1:], 15)):
        sim = replace(scene, colliders=colliders).build(dt=1 / 240)   # the demo's step
        inside, riding = [], 0.0
        for _ in range(frames):
            sim.step(8)
            vertices = figure.vertices_at(sim.time)
            w = igl.fast_winding_number(vertices, figure.mesh.triangles.astype(np.int64),
                                        sim.positions()[free].astype(np.float64))
            inside.append(int((np.abs(w) > 0.5).sum()))
            expected = scene.cloth.particle_position[attachment.particles] + carried(sim.time)
            riding = max(riding, np.abs(sim.positions()[attachment.particles] - expected).max())
        runs[name] = (inside, riding)
    report("cape particles inside the figure per frame, with it", runs["with"][0], "all 0")
    report("without it", runs["without"][0], "some frames > 0")
    assert sum(runs["with"][0]) == 0 and sum(runs["without"][0]) > 0
    assert runs["with"][1] < 1e-5      # f32 positions of ~1 m: a few roundings


def skirt_sews_shut_and_stays_out_of_the_figure():
    """demos/skirt_walk.toml for 0.6 s (a step): the side seams shut to within the collider's
    thickness by 0.3 s and stay so, no particle is ever inside the walking figure (libigl's
    winding number: not our code), and the waistband rides the hips. Without the demo's
    self-collision (cape_stays_on_the_shoulders_and_out_of_the_figure says why)."""
    import igl
    scene = load_scene(Path(__file__).parents[1] / "demos" / "skirt_walk.toml")
    scene = replace(scene, self_collision=None)
    figure = scene.colliders[0]
    sim = scene.build(dt=1 / 240)
    pairs = scene.cloth.seam_indices
    held = np.concatenate([a.particles for a in scene.handles])
    free = np.setdiff1d(np.arange(scene.cloth.particle_count), held)
    inside, open_after = [], 0.0
    for frame in range(18):
        sim.step(8)
        x = sim.positions()
        w = igl.fast_winding_number(figure.vertices_at(sim.time),
                                    figure.mesh.triangles.astype(np.int64), x[free])
        inside.append(int((np.abs(w) > 0.5).sum()))
        if sim.time > 0.3:
            open_after = max(open_after,
                             np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1).max())
    report("skirt particles inside the figure per frame; widest seam after 0.3 s (m)",
           (inside, open_after), "all 0; < 0.01")
    assert sum(inside) == 0 and open_after < figure.thickness


FIGURE_CHECKS = {"cape": cape_stays_on_the_shoulders_and_out_of_the_figure,
                 "skirt_walk": skirt_sews_shut_and_stays_out_of_the_figure}


def _load(script: Path):
    """The demo script as a module."""
    spec = importlib.util.spec_from_file_location(script.stem, script)
    demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo)
    return demo


def test_the_drape_measures_read_a_cone_and_a_fluted_disc():
    """The Cusick demo's measures on shapes with closed forms: a 30 cm disc folded down 45
    degrees outside the 18 cm stand casts a shadow of radius a + (R - a) cos 45, so DC =
    ((a + (R - a) cos 45)^2 - a^2) / (R^2 - a^2) (to the 0.5 mm raster: |d DC| <= 2 r dr /
    (R^2 - a^2) = 0.01); the flat disc gives 1; a hem fluted as R (1 + e cos 6 phi) has 6 folds
    when its peak-to-trough 2 e R passes FOLD_DEPTH and none when it does not."""
    cusick = _load(Path(__file__).parents[1] / "demos" / "cusick_drape.py")
    radius, stand = 0.15, cusick.SUPPORT_RADIUS
    mesh = tc.disc_mesh(radius, 20)
    rest = mesh.vertices
    r = np.hypot(rest[:, 0], rest[:, 2])
    out = np.maximum(r - stand, 0.0)
    folded = np.minimum(r, stand) + out * np.cos(np.pi / 4)     # the radius seen from above
    scale = np.where(r > 0, folded / np.maximum(r, 1e-12), 1.0)
    cone = rest * np.stack([scale, np.ones_like(r), scale], 1)
    cone[:, 1] -= out * np.sin(np.pi / 4)
    scene = SimpleNamespace(cloth=tc.Cloth(mesh, tc.Fabric()))       # what measure reads
    shadow = stand + (radius - stand) * np.cos(np.pi / 4)
    expected = (shadow ** 2 - stand ** 2) / (radius ** 2 - stand ** 2)
    coefficient, _ = cusick.measure(scene, cone)
    assert abs(coefficient - expected) < 0.01
    assert cusick.measure(scene, rest)[0] == 1.0
    phi = np.arctan2(rest[:, 2], rest[:, 0])
    for amplitude, count in ((2.5 * cusick.FOLD_DEPTH, 6), (0.3 * cusick.FOLD_DEPTH, 0)):
        flute = 1.0 + (amplitude / (2 * radius)) * np.cos(6 * phi) * (r / radius) ** 4
        fluted = rest * np.stack([flute, np.ones_like(r), flute], 1)
        assert cusick.folds(fluted, rest) == count


def test_the_skirt_counts_the_folds_of_a_fluted_hem():
    """The skirt demo's fold count on hems with closed forms: a ring of radius R fluted as
    R (1 + e cos k phi), in any order and off the axis, has k folds when its amplitude e R
    passes FOLD_DEADBAND and none below it; the scene's hem is the panels' two bottom edges
    (every particle at the pattern's y = 0, a row of both panels)."""
    skirt = _load(Path(__file__).parents[1] / "demos" / "skirt_walk.py")
    phi = np.random.default_rng(1).permutation(np.linspace(0, 2 * np.pi, 120, endpoint=False))
    for k in (3, 6, 9):
        for amplitude, folds in ((3 * skirt.FOLD_DEADBAND, k), (0.5 * skirt.FOLD_DEADBAND, 0)):
            radius = 0.3 + amplitude * np.cos(k * phi)
            ring = np.stack([0.4 + radius * np.cos(phi), np.full_like(phi, 0.2),
                             -0.1 + radius * np.sin(phi)], axis=1)
            assert skirt.hem_folds(ring, np.arange(len(phi))) == folds
    scene = load_scene(Path(__file__).parents[1] / "demos" / "skirt_walk.toml")
    hem = skirt.hem_of(scene.cloth)
    placed = scene.cloth.particle_position[hem]
    assert len(hem) > 40 and np.ptp(placed[:, 1]) < 1e-9          # one level ring round the legs
