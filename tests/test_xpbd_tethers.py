"""XPBD's tethers (XPBD(tethers=s), energies/tethers.py): each particle within (1 + s) of its
rest geodesic distance from its nearest pins. The table against independent geodesics (a
flat sheet's straight lines, an L's way round its inner corner), the limit held in every step
where the passes alone break it, the sheet nearer the elastic one than the passes alone, a
pin let go that holds nothing (momentum's closed form), and bad values refused by name. Their
bits across launch plans and threads: test_stepping.py."""

import numpy as np
import pytest
from helpers import check_xpbd_scene_option, report

import ti_cloth as tc
from ti_cloth.energies.tethers import TETHERS, tether_table

DENIM = dict(density=0.324, stretch=5e3, shear=1e3, bending=1e-4)    # issue 53's sheet


def denim_sheet(n: int) -> tc.Cloth:
    mesh = tc.grid_mesh(rows=n, cols=n, size=(0.5, 0.5), plane="xz")
    return tc.Cloth(mesh, tc.Fabric(**DENIM), pinned=[0, n - 1])


def table(cloth: tc.Cloth):
    return tether_table(cloth.rest_position, cloth.mesh.triangles, np.zeros((0, 2)),
                        cloth.seam_indices, cloth.pinned)


def test_a_flat_sheets_tethers_are_the_straight_rest_distances_to_its_pins():
    """A flat square holds every straight line, so each particle's geodesic to a corner pin
    is the straight rest distance (the edge graph alone would give up to 8 % more), nearest
    pin first; the pins themselves have no tethers."""
    n = 9
    cloth = denim_sheet(n)
    anchors, lengths = table(cloth)
    rest = cloth.rest_position
    free = ~cloth.pinned
    assert anchors.shape == (n * n, TETHERS) and (anchors[cloth.pinned] == -1).all()
    assert (np.sort(anchors[free, :2], axis=1) == [0, n - 1]).all() and (anchors[:, 2:] == -1).all()
    straight = np.linalg.norm(rest[free, None, :] - rest[anchors[free, :2]], axis=2)
    np.testing.assert_allclose(lengths[free, :2], straight, rtol=1e-12)
    assert (np.diff(lengths[free, :2], axis=1) >= 0).all()


def test_an_l_shapes_tethers_go_round_its_inner_corner():
    """An L (a 2 x 2 m square less its upper right quarter) pinned at the end of its lower
    arm: a particle of the upper arm whose straight line to the pin would cross the missing
    quarter is tethered at no less than the way round the inner corner (|p - c| + |c - a|,
    computed here: a shorter tether would hold an unstretched L), and at most the edge
    graph's path (within sqrt 2 of it on this grid of right triangles); one it can see, at
    the straight distance."""
    mesh = tc.grid_mesh(rows=9, cols=9, size=(2.0, 2.0), plane="xy")
    x = mesh.vertices
    keep = ~((x[mesh.triangles][:, :, 0] > 1.0 + 1e-9).any(axis=1)
             & (x[mesh.triangles][:, :, 1] > 1.0 + 1e-9).any(axis=1))
    used, triangles = np.unique(mesh.triangles[keep], return_inverse=True)
    x = x[used]
    cloth = tc.Cloth(tc.Mesh(x, triangles.reshape(-1, 3)), tc.Material(),
                     pinned=[int(np.argmin(np.linalg.norm(x - [2.0, 0.0, 0.0], axis=1)))])
    anchors, lengths = table(cloth)
    pin, corner = cloth.pinned.nonzero()[0][0], np.array([1.0, 1.0, 0.0])
    assert (anchors[~cloth.pinned, 0] == pin).all()
    top = int(np.argmin(np.linalg.norm(x - [0.5, 2.0, 0.0], axis=1)))   # hidden from the pin
    round_corner = np.linalg.norm(x[top] - corner) + np.linalg.norm(corner - x[pin])
    report("tether of a hidden particle, the way round [m]", lengths[top, 0], round_corner)
    assert round_corner - 1e-12 <= lengths[top, 0] <= np.sqrt(2.0) * round_corner
    seen = int(np.argmin(np.linalg.norm(x - [0.0, 0.0, 0.0], axis=1)))
    assert lengths[seen, 0] == pytest.approx(np.linalg.norm(x[seen] - x[pin]), rel=1e-12)


