"""Image layout, atomic PNG writing, frame sequences, GIF/MP4 and the 2-D dots-and-lines view."""

import importlib.util
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

import ti_cloth as tc
from ti_cloth.render import (
    FrameSequence,
    SpringView,
    frame_path,
    from_taichi,
    write_gif,
    write_mp4,
    write_png,
)


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


def frames_of(count, h=16, w=24):
    """Distinct test frames: a bar moving right."""
    images = []
    for k in range(count):
        image = np.full((h, w, 3), 40, np.uint8)
        image[:, 2 * k: 2 * k + 4] = (230, 120, 30)
        images.append(image)
    return images


def test_frame_sequence_writes_numbered_frames_and_a_gif(tmp_path):
    folder = tmp_path / "demo"
    folder.mkdir()
    (folder / "frame_00007.png").write_bytes(b"stale frame of an earlier, longer run")
    (folder / "notes.txt").write_text("not ours")
    sequence = FrameSequence(folder, fps=10)
    for image in frames_of(3):
        sequence.write(image)
    outputs = sequence.close()
    assert sorted(p.name for p in folder.iterdir()) == [
        "demo.gif", "frame_00000.png", "frame_00001.png", "frame_00002.png", "notes.txt"]
    assert outputs == [folder / "demo.gif"]
    gif = iio.imread(folder / "demo.gif", index=None)
    assert gif.shape[:3] == (3, 16, 24)


def test_gif_can_be_resized(tmp_path):
    gif = write_gif(frames_of(2), tmp_path / "small.gif", width=12)
    assert iio.imread(gif, index=None).shape[:3] == (2, 8, 12)


def test_an_interrupted_run_keeps_every_finished_frame(tmp_path, monkeypatch):
    sequence = FrameSequence(tmp_path, gif=False)
    images = frames_of(3)
    sequence.write(images[0])
    sequence.write(images[1])

    def crash(path, image, **kwargs):                 # dies half-way through writing frame 2
        Path(path).write_bytes(b"\x89PNG half")
        raise KeyboardInterrupt

    monkeypatch.setattr("ti_cloth.render.image.iio.imwrite", crash)
    with pytest.raises(KeyboardInterrupt):
        sequence.write(images[2])
    monkeypatch.undo()
    finished = sorted(p.name for p in tmp_path.glob("frame_*.png"))
    assert finished == ["frame_00000.png", "frame_00001.png"]
    assert np.array_equal(iio.imread(tmp_path / "frame_00001.png"), images[1])
    assert not list(tmp_path.glob(".*tmp*")), "the half-written temporary file was left behind"


@pytest.mark.skipif(importlib.util.find_spec("imageio_ffmpeg") is None,
                    reason="imageio-ffmpeg (the optional MP4 writer) is not installed")
def test_mp4_holds_every_frame(tmp_path):
    images = frames_of(5, h=32, w=48)
    path = write_mp4(images, tmp_path / "clip.mp4", fps=10)
    import imageio.v2 as iio2

    with iio2.get_reader(path, format="FFMPEG") as reader:
        video = [frame for frame in reader]
    assert len(video) == 5 and video[0].shape == (32, 48, 3)
    for got, sent in zip(video, images):            # lossy codec: compare in float, loosely
        assert np.abs(got.astype(float) - sent.astype(float)).mean() < 8.0
    assert not list(tmp_path.glob(".*tmp*"))


def test_mp4_without_imageio_ffmpeg_says_what_to_install(tmp_path, monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "imageio_ffmpeg" else real(name, *a))
    with pytest.raises(ImportError, match=r"imageio-ffmpeg.*pip install"):
        write_mp4(frames_of(2), tmp_path / "clip.mp4")
    with pytest.raises(ImportError, match="imageio-ffmpeg"):
        FrameSequence(tmp_path, mp4=True)


def test_ghost_particles_are_never_drawn(f32):
    """A ghost-braced strand renders exactly like its strand particles alone (the same
    positions, pins and edges, no ghosts): in the 3-D renderer and the 2-D view."""
    from ti_cloth.render import Camera, Renderer, SurfaceStyle

    hair = tc.hair([[0.0, 0.0, 0.0]], 5, 0.5, directions=[[1.0, -0.3, 0.2]])
    real = ~hair.ghost
    strand = tc.Cloth.from_particles(hair.particle_position[real], hair.particle_mass[real],
                                     [[k, k + 1] for k in range(5)], pinned=[0, 1])
    camera = Camera.fit(strand, aspect=1.0)
    style = SurfaceStyle(particles=3.0, line_width=2.0)
    images = []
    for body in (hair, strand):
        sim = tc.Simulation(body, dt=1e-3)
        with Renderer(64, 64, camera) as r:
            r.begin()
            r.draw_simulation(sim, style)
            images.append(r.end())
        view = SpringView((np.array([-0.1, -0.3]), np.array([0.6, 0.2])), res=(64, 64))
        images.append(view.render(sim.positions(), body.spring_indices, body.spring_kind,
                                  sim.pinned(), ghost=body.ghost))
    assert images[0].std() > 1 and images[1].std() > 1, "something is drawn"
    np.testing.assert_array_equal(images[0], images[2])
    np.testing.assert_array_equal(images[1], images[3])


def test_a_frame_for_the_window_is_the_image_in_the_windows_layout(f32):
    """Renderer.end_window is the same frame as end(), in ti.GUI's layout: (width, height, 3),
    origin bottom-left. A sheet drawn off-centre, to the left and low, lands in the window's
    low x and low y."""
    from ti_cloth.render import Camera, Renderer

    cloth = tc.Cloth(tc.grid_mesh(4, 4, size=(0.3, 0.3), plane="xy", origin=(-0.5, -0.4, 0.0)),
                     tc.Material())
    sim = tc.Simulation(cloth, dt=1e-3)
    camera = Camera(position=(0.0, 0.0, 2.0), target=(0.0, 0.0, 0.0), fov=60)
    with Renderer(48, 32, camera, supersample=1) as r:
        r.begin()
        r.draw_simulation(sim)
        image = r.end()
        r.begin()
        r.draw_simulation(sim)
        window = r.end_window().copy()
    assert window.shape == (48, 32, 3) and image.shape == (32, 48, 3)
    np.testing.assert_array_equal(from_taichi(window), image)
    background = window[-1, -1].astype(int)
    drawn = np.abs(window.astype(int) - background).max(axis=2) > 30
    xs, ys = np.nonzero(drawn)
    assert len(xs) > 20 and xs.mean() < 24 and ys.mean() < 16, (xs.mean(), ys.mean())
