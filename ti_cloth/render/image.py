"""Image layout and files: the one place Taichi's (width, height, bottom-left origin) arrays
become numpy's (height, width, top-left origin) images, and atomic PNG / GIF writing."""

from pathlib import Path

import imageio.v3 as iio
import numpy as np


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
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp.png")
    iio.imwrite(tmp, image)
    tmp.replace(path)
    return path


def write_gif(frames, path, fps: float = 30.0) -> Path:
    """Assemble PNG files (or arrays) into an animated GIF, written atomically."""
    path = Path(path)
    images = [iio.imread(f) if isinstance(f, (str, Path)) else f for f in frames]
    tmp = path.with_name(f".{path.stem}.tmp.gif")
    iio.imwrite(tmp, np.stack(images), duration=1000.0 / fps, loop=0)
    tmp.replace(path)
    return path
