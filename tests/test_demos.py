"""Every demo runs in --test mode and writes distinct, non-blank frames."""

import importlib.util
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

# the runs here initialise Taichi in their scenes' precision, f32: among the f32 tests
# (conftest), they do not switch a worker out of f64 and back
pytestmark = pytest.mark.usefixtures("f32")

DEMOS = sorted((Path(__file__).parents[1] / "demos").glob("*.py"))
EXPECTED = {"hanging_cloth", "curtain_hem", "flag_in_wind", "tearing", "verlet_pbd_cloth",
            "string_wall", "hair", "soft_block", "stuyck_explicit", "cloth_pile", "two_layers", "tablecloth", "turntable",
            "cusick_drape"}


def test_every_system_of_the_source_texts_has_a_demo_with_a_scene_file():
    assert {d.stem for d in DEMOS} == EXPECTED
    assert all(d.with_suffix(".toml").is_file() for d in DEMOS)


@pytest.mark.parametrize("script", DEMOS, ids=[d.stem for d in DEMOS])
def test_demo_writes_frames(script, tmp_path):
    spec = importlib.util.spec_from_file_location(script.stem, script)
    demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo)
    frames = demo.main(["--test", "--no-progress", "--out-dir", str(tmp_path)])
    images = [iio.imread(f).astype(float) for f in frames]
    assert len(images) >= 2
    for image in images:
        assert image.std() > 5.0, "blank frame"
    for a, b in zip(images, images[1:]):
        assert np.abs(a - b).mean() > 0.01, "frames identical"
    assert not list(tmp_path.glob(".*tmp*"))
    assert list(tmp_path.glob("*.gif"))
