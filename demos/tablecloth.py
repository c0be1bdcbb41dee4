"""A tablecloth falls onto a table mesh (a mesh collider): runs demos/tablecloth.toml.

    python demos/tablecloth.py            # renders/tablecloth/frame_00000.png ... + tablecloth.gif
    python demos/tablecloth.py --test     # tiny and fast
"""

from pathlib import Path

from ti_cloth.app.cli import demo_main


def main(argv=None):
    return demo_main(Path(__file__).with_suffix(".toml"), argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
