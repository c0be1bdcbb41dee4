"""Write the collider meshes the demos load (committed beside this script; run it again after
changing a shape):

- table.obj: a 1.2 m x 0.8 m table, 0.76 m high (a 4 cm top on four 5 cm legs), for tablecloth;
- pedestal.obj: a 0.5 m square pedestal, 0.6 m high, with a 4 cm rim plate, for turntable;
- cusick_stand.obj: the drape tester's stand (BS 5058), an 18 cm disc on a 30 cm column, for
  cusick_drape;
- cusick_disc.obj: its 30 cm specimen (tc.disc_mesh, 20 rings: 7.5 mm edges) 2 mm above it.

Boxes with each face on its own vertices (the renderer shades them flat), and cylinders whose
caps are apart from their sides.

    python demos/assets/make_assets.py
"""

from pathlib import Path

import numpy as np

import ti_cloth as tc

HERE = Path(__file__).parent


def table():
    top = tc.box_mesh((-0.6, 0.72, -0.4), (0.6, 0.76, 0.4))
    legs = [tc.box_mesh((x - 0.025, 0.0, z - 0.025), (x + 0.025, 0.72, z + 0.025))
            for x in (-0.52, 0.52) for z in (-0.32, 0.32)]
    return tc.combine_meshes([top, *legs])


def pedestal():
    column = tc.box_mesh((-0.2, 0.0, -0.2), (0.2, 0.56, 0.2))
    plate = tc.box_mesh((-0.25, 0.56, -0.25), (0.25, 0.6, 0.25))
    return tc.combine_meshes([column, plate])


def cylinder(radius, bottom, top, sides=48):
    """A closed upright cylinder on the y axis: a side of `sides` quads, two capped discs."""
    angle = 2 * np.pi * np.arange(sides) / sides
    ring = np.stack([radius * np.cos(angle), np.zeros(sides), -radius * np.sin(angle)], 1)
    k = np.arange(sides)
    nxt = (k + 1) % sides
    side = tc.Mesh(np.vstack([ring + [0, bottom, 0], ring + [0, top, 0]]),
                   np.concatenate([np.stack([k, nxt, sides + nxt], 1),
                                   np.stack([k, sides + nxt, sides + k], 1)]))
    caps = []
    for y, up in ((top, True), (bottom, False)):
        fan = np.stack([np.zeros(sides, int), 1 + k, 1 + nxt], 1)
        caps.append(tc.Mesh(np.vstack([[0, y, 0], ring + [0, y, 0]]),
                            fan if up else fan[:, ::-1]))
    return tc.combine_meshes([side, *caps])


STAND_TOP = 0.3      # the specimen lies on the stand's disc at this height [m]


def cusick_stand():
    return tc.combine_meshes([cylinder(0.09, STAND_TOP - 0.01, STAND_TOP),
                              cylinder(0.03, 0.0, STAND_TOP - 0.01, sides=24)])


def cusick_disc():
    return tc.disc_mesh(0.15, 20, centre=(0.0, STAND_TOP + 0.002, 0.0))


def main():
    for name, mesh in (("table", table()), ("pedestal", pedestal()),
                       ("cusick_stand", cusick_stand()), ("cusick_disc", cusick_disc())):
        tc.save_mesh(HERE / f"{name}.obj", mesh)
        print(f"{HERE / name}.obj: {mesh.vertex_count} vertices, {mesh.triangle_count} triangles")


if __name__ == "__main__":
    main()
