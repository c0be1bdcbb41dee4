"""A garment's rest state is its flat pattern (Cloth(rest=...)): rest angles, lengths and
metric from the panels, not from where they are placed, so a wrapped panel stores the
bending energy of the flat pattern bent round the body."""

import numpy as np
import pytest
from helpers import report

import ti_cloth as tc
from ti_cloth.energies.isometric import is_flat
from ti_cloth.physics.forces import energies

G = 1e-4            # isotropic flexural rigidity [N m]
FABRIC = tc.Fabric(density=0.2, stretch=(1e3, 1e3), shear=100.0, bending=(G, G))
RECTANGLE = [(-0.3, 0.0), (0.3, 0.0), (0.3, 0.3), (-0.3, 0.3)]


def wrapped(radius, edge_length=0.02, flare=0.0):
    piece = tc.panel(RECTANGLE, edge_length=edge_length).wrapped(radius, flare=flare)
    return tc.Garment([piece], seams=[])


def bending_at_placement(cloth):
    x = cloth.particle_position
    return energies(cloth, x, np.zeros_like(x), (0.0, 0.0, 0.0), isometric=is_flat(cloth))


def test_a_wrapped_panels_rest_is_its_pattern_angles_zero_lengths_the_patterns():
    """Onto a cone (lengths not kept round it): with rest="uv" every hinge's rest angle is
    the flat pattern's 0 and every spring's rest length the pattern's distance; from the
    placed mesh they are the cone's."""
    garment = wrapped(0.165, flare=0.25)
    placed = tc.Cloth(garment.mesh, FABRIC, warp="uv")
    pattern = tc.Cloth(garment.mesh, FABRIC, warp="uv", rest="uv")
    report("largest rest angle: placed, pattern", np.abs(placed.hinge_rest_angle).max(), "0")
    assert np.abs(placed.hinge_rest_angle).max() > 0.05
    assert np.abs(pattern.hinge_rest_angle).max() < 1e-12 and is_flat(pattern)
    springs = tc.Cloth(garment.mesh, tc.Material.preset("cotton_springs"), rest="uv")
    uv = garment.mesh.uvs
    i, j = springs.spring_indices.T
    np.testing.assert_allclose(springs.spring_rest_length, np.linalg.norm(uv[i] - uv[j], axis=1),
                               rtol=1e-12)
    a, b, c = (uv[pattern.face_indices[:, k]] for k in range(3))
    area = 0.5 * np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    np.testing.assert_allclose(pattern.face_area, area, rtol=1e-12)
    np.testing.assert_allclose(pattern.particle_mass.sum(), FABRIC.density * 0.6 * 0.3, rtol=1e-12)
    # the start is where the mesh places it
    np.testing.assert_array_equal(pattern.particle_position, garment.mesh.vertices)


@pytest.mark.parametrize("radius", [0.2, 0.4])
def test_placed_on_a_cylinder_it_stores_the_bending_of_the_flat_pattern_bent_round_it(radius):
    """A flat plate bent onto a cylinder of radius R stores 1/2 G A / R^2 (isotropic G, mean
    curvature 1/2R). With the pattern as rest the discrete energy converges to it at first
    order in the edge length (within 2.5 % at 2 cm, half that at 1 cm); with the placed mesh
    as rest it stores none."""
    closed = 0.5 * G * 0.6 * 0.3 / radius ** 2
    errors = []
    for edge in (0.02, 0.01):
        garment = wrapped(radius, edge_length=edge)
        stored = bending_at_placement(tc.Cloth(garment.mesh, FABRIC, warp="uv", rest="uv"))
        errors.append(abs(stored["bending"] / closed - 1))
        assert bending_at_placement(tc.Cloth(garment.mesh, FABRIC, warp="uv"))["bending"] == 0
    report(f"R = {radius}: bending energy error at 2 cm, 1 cm", errors, "< 2.5 %, halving")
    assert errors[0] < 0.025 and errors[1] < 0.6 * errors[0]


def test_a_rest_mesh_or_positions_and_bad_ones():
    mesh = tc.grid_mesh(4, 4, size=(0.3, 0.3), plane="xz")
    bent = tc.Mesh(mesh.vertices + [0.0, 0.1, 0.0] * (mesh.vertices[:, :1] ** 2), mesh.triangles)
    by_mesh = tc.Cloth(bent, FABRIC, rest=mesh)
    by_array = tc.Cloth(bent, FABRIC, rest=mesh.vertices)
    np.testing.assert_array_equal(by_mesh.face_gradient, by_array.face_gradient)
    np.testing.assert_array_equal(by_mesh.rest_position, mesh.vertices)
    assert np.abs(by_mesh.hinge_rest_angle).max() < 1e-12
    with pytest.raises(ValueError, match="rest must be a Mesh of the same 16 vertices"):
        tc.Cloth(bent, FABRIC, rest=tc.grid_mesh(3, 3))
    with pytest.raises(ValueError, match="rest"):
        tc.Cloth(bent, FABRIC, rest=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="texture coordinates in metres"):
        tc.Cloth(bent, FABRIC, rest="uv")
    with pytest.raises(ValueError, match='rest must be None, "uv"'):
        tc.Cloth(bent, FABRIC, rest="pattern")


