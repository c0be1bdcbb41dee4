"""The lecture's dots-and-lines view: particles as dots, springs as lines coloured by kind,
drawn by Taichi's GUI with no window (show_gui=False)."""

import numpy as np
import taichi as ti

from ..body.material import SpringKind
from .image import from_taichi

KIND_COLOURS = {SpringKind.STRETCH: 0x4CAF50, SpringKind.SHEAR: 0x9C27B0, SpringKind.BEND: 0xFFC107}
PIN_COLOUR, PARTICLE_COLOUR, BACKGROUND = 0xE53935, 0x202020, 0xF5F5F5


FRONT = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))          # looking down -z, y up
OBLIQUE = ((1.0, 0.0, 0.4), (0.0, 1.0, 0.25))        # cabinet projection: depth drawn up-right


class SpringView:
    """Parallel projection of a body to 2-D: screen (u, v) = projection @ x, with `projection`
    a (2, 3) matrix (FRONT, OBLIQUE or your own); `bounds` ((u_min, v_min), (u_max, v_max)) in
    metres is the visible window, widened to the image's aspect."""

    def __init__(self, bounds, projection=FRONT, res=(512, 512), kinds=tuple(SpringKind),
                 particle_radius: float = 2.0):
        self.projection = np.asarray(projection, np.float64)
        if self.projection.shape != (2, 3):
            raise ValueError(f"projection must have shape (2, 3), got {self.projection.shape}")
        self.res, self.kinds, self.radius = res, tuple(kinds), particle_radius
        lo, hi = np.asarray(bounds, np.float64)
        if not np.all(hi > lo):
            raise ValueError(f"bounds must satisfy max > min on both axes, got {bounds!r}")
        # keep metres square: the visible window has the image's aspect and holds `bounds`
        aspect = res[0] / res[1]
        width = max(hi[0] - lo[0], (hi[1] - lo[1]) * aspect)
        self._size = np.array([width, width / aspect])
        self._lo = (lo + hi) / 2 - self._size / 2
        self._gui = ti.GUI("ti_cloth", res=res, background_color=BACKGROUND, show_gui=False)

    def _to_screen(self, points):
        return (points @ self.projection.T - self._lo) / self._size

    def render(self, positions, spring_indices, spring_kind, pinned, alive=None,
               ghost=None) -> np.ndarray:
        """(H, W, 3) uint8 image of the body at `positions` [m]; ghost particles (a mask) and
        their springs are not drawn."""
        gui = self._gui
        gui.clear(BACKGROUND)
        p = self._to_screen(np.asarray(positions, np.float64))
        keep = np.ones(len(spring_indices), bool) if alive is None else np.asarray(alive, bool)
        shown = np.ones(len(p), bool) if ghost is None else ~np.asarray(ghost, bool)
        keep = keep & shown[spring_indices[:, 0]] & shown[spring_indices[:, 1]]
        pinned = np.asarray(pinned, bool)
        p, pinned = p[shown], pinned[shown]
        spring_indices = np.cumsum(shown)[spring_indices] - 1
        for kind in self.kinds:
            sel = keep & (spring_kind == kind)
            if sel.any():
                i, j = spring_indices[sel].T
                gui.lines(p[i], p[j], radius=1, color=KIND_COLOURS[kind])
        gui.circles(p[~pinned], radius=self.radius, color=PARTICLE_COLOUR)
        if pinned.any():
            gui.circles(p[pinned], radius=self.radius * 2, color=PIN_COLOUR)
        return from_taichi(gui.get_image())
