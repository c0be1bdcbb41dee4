"""The lecture's Verlet + relaxation cloth with one particle pulled along a path: runs demos/verlet_pbd_cloth.toml.

    python demos/verlet_pbd_cloth.py            # renders/verlet_pbd_cloth/frame_00000.png ... + verlet_pbd_cloth.gif
    python demos/verlet_pbd_cloth.py --test     # tiny and fast
"""

from pathlib import Path

from ti_cloth.app.cli import demo_main


def main(argv=None):
    return demo_main(Path(__file__).with_suffix(".toml"), argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
