"""What a Fabric's step costs against a step of Stuyck's springs on the same mesh.

The scene: grid_mesh(N, N), two corners pinned, gravity, at rest, stepped by symplectic Euler
with one dt for all bodies (half the smallest of their stable steps): the default Material
(stretch, shear and bend springs: about 6 per particle), Fabric.preset("denim",
bending_curve=None) on the flat grid (a membrane per triangle, 2 per particle, and the
isometric bending of a flat sheet: a row of its constant Q per particle), the same fabric on
the grid bowed to a 10 m radius (curved at rest: bending by the mid-edge tangents, a hinge per
interior edge, about 3 per particle), and the preset with its measured BendingCurve on the
flat grid (the mid-edge tangents too, each triangle's rigidity looked up in the table:
energies/bending_law.py). All run the full simulator (Simulation.step, many steps per launch, divergence
guard included). Rates are medians of --repeats rounds, each timing every variant in turn for
about --seconds, in the same process; a cost is the median over the rounds of the ratio of
the spring step's rate to the variant's in that round.

--newton also times Newton's semi-implicit cloth on the same mesh, particles, pins and dt:
SolverSemiImplicit with its triangle FEM (tri_ke = tri_ka = the fabric's mean stretch / 2,
tri_kd from its damping) and dihedral bending (edge_ke = its mean rigidity), its contacts
reduced to nothing (ti_cloth's sheet has no self-collision either): triangle contact off and
particles of radius 1e-5 m for its particle-particle grid (its defaults made it 18 steps/s at
32^2), f32 (newton 1.8, benchmarks/peers.py). Its laws are not ti_cloth's, so its trajectory is not checked against
ours; the run checks only that it stayed finite.

    python benchmarks/fabric_step.py [--sizes 32 64 128] [--precision f32] [--arch cpu] [--newton]
"""

import argparse
import statistics

import numpy as np
import peers
from throughput import NEWTON_CHECKED, NewtonCloth, interleaved_rates, median_rate

import ti_cloth as tc


def bodies(n: int) -> dict[str, tc.Cloth]:
    mesh = tc.grid_mesh(n, n, (1.0, 1.0))
    pinned = [n * (n - 1), n * n - 1]
    x = mesh.vertices
    bowed = tc.Mesh(x + np.outer(10.0 - np.sqrt(100.0 - (x[:, 0] - 0.5) ** 2), [0, 0, 1]),
                    mesh.triangles)
    constant = tc.Fabric.preset("denim", bending_curve=None)
    return {"springs": tc.Cloth(mesh, tc.Material(), pinned=pinned),
            "fabric": tc.Cloth(mesh, constant, pinned=pinned),
            "curved": tc.Cloth(bowed, constant, pinned=pinned),
            "table": tc.Cloth(mesh, tc.Fabric.preset("denim"), pinned=pinned)}


class NewtonFabric(NewtonCloth):
    """Newton's semi-implicit cloth (triangle FEM, dihedral bending) on `cloth`'s mesh;
    stepped and read as throughput.py's NewtonCloth."""

    def __init__(self, cloth: tc.Cloth, fabric: tc.Fabric, dt: float):
        peers.require("newton", NEWTON_CHECKED, "--newton")
        import newton
        import warp as wp
        wp.config.quiet = True
        self.wp, self.device, self.dt = wp, "cpu", dt
        builder = newton.ModelBuilder(up_axis=newton.Axis.Y, gravity=(0.0, -9.81, 0.0))
        stretch = float(np.mean(fabric.stretch))
        builder.add_cloth_mesh(pos=(0.0, 0.0, 0.0), rot=wp.quat_identity(), scale=1.0,
                               vel=(0.0, 0.0, 0.0), vertices=[tuple(v) for v in cloth.mesh.vertices],
                               indices=cloth.mesh.triangles.ravel().tolist(),
                               density=fabric.density, tri_ke=stretch / 2, tri_ka=stretch / 2,
                               tri_kd=fabric.damping * stretch / 2,
                               edge_ke=float(np.mean(fabric.bending)),
                               edge_kd=fabric.damping * float(np.mean(fabric.bending)),
                               particle_radius=1e-5)
        for i in np.flatnonzero(cloth.pinned):
            builder.particle_mass[i] = 0.0
        self.model = builder.finalize(device="cpu")
        self.solver = newton.solvers.SolverSemiImplicit(self.model, enable_tri_contact=False)
        self.states = [self.model.state(), self.model.state()]
        self.control = self.model.control()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128])
    parser.add_argument("--precision", default="f32", choices=("f32", "f64"))
    parser.add_argument("--arch", default="cpu")
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--newton", action="store_true", help="also time Newton's cloth")
    args = parser.parse_args()
    tc.init(arch=args.arch, precision=args.precision)
    print(f"symplectic Euler, {args.precision}, {args.arch}, medians of {args.repeats} runs")
    print(f"{'N':>5} {'particles':>9} {'springs steps/s':>16} {'fabric steps/s':>15} "
          f"{'fabric cost / springs':>22} {'curved steps/s':>15} {'curved cost / springs':>22}"
          f" {'table steps/s':>14} {'table cost / springs':>21}"
          + (f" {'Newton steps/s':>15} {'fabric / Newton':>16}" if args.newton else ""))
    for n in args.sizes:
        cloths = bodies(n)
        dt = 0.5 * min(tc.stable_dt(c, "symplectic_euler") for c in cloths.values())
        sims = {name: tc.Simulation(cloth, integrator="symplectic_euler", dt=dt)
                for name, cloth in cloths.items()}
        rounds = interleaved_rates({name: (sim.step, sim.velocities) for name, sim in sims.items()},
                                   args.seconds, args.repeats)
        rates = {name: statistics.median(r) for name, r in rounds.items()}
        cost = {name: statistics.median(np.divide(rounds["springs"], rounds[name]))
                for name in ("fabric", "curved", "table")}
        line = (f"{n:>5} {n * n:>9} {rates['springs']:>16.1f} {rates['fabric']:>15.1f} "
                f"{cost['fabric']:>22.2f} {rates['curved']:>15.1f} {cost['curved']:>22.2f}"
                f" {rates['table']:>14.1f} {cost['table']:>21.2f}")
        if args.newton:
            peer = NewtonFabric(cloths["fabric"], tc.Fabric.preset("denim", bending_curve=None), dt)
            rate = median_rate(peer.step, peer.sync, args.seconds, args.repeats)
            finite = "" if np.isfinite(peer.velocities()).all() else " (diverged)"
            line += f" {rate:>15.1f} {rates['fabric'] / rate:>16.2f}{finite}"
        print(line, flush=True)


if __name__ == "__main__":
    main()