def test_a_body_placed_farther_than_its_rest_keeps_that_distance():
    """A sheet placed 10 % larger than its rest shape about a pinned corner (a garment starts
    gathered and wrapped, up to 1.4x its pattern's geodesic from its pins): its tethers are
    the placed distances, so the first step snaps nothing into place; placed at rest, the
    rest distances."""
    mesh = tc.grid_mesh(rows=6, cols=6, size=(0.5, 0.5), plane="xz")
    placed = tc.Mesh(mesh.vertices * 1.1, mesh.triangles)
    cloth = tc.Cloth(placed, tc.Material(), rest=mesh, pinned=[0])
    anchors, lengths = tether_table(cloth.rest_position, cloth.mesh.triangles, np.zeros((0, 2)),
                                    cloth.seam_indices, cloth.pinned, cloth.particle_position)
    free = ~cloth.pinned
    assert (anchors[free, 0] == 0).all()
    x = cloth.particle_position
    np.testing.assert_allclose(lengths[free, 0], np.linalg.norm(x[free] - x[0], axis=1),
                               rtol=1e-12)
    _, at_rest = table(cloth)
    np.testing.assert_allclose(lengths[free, 0], 1.1 * at_rest[free, 0], rtol=1e-12)


def far_side(sim, cloth) -> float:
    """The largest distance / rest straight distance, over the particles and both pins."""
    x, rest = sim.positions(), cloth.rest_position
    free = ~cloth.pinned
    ratios = [np.linalg.norm(x[free] - x[p], axis=1) / np.linalg.norm(rest[free] - rest[p], axis=1)
              for p in np.flatnonzero(cloth.pinned)]
    return float(np.max(ratios))


@pytest.mark.parametrize("tethers", [None, 1e-3])
def test_tethers_hold_every_particle_within_its_strain_of_the_pins(f64, tethers):
    """Issue 53's denim sheet at 12², 4 passes a step at 1/240 s for 0.3 s: with tethers at
    0.1 % no particle ends a step farther than 1.001 x its straight rest distance from either
    pin (to rounding); without them the unconverged passes leave it 0.3-0.5 % long, which is
    what the test measures the tethers against."""
    cloth = denim_sheet(12)
    sim = tc.Simulation(cloth, integrator=tc.XPBD(iterations=4, scheme="bdf2", tethers=tethers),
                        dt=1 / 240)
    longest = 0.0
    for _ in range(72):
        sim.step(1)
        longest = max(longest, far_side(sim, cloth))
    report(f"longest, tethers {tethers}", longest - 1.0, "")
    if tethers is None:
        assert longest > 1.002
    else:
        assert longest <= 1.0 + tethers + 1e-12


def test_tethers_bring_unconverged_passes_nearer_the_elastic_sheet(f64):
    """Issue 53's denim sheet at 16², falling 0.3 s from two corners: against symplectic
    Euler at half its stable step (f64; 0.16 mm from itself at twice the step), xpbd's BDF2
    step with 4 passes at 1/240 s ends 34 mm away without tethers and 8.4 mm with tethers at
    0.1 % (measured): at least 3x nearer."""
    cloth = denim_sheet(16)
    dt = 0.5 * tc.stable_dt(cloth, "symplectic_euler", pinned=cloth.pinned)
    steps = round(0.3 / dt)
    reference = tc.Simulation(cloth, integrator="symplectic_euler", dt=0.3 / steps)
    reference.step(steps)
    errors = []
    for tethers in (None, 1e-3):
        sim = tc.Simulation(cloth, integrator=tc.XPBD(iterations=4, scheme="bdf2",
                                                     tethers=tethers), dt=1 / 240)
        sim.step(72)
        errors.append(np.linalg.norm(sim.positions() - reference.positions(), axis=1).max())
    report("max error without / with tethers [m]", errors, "")
    assert errors[1] < errors[0] / 3 and errors[1] < 0.015