def sewn_pair(width, height, edge, wrap=None):
    """Two panels, [-width, 0] and [0, width] by `height`, sewn along x = 0 (optionally
    wrapped onto a cylinder of radius `wrap`), and the one panel they make together."""
    left = tc.panel([(-width, 0), (0, 0), (0, height), (-width, height)], edge)
    right = tc.panel([(0, 0), (width, 0), (width, height), (0, height)], edge)
    whole = tc.panel([(-width, 0), (width, 0), (width, height), (-width, height)], edge)
    if wrap is not None:
        left, right, whole = (p.wrapped(wrap) for p in (left, right, whole))
    return tc.Garment([left, right], seams=[(0, 1, 1, 3)]), tc.Garment([whole], seams=[])


def test_a_seam_bends_as_the_cloth_two_sewn_panels_store_one_sheets_bending():
    """Two panels sewn edge to edge and wrapped onto a cylinder of radius R store the plate's
    1/2 G A / R^2 as one panel does (within 4 % at 2 cm edges on a 20 cm wide sheet): every
    sewn edge is a hinge between the panels' triangles, flat at rest. Unsewn (no hinge across
    the seam, as every seam was before) the same mesh stores 14 % less: the seam's column bent
    for free, a fin."""
    radius = 0.2
    closed = 0.5 * G * 0.2 * 0.3 / radius ** 2
    sewn, whole = sewn_pair(0.1, 0.3, 0.02, wrap=radius)
    pair = tc.Cloth(sewn.mesh, FABRIC, warp="uv", rest="uv", seams=sewn.seam_pairs)
    loose = tc.Cloth(sewn.mesh, FABRIC, warp="uv", rest="uv")
    one = tc.Cloth(whole.mesh, FABRIC, warp="uv", rest="uv")
    seam_edges = len(sewn.particles(0, 1)) - 1
    assert pair.hinge_count == loose.hinge_count + seam_edges
    assert is_flat(pair) and np.abs(pair.hinge_rest_angle).max() == 0.0
    stored = {name: bending_at_placement(c)["bending"] / closed
              for name, c in (("sewn", pair), ("unsewn", loose), ("one panel", one))}
    report("bending stored / 1/2 G A / R^2", stored, "sewn and one panel within 4 %")
    assert abs(stored["sewn"] - 1) < 0.04 and abs(stored["one panel"] - 1) < 0.08
    assert stored["unsewn"] < 0.9


@pytest.mark.parametrize("operator", ["isometric", "mid-edge"])
def test_a_sewn_cantilever_droops_as_one_strip(f64, operator):
    """A 10 cm strip clamped at one end (two columns pinned), sewn from two 5 cm panels,
    settles under gravity (implicit Euler at 1/100 s) with its tip where a strip cut in one piece has it, within 2 % of
    the droop (the triangulations differ): the seam's hinges carry the bending moment, and
    the implicit solve moves the seam's sewn pairs as one particle (symplectic Euler at its
    stable step gave the same tip within 0.2 %, measured: the explicit forces cross the seam
    as the implicit ones do). Unsewn across the seam the
    outer panel would hang from it (a droop of more than 5 cm against 2 cm); with separate
    implicit solves for the two sides of the seam the tip rose 1 cm above the clamp (both
    seen before the change). Tearing (at a strain never reached) switches the flat sheet's
    isometric bending to the mid-edge operator."""
    rigidity = 1e-3
    fabric = tc.Fabric(density=0.2, stretch=(1e3, 1e3), shear=100.0, bending=(rigidity, rigidity))
    edge, length = 0.005, 0.1
    sewn, whole = sewn_pair(length / 2, 0.03, edge)
    tearing = 1e6 if operator == "mid-edge" else None
    drops = []
    for garment, seams in ((whole, None), (sewn, sewn.seam_pairs)):
        uv = garment.mesh.uvs
        cloth = tc.Cloth(garment.mesh, fabric, warp="uv", rest="uv", seams=seams,
                         pinned=np.flatnonzero(uv[:, 0] < -length / 2 + 1.1 * edge))
        sim = tc.Simulation(cloth, integrator="implicit_euler", dt=0.01, gravity=(0.0, 0.0, -9.81),
                            drag=8.0, tearing=tearing)
        sim.step(200)                                   # 2 s: settled
        tip = np.isclose(uv[:, 0], length / 2)
        drops.append(-sim.positions()[tip, 2].mean())
    report(f"implicit Euler, {operator}: tip droop one piece, sewn (m)", drops, "equal within 2 %")
    assert 0.01 < drops[0] < 0.04
    assert abs(drops[1] / drops[0] - 1) < 0.02
