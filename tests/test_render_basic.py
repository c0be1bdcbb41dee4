"""Image layout, atomic PNG writing and the 2-D dots-and-lines view."""

import imageio.v3 as iio
import numpy as np

import ti_cloth as tc
from ti_cloth.render import SpringView, frame_path, from_taichi, write_gif, write_png


def test_taichi_layout_becomes_top_left_numpy():
    w, h = 5, 3
    taichi_image = np.zeros((w, h, 3), np.float32)   # (x, y), y up
    taichi_image[0, h - 1] = 1.0                      # top-left pixel on screen
    taichi_image[w - 1, 0, 0] = 1.0                   # bottom-right pixel, red
    image = from_taichi(taichi_image)
    assert image.shape == (h, w, 3) and image.dtype == np.uint8
    assert image[0, 0].tolist() == [255, 255, 255]
    assert image[h - 1, w - 1].tolist() == [255, 0, 0]
    assert image.sum() == 4 * 255


def test_png_written_atomically_and_read_back(tmp_path):
    image = np.random.default_rng(0).integers(0, 256, size=(7, 9, 3), dtype=np.uint8)
    path = write_png(frame_path(tmp_path / "frames", 3), image)
    assert path.name == "frame_00003.png"
    assert np.array_equal(iio.imread(path), image)
    assert [p.name for p in path.parent.iterdir()] == ["frame_00003.png"]
    gif = write_gif([path, 255 - image, image // 2], tmp_path / "a.gif")
    assert iio.imread(gif, index=None).shape[:3] == (3, 7, 9)


def test_spring_view_puts_a_top_left_particle_top_left(f32):
    cloth = tc.Cloth.from_particles([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]], [1.0, 1.0], [[0, 1]])
    view = SpringView(bounds=((0.0, 0.0), (1.0, 1.0)), res=(64, 64), particle_radius=3)
    image = view.render(cloth.particle_position, cloth.spring_indices, cloth.spring_kind,
                        np.array([True, False])).astype(int)
    red = (image[..., 0] > 180) & (image[..., 1] < 100)      # the pin dot
    rows, cols = np.nonzero(red)
    assert rows.max() < 10 and cols.max() < 10, (rows, cols)
    dark = image.sum(axis=2) < 200                              # the free particle, bottom-right
    rows, cols = np.nonzero(dark)
    assert rows.min() > 54 and cols.min() > 54
