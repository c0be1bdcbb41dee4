"""Images and files: the one place Taichi's (width, height, bottom-left origin) arrays become
numpy's (height, width, top-left origin) images; atomic PNG writing; frame sequences assembled
into an animated GIF or an MP4 (the latter through the optional imageio-ffmpeg)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from ..inputs.files import atomic_path, remove_temporaries
from ..inputs.validation import finite_number, require

MP4_HINT = "pip install 'ti_cloth[video]' (or: pip install imageio-ffmpeg)"


def from_taichi(image: np.ndarray) -> np.ndarray:
    """(W, H, C) float in [0, 1] or uint8, origin bottom-left -> (H, W, 3) uint8, origin top-left."""
    image = np.asarray(image)
    if image.dtype != np.uint8:
        image = (np.clip(image, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    return np.ascontiguousarray(np.flip(np.swapaxes(image[..., :3], 0, 1), axis=0))


def frame_path(folder, index: int) -> Path:
    """folder/frame_00000.png, ..."""
    return Path(folder) / f"frame_{index:05d}.png"


def write_png(path, image: np.ndarray) -> Path:
    """Write an (H, W, 3) uint8 image under a temporary name, then rename: an interrupted run
    never leaves a half-written frame."""
    path = Path(path)
    with atomic_path(path) as tmp:
        iio.imwrite(tmp, image)
    return path


def _images(frames, width: int | None = None):
    """Frames given as PNG paths or (H, W, 3) arrays, optionally resized to `width` pixels."""
    for frame in frames:
        image = iio.imread(frame) if isinstance(frame, (str, Path)) else np.asarray(frame)
        if width is not None and image.shape[1] != width:
            from PIL import Image

            height = max(1, round(image.shape[0] * width / image.shape[1]))
            image = np.asarray(Image.fromarray(image).resize((width, height), Image.LANCZOS))
        yield image


def write_gif(frames, path, fps: float = 30.0, width: int | None = None) -> Path:
    """Assemble frames (PNG paths or arrays) into a looping GIF, written atomically;
    width: resize to this many pixels wide (GIFs of full-HD frames are large)."""
    path = Path(path)
    fps = finite_number("fps", fps, 0.0, strict=True, unit="frames/s")
    require(width is None or (isinstance(width, int) and width > 0), "width", width,
            "a positive int or None")
    images = list(_images(frames, width))
    require(len(images) > 0, "frames", frames, "at least one frame")
    with atomic_path(path) as tmp:
        iio.imwrite(tmp, np.stack(images), duration=1000.0 / fps, loop=0)
    return path


def write_mp4(frames, path, fps: float = 30.0, quality: float = 8.0) -> Path:
    """Assemble frames (PNG paths or arrays) into an H.264 MP4, written atomically.
    Needs the optional imageio-ffmpeg package; quality: 0 (smallest) to 10 (best)."""
    if importlib.util.find_spec("imageio_ffmpeg") is None:
        raise ImportError(f"writing MP4 needs the optional package imageio-ffmpeg: {MP4_HINT}")
    import imageio.v2 as iio2

    path = Path(path)
    fps = finite_number("fps", fps, 0.0, strict=True, unit="frames/s")
    quality = finite_number("quality", quality, 0.0)
    require(quality <= 10, "quality", quality, "a number in [0, 10]")
    with atomic_path(path) as tmp:
        count = 0
        with iio2.get_writer(tmp, format="FFMPEG", mode="I", fps=fps, codec="libx264",
                             quality=quality, pixelformat="yuv420p", macro_block_size=2) as writer:
            for image in _images(frames):
                writer.append_data(image)
                count += 1
        require(count > 0, "frames", frames, "at least one frame")
    return path


class FrameSequence:
    """Numbered PNG frames in `folder` (frame_00000.png, ...), each written atomically as it
    comes, then assembled by `close` into `<name>.gif` and/or `<name>.mp4`. Frames left in the
    folder by an earlier, longer run, and temporary files of a killed one, are removed when the
    sequence starts. first: the frame the first write() is (a resumed run): frames 0 to
    first - 1 must be in the folder already and are kept (FileNotFoundError naming a missing
    one); later ones are removed (they are written again)."""

    def __init__(self, folder, *, fps: float = 30.0, gif: bool = True, mp4: bool = False,
                 name: str | None = None, gif_width: int | None = None, first: int = 0):
        self.folder = Path(folder)
        self.fps = finite_number("fps", fps, 0.0, strict=True, unit="frames/s")
        if mp4 and importlib.util.find_spec("imageio_ffmpeg") is None:
            raise ImportError(f"mp4=True needs the optional package imageio-ffmpeg: {MP4_HINT}")
        self.gif, self.mp4, self.gif_width = gif, mp4, gif_width
        self.name = name or self.folder.name
        self.paths = [frame_path(self.folder, k) for k in range(first)]
        for path in self.paths:
            if not path.is_file():
                raise FileNotFoundError(f"frame {path} is missing: the run cannot be resumed "
                                        "there; run it again from the start")
        self.folder.mkdir(parents=True, exist_ok=True)
        for stale in self.folder.glob("frame_[0-9][0-9][0-9][0-9][0-9].png"):
            if int(stale.stem[-5:]) >= first:
                stale.unlink()
        remove_temporaries(self.folder)

    def write(self, image: np.ndarray) -> Path:
        """Write the next frame; returns its path."""
        path = write_png(frame_path(self.folder, len(self.paths)), image)
        self.paths.append(path)
        return path

    def close(self) -> list[Path]:
        """Assemble the GIF / MP4 from the frames written so far; returns their paths."""
        outputs = []
        if self.paths and self.gif:
            outputs.append(write_gif(self.paths, self.folder / f"{self.name}.gif", self.fps,
                                     self.gif_width))
        if self.paths and self.mp4:
            outputs.append(write_mp4(self.paths, self.folder / f"{self.name}.mp4", self.fps))
        return outputs
