"""Write the collider meshes the demos load (committed beside this script; run it again after
changing a shape):

- table.obj: a 1.2 m x 0.8 m table, 0.76 m high (a 4 cm top on four 5 cm legs), for tablecloth;
- pedestal.obj: a 0.5 m square pedestal, 0.6 m high, with a 4 cm rim plate, for turntable.

Boxes only, each face with its own vertices, so the renderer shades them flat.

    python demos/assets/make_assets.py
"""

from pathlib import Path

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


def main():
    for name, mesh in (("table", table()), ("pedestal", pedestal())):
        tc.save_mesh(HERE / f"{name}.obj", mesh)
        print(f"{HERE / name}.obj: {mesh.vertex_count} vertices, {mesh.triangle_count} triangles")


if __name__ == "__main__":
    main()
