"""A skirt sewn from two panels on a walking figure: runs demos/skirt_walk.toml and prints the
hem's folds and the particles inside the figure in every frame.

    python demos/skirt_walk.py            # renders/skirt_walk/frame_00000.png ... + skirt_walk.gif
    python demos/skirt_walk.py --test     # tiny and fast

Folds: the hem (the particles on the panels' bottom edges, pattern y = 0) taken round the
body's vertical axis in angle order; its radial offset from its mean circle changes sign
twice a fold (out, then in), counted with a FOLD_DEADBAND so that a particle's jitter about
the circle is not a fold.
"""

from pathlib import Path

import numpy as np

from ti_cloth.app.cli import demo_main
from ti_cloth.app.scene import load_scene

SCENE = Path(__file__).with_suffix(".toml")
FOLD_DEADBAND = 1e-3      # m: an offset within this of the mean circle keeps the last sign


def hem_of(cloth) -> np.ndarray:
    """The hem's particles: those on the pattern's lowest line (the panels' bottom edges)."""
    rest = cloth.rest_position
    return np.flatnonzero(np.isclose(rest[:, 1], rest[:, 1].min(), atol=1e-9))


def hem_folds(positions: np.ndarray, hem: np.ndarray) -> int:
    """Folds of the hem at `positions`: sign changes of its radial offset from its mean
    circle, round the loop in angle order about the vertical axis through its centre, / 2."""
    x = positions[hem][:, [0, 2]]
    centre = x.mean(axis=0)
    angle = np.arctan2(x[:, 1] - centre[1], x[:, 0] - centre[0])
    radius = np.hypot(*(x - centre).T)[np.argsort(angle)]
    offset = radius - radius.mean()
    signs = np.sign(np.where(np.abs(offset) > FOLD_DEADBAND, offset, 0.0))
    signs = signs[signs != 0]
    if len(signs) < 2:
        return 0
    return int((signs != np.roll(signs, 1)).sum()) // 2


def main(argv=None):
    frames = demo_main(SCENE, argv, __doc__.splitlines()[0])
    record = frames[-1].parent / "skirt_walk.npz"        # the positions of every frame
    if record.is_file():
        scene = load_scene(SCENE)
        figure = scene.colliders[0]
        with np.load(record) as data:
            hem = np.searchsorted(data["particle"], hem_of(scene.cloth))
            counts = [hem_folds(x, hem) for x in data["positions"]]
            inside = [int(figure.inside(x, t).sum())
                      for x, t in zip(data["positions"], data["time"])]
        print(f"skirt_walk: hem folds per frame: {counts} (most {max(counts)})")
        print(f"skirt_walk: particles inside the figure per frame: {inside} "
              f"(most {max(inside)})")
    return frames


if __name__ == "__main__":
    main()
