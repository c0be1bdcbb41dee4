"""A skirt sewn from two panels on a walking figure: runs demos/skirt_walk.toml.

    python demos/skirt_walk.py            # renders/skirt_walk/frame_00000.png ... + skirt_walk.gif
    python demos/skirt_walk.py --test     # tiny and fast
"""

from pathlib import Path

from ti_cloth.app.cli import demo_main


def main(argv=None):
    return demo_main(Path(__file__).with_suffix(".toml"), argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
