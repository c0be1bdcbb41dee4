"""A sheet torn apart by two handles pulling in opposite directions: runs demos/tearing.toml.

    python demos/tearing.py            # renders/tearing/frame_00000.png ... + tearing.gif
    python demos/tearing.py --test     # tiny and fast
"""

from pathlib import Path

from ti_cloth.app.cli import demo_main


def main(argv=None):
    return demo_main(Path(__file__).with_suffix(".toml"), argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
