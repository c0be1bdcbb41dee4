"""Headless rendering. The simulation never imports this package."""

from .image import frame_path, from_taichi, write_gif, write_png
from .springs2d import FRONT, OBLIQUE, SpringView

__all__ = ["frame_path", "from_taichi", "write_gif", "write_png", "SpringView", "FRONT", "OBLIQUE"]
