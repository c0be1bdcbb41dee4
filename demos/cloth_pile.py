"""A sheet collapsing onto the ground into folds (self-collision): runs demos/cloth_pile.toml.

    python demos/cloth_pile.py            # renders/cloth_pile/frame_00000.png ... + cloth_pile.gif
    python demos/cloth_pile.py --test     # tiny and fast
"""

from pathlib import Path

from ti_cloth.app.cli import demo_main


def main(argv=None):
    return demo_main(Path(__file__).with_suffix(".toml"), argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
