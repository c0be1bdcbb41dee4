"""Every demo runs in --test mode and writes distinct, non-blank frames."""

import importlib.util
from pathlib import Path
from types import SimpleNamespace

import imageio.v3 as iio
import numpy as np
import pytest

import ti_cloth as tc

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
    demo = _load(script)
    frames = demo.main(["--test", "--no-progress", "--out-dir", str(tmp_path)])
    images = [iio.imread(f).astype(float) for f in frames]
    assert len(images) >= 2
    for image in images:
        assert image.std() > 5.0, "blank frame"
    for a, b in zip(images, images[1:]):
        assert np.abs(a - b).mean() > 0.01, "frames identical"
    assert not list(tmp_path.glob(".*tmp*"))
    assert list(tmp_path.glob("*.gif"))


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
