"""Stuyck ch. 4 as written (explicit Euler, relative damping): runs demos/stuyck_explicit.toml.

    python demos/stuyck_explicit.py            # renders/stuyck_explicit/frame_00000.png ... + stuyck_explicit.gif
    python demos/stuyck_explicit.py --test     # tiny and fast
"""

from pathlib import Path

from ti_cloth.app.cli import demo_main


def main(argv=None):
    return demo_main(Path(__file__).with_suffix(".toml"), argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
