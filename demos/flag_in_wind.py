"""A flag on a pole in gusty, turbulent wind: runs demos/flag_in_wind.toml.

    python demos/flag_in_wind.py            # renders/flag_in_wind/frame_00000.png ... + flag_in_wind.gif
    python demos/flag_in_wind.py --test     # tiny and fast
"""

from pathlib import Path

from ti_cloth.app.cli import demo_main


def main(argv=None):
    return demo_main(Path(__file__).with_suffix(".toml"), argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
