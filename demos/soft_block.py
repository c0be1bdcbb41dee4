"""A soft tetrahedral block dropping onto the ground and bouncing back to shape: runs demos/soft_block.toml.

    python demos/soft_block.py            # renders/soft_block/frame_00000.png ... + soft_block.gif
    python demos/soft_block.py --test     # tiny and fast
"""

from pathlib import Path

from ti_cloth.app.cli import demo_main


def main(argv=None):
    return demo_main(Path(__file__).with_suffix(".toml"), argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
