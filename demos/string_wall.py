"""The lecture's elastic string, fixed to a wall at one end: runs demos/string_wall.toml.

    python demos/string_wall.py            # renders/string_wall/frame_00000.png ... + string_wall.gif
    python demos/string_wall.py --test     # tiny and fast
"""

from pathlib import Path

from ti_cloth.app.cli import demo_main


def main(argv=None):
    return demo_main(Path(__file__).with_suffix(".toml"), argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
