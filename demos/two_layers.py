"""Silk under denim draped over a table (self-collision): runs demos/two_layers.toml.

    python demos/two_layers.py            # renders/two_layers/frame_00000.png ... + two_layers.gif
    python demos/two_layers.py --test     # tiny and fast
"""

from pathlib import Path

from ti_cloth.app.cli import demo_main


def main(argv=None):
    return demo_main(Path(__file__).with_suffix(".toml"), argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
