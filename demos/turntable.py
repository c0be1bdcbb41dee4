"""A cloth on a spinning pedestal (a turning mesh collider): runs demos/turntable.toml.

    python demos/turntable.py            # renders/turntable/frame_00000.png ... + turntable.gif
    python demos/turntable.py --test     # tiny and fast
"""

from pathlib import Path

from ti_cloth.app.cli import demo_main


def main(argv=None):
    return demo_main(Path(__file__).with_suffix(".toml"), argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
