"""Styled straight and curly hair (ghost-braced strands) on swaying heads: runs demos/hair.toml.

    python demos/hair.py            # renders/hair/frame_00000.png ... + hair.gif
    python demos/hair.py --test     # tiny and fast
"""

from pathlib import Path

from ti_cloth.app.cli import demo_main


def main(argv=None):
    return demo_main(Path(__file__).with_suffix(".toml"), argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
