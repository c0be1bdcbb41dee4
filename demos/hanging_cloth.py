"""A sheet pinned at two corners falls and swings: runs demos/hanging_cloth.toml.

    python demos/hanging_cloth.py            # renders/hanging_cloth/frame_00000.png ... + hanging_cloth.gif
    python demos/hanging_cloth.py --test     # tiny and fast
"""

from pathlib import Path

from ti_cloth.app.cli import demo_main


def main(argv=None):
    return demo_main(Path(__file__).with_suffix(".toml"), argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
