"""A cape attached at the shoulders of a turning figure: runs demos/cape.toml.

    python demos/cape.py            # renders/cape/frame_00000.png ... + cape.gif
    python demos/cape.py --test     # tiny and fast
"""

from pathlib import Path

from ti_cloth.app.cli import demo_main


def main(argv=None):
    return demo_main(Path(__file__).with_suffix(".toml"), argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
