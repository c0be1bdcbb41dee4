"""A cape gathered at the neck of a turning figure: runs demos/cape.toml and prints the
particles inside the figure in every frame.

    python demos/cape.py            # renders/cape/frame_00000.png ... + cape.gif
    python demos/cape.py --test     # tiny and fast
"""

from pathlib import Path

import numpy as np

from ti_cloth.app.cli import demo_main
from ti_cloth.app.scene import load_scene

SCENE = Path(__file__).with_suffix(".toml")


def main(argv=None):
    frames = demo_main(SCENE, argv, __doc__.splitlines()[0])
    record = frames[-1].parent / "cape.npz"              # the positions of every frame
    if record.is_file():
        figure = load_scene(SCENE).colliders[0]
        with np.load(record) as data:
            inside = [int(figure.inside(x, t).sum())
                      for x, t in zip(data["positions"], data["time"])]
        print(f"cape: particles inside the figure per frame: {inside} (most {max(inside)})")
    return frames


if __name__ == "__main__":
    main()
