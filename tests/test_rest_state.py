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