def test_a_pin_let_go_holds_nothing(f64):
    """A string held at its top by a handle let go at 0.1 s, strict tethers (s = 0) to it:
    once let go, gravity is the only external force, so the mean velocity falls by exactly
    g t (XPBD's spring updates keep momentum; a tether still pulling toward the released top
    would not). Before, the handle holds it hanging (its tethers keep it from stretching):
    its mean velocity is nowhere near free fall's."""
    cloth = tc.string(8, 0.5, mass=0.05, stretch=tc.SpringParams(50.0, 0.0),
                      direction=(0.0, -1.0, 0.0), fixed="none")
    top = cloth.particle_position[0].copy()
    sim = tc.Simulation(cloth, integrator=tc.XPBD(iterations=6, tethers=0.0), dt=1 / 200,
                        handles=[tc.Handle([0], lambda t: top, release=0.1)])
    sim.step(20)
    held = sim.velocities().mean(axis=0)
    assert abs(held[1]) < 0.05 * 9.81 * 0.1
    sim.step(2)
    before = sim.velocities().mean(axis=0)
    sim.step(40)
    after = sim.velocities().mean(axis=0)
    report("mean velocity change over 0.2 s [m/s]", after - before, (0, -9.81 * 0.2, 0))
    np.testing.assert_allclose(after - before, [0.0, -9.81 * 0.2, 0.0], atol=1e-9)


def test_auto_tethers_take_the_strain_the_body_expects(f64):
    """tethers="auto": the strain at a pin of a strip as long as the longest tether, swung
    down from level, 2.5 g rho L / E (a uniform rod's tension at the bottom of that swing,
    over the strip's width): on the denim sheet, pinned at two corners, L is its diagonal and
    E its Young's modulus on the bias, 4 / (1/C11 + 1/C22 + 1/C33) with no Poisson coupling
    (2.86 kN/m, under the threads' 5 kN/m), 0.2 %; on an interlock knit, 300x softer, about
    17 % (its tethers then hold only what would tear it: a fixed 0.1 % held the knit flap of
    demos/study_fabric.toml short, 4x farther from the elastic flap than untethered)."""
    cloth = denim_sheet(12)
    integrator = tc.XPBD(scheme="bdf2", tethers="auto")
    sim = tc.Simulation(cloth, integrator=integrator, dt=1 / 240)
    sim.step(1)
    bias = 4.0 / (1 / 5e3 + 1 / 5e3 + 1 / 1e3)        # DENIM's stretch, stretch and shear
    expected = 2.5 * 9.81 * cloth.particle_mass.sum() / 0.25 * np.sqrt(0.5) / bias
    report("denim's expected strain", integrator.tether_strain, expected)
    assert integrator.tether_strain == pytest.approx(expected, rel=1e-9)
    assert 1.9e-3 < expected < 2e-3
    mesh = tc.grid_mesh(rows=6, cols=6, size=(0.6, 0.6), plane="xz")
    knit = tc.Cloth(mesh, tc.Fabric.preset("interlock"), pinned=[0, 5])
    loose = tc.XPBD(tethers="auto")
    tc.Simulation(knit, integrator=loose, dt=1 / 240).step(1)
    assert loose.tether_strain > 0.1


@pytest.mark.parametrize("value", [-0.01, 1.5, float("nan"), "a"])
def test_bad_tethers_are_refused_by_name(value):
    with pytest.raises(ValueError, match=r"XPBD\.tethers"):
        tc.XPBD(tethers=value)


def test_tethers_refuse_tearing():
    """A piece torn off would stay tied to its pin: the two are refused together, naming the
    field."""
    with pytest.raises(ValueError, match=r"tearing must be None when xpbd has tethers"):
        tc.Simulation(denim_sheet(6), integrator=tc.XPBD(tethers=1e-3), tearing=0.3)


def test_a_scene_file_sets_the_tethers(tmp_path):
    check_xpbd_scene_option(tmp_path, "tethers", 0.002, -0.5)
