"""The Cusick drape test (BS 5058): runs demos/cusick_drape.toml and prints the drape
coefficient and the number of folds of the settled disc; --presets settles a disc of every
fabric preset (no frames), bent by its measured table and by its zero-curvature rigidity
alone, and prints the table docs/fabrics.md quotes.

    python demos/cusick_drape.py             # renders/cusick_drape/frame_00000.png ... + measures
    python demos/cusick_drape.py --test      # tiny and fast
    python demos/cusick_drape.py --presets   # the table, one settled disc per preset

Drape coefficient (BS 5058): DC = (A_shadow - A_support) / (A_specimen - A_support), the
shadow the draped specimen casts straight down (its triangles projected onto the horizontal
plane, rasterised at 0.5 mm: ti_cloth.app.drape); 1 for a fabric that stays flat, lower the
more it drapes. Folds (nodes): the maxima of the hem's projected radius around the disc
standing at least 3 mm above the troughs on both sides. A scanned drape is measured, and a
Fabric fitted to it, by `ti-cloth fit SCAN --cusick` (docs/fabrics.md).
"""

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

import ti_cloth as tc
from ti_cloth.app.cli import demo_main
from ti_cloth.app.drape import FOLD_DEPTH, circular_folds, shadow_area
from ti_cloth.app.runner import state_path
from ti_cloth.app.scene import load_scene

SCENE = Path(__file__).with_suffix(".toml")
SUPPORT_RADIUS = 0.09     # the stand's disc [m]


def folds(positions: np.ndarray, rest: np.ndarray) -> int:
    """The hem's maxima of projected radius, around the disc, that stand FOLD_DEPTH above the
    lowest point between them and each neighbouring maximum (drape.circular_folds)."""
    centre = rest.mean(axis=0)
    radius = np.hypot(*(rest[:, [0, 2]] - centre[[0, 2]]).T)
    hem = np.flatnonzero(radius > radius.max() - 1e-9)
    hem = hem[np.argsort(np.arctan2(rest[hem, 2] - centre[2], rest[hem, 0] - centre[0]))]
    return circular_folds(np.hypot(*(positions[hem][:, [0, 2]] - centre[[0, 2]]).T), FOLD_DEPTH)


def measure(scene, positions: np.ndarray) -> tuple[float, int]:
    """(drape coefficient, folds) of the body of `scene` at `positions`."""
    rest = scene.cloth.particle_position
    triangles = scene.cloth.mesh.triangles
    specimen = shadow_area(rest[:, [0, 2]], triangles)
    support = np.pi * SUPPORT_RADIUS ** 2
    return ((shadow_area(positions[:, [0, 2]], triangles) - support) / (specimen - support),
            folds(positions, rest))


def settled(scene, fabric: tc.Fabric, seconds: float) -> np.ndarray:
    """The scene's disc made of `fabric`, settled for `seconds`."""
    cloth = tc.Cloth(scene.cloth.mesh, fabric,
                     pinned=np.flatnonzero(scene.cloth.pinned))
    sim = dataclasses.replace(scene, cloth=cloth, substeps="auto").build()
    sim.step(int(round(seconds / sim.dt)))
    return sim.positions()


def table(seconds: float) -> None:
    tc.init(arch="cpu")
    scene = load_scene(SCENE)
    print(f"{'preset':14} {'G warp/weft [uN m]':>20} {'density [g/m2]':>15} {'DC':>6} {'folds':>6}"
          f" {'DC flat':>8} {'folds flat':>10}")
    for name in tc.FABRICS:
        fabric = tc.Fabric.preset(name)            # bent by its measured table
        dc, n = measure(scene, settled(scene, fabric, seconds))
        flat = tc.Fabric.preset(name, bending_curve=None)   # its rigidity at zero curvature
        dc_flat, n_flat = measure(scene, settled(scene, flat, seconds))
        g = "/".join(f"{1e6 * b:.0f}" for b in fabric.bending)
        print(f"{name:14} {g:>20} {1000 * fabric.density:15.0f} {dc:6.2f} {n:6d} {dc_flat:8.2f} "
              f"{n_flat:10d}", flush=True)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    if "--presets" in argv:
        parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
        parser.add_argument("--presets", action="store_true")
        parser.add_argument("--seconds", type=float, default=3.0, help="settling time [s]")
        table(parser.parse_args(argv).seconds)
        return []
    frames = demo_main(SCENE, argv, __doc__.splitlines()[0])
    scene = load_scene(SCENE)
    sim = scene.build()
    sim.load_state(state_path(frames[-1].parent, scene.name))
    dc, n = measure(scene, sim.positions())
    print(f"{scene.name}: drape coefficient {dc:.2f}, {n} folds (t = {sim.time:.2f} s)")
    return frames


if __name__ == "__main__":
    main()
