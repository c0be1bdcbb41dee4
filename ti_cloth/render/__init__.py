"""Headless rendering into numpy images and image files. The simulation never imports this
package; nothing here opens a window or needs a display or a graphics stack."""

from .camera import Camera
from .image import FrameSequence, frame_path, from_taichi, write_gif, write_mp4, write_png
from .renderer import Background, Light, NullRenderer, Renderer, SurfaceStyle
from .springs2d import FRONT, OBLIQUE, SpringView
from .strain import vertex_strain

__all__ = [
    "Camera", "FrameSequence", "frame_path", "from_taichi", "write_gif", "write_mp4", "write_png",
    "Background", "Light", "NullRenderer", "Renderer", "SurfaceStyle", "FRONT", "OBLIQUE",
    "SpringView", "vertex_strain",
]
