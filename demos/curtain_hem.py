"""Curtains without (left) and with (right) a heavy hem: runs demos/curtain_hem.toml.

    python demos/curtain_hem.py            # renders/curtain_hem/frame_00000.png ... + curtain_hem.gif
    python demos/curtain_hem.py --test     # tiny and fast
"""

from pathlib import Path

from ti_cloth.app.cli import demo_main


def main(argv=None):
    return demo_main(Path(__file__).with_suffix(".toml"), argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
