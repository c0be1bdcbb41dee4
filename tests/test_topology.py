"""Springs, rest lengths and lumped masses (Stuyck 4.2, fig. 4.2), on the host."""

import numpy as np
import pytest
from helpers import report

import ti_cloth as tc
from ti_cloth.body.fabric import PRESETS as FABRIC_PRESETS
from ti_cloth.body.topology import color_springs, mesh_springs, unique_springs

K = tc.SpringKind


def grid_cloth(rows=4, cols=5, width=2.0, height=1.5, **material):
    return tc.Cloth(tc.grid_mesh(rows, cols, size=(width, height)), tc.Material(**material))


def test_masses_sum_to_density_times_area_plus_hem():
    """The default hem of a grid is its bottom edge: cols particles."""
    rows, cols, width, height, rho, hem = 5, 7, 2.0, 1.5, 0.3, 0.01
    cloth = grid_cloth(rows, cols, width, height, density=rho, hem_mass=hem)
    expected = rho * width * height + hem * cols
    report("total mass", cloth.particle_mass.sum(), expected)
    assert cloth.particle_mass.sum() == pytest.approx(expected, rel=1e-12)


def test_grid_masses_match_hand_computation():
    rows, cols, width, height, rho = 4, 5, 2.0, 1.5, 0.3
    cloth = grid_cloth(rows, cols, width, height, density=rho)
    quad = rho * (width / (cols - 1)) * (height / (rows - 1))  # two triangles of quad / 2 each
    m = cloth.particle_mass.reshape(rows, cols)
    # interior: 6 triangles x (quad/2)/3 = quad; edge: 3 triangles = quad/2;
    # corners on the cut diagonal (0,0) and (top,right): 2 triangles = quad/3; others 1 = quad/6.
    expected = {"interior": (m[1:-1, 1:-1], quad), "bottom edge": (m[0, 1:-1], quad / 2),
                "left edge": (m[1:-1, 0], quad / 2), "corner (0,0)": (m[0, 0], quad / 3),
                "corner (top,right)": (m[-1, -1], quad / 3), "corner (0,right)": (m[0, -1], quad / 6),
                "corner (top,0)": (m[-1, 0], quad / 6)}
    for label, (got, want) in expected.items():
        report(label, np.unique(got), want)
        np.testing.assert_allclose(got, want, rtol=1e-12)


def test_hem_mass_goes_to_the_hem_never_to_pins_and_override_wins():
    """A 4 x 5 grid (rows x cols, row 0 at the bottom), hem_mass 0.05 kg, corner 0 pinned:
    the extra mass per particle, written out by hand for each choice of hem."""
    plain = grid_cloth(density=0.3)

    def extra(**options):
        body = tc.Cloth(tc.grid_mesh(4, 5, size=(2.0, 1.5)), tc.Material(density=0.3, hem_mass=0.05),
                        pinned=[0], **options)
        return ((body.particle_mass - plain.particle_mass) / 0.05).round(12).reshape(4, 5)

    by_hand = {
        "default (bottom)": ({}, [[0, 1, 1, 1, 1], [0] * 5, [0] * 5, [0] * 5]),
        "left": (dict(hem="left"), [[0, 0, 0, 0, 0], [1, 0, 0, 0, 0], [1, 0, 0, 0, 0], [1, 0, 0, 0, 0]]),
        "boundary": (dict(hem="boundary"), [[0, 1, 1, 1, 1], [1, 0, 0, 0, 1], [1, 0, 0, 0, 1],
                                            [1, 1, 1, 1, 1]]),
        "indices": (dict(hem=[0, 7, 19]), [[0, 0, 0, 0, 0], [0, 0, 1, 0, 0], [0] * 5, [0, 0, 0, 0, 1]]),
        "none": (dict(hem=[]), [[0] * 5] * 4),
    }
    for label, (options, expected) in by_hand.items():
        np.testing.assert_array_equal(extra(**options), expected, err_msg=label)
    mesh = tc.Mesh(tc.grid_mesh(4, 5).vertices, tc.grid_mesh(4, 5).triangles)    # not a grid
    body = tc.Cloth(mesh, tc.Material(hem_mass=0.05))
    np.testing.assert_array_equal(np.flatnonzero(body.hem), mesh.boundary_vertices())
    override = tc.Cloth(tc.grid_mesh(4, 5), tc.Material(hem_mass=0.05), particle_mass_override={2: 1.25})
    assert override.particle_mass[2] == 1.25 and override.hem[2]
    with pytest.raises(ValueError, match="hem must be particle indices or names of .* got 'hem'"):
        tc.Cloth(tc.grid_mesh(4, 5), tc.Material(), hem="hem")
    with pytest.raises(ValueError, match=r"hem must be particle indices in \[0, 19\], got \[20\]"):
        tc.Cloth(tc.grid_mesh(4, 5), tc.Material(), hem=[20])


@pytest.mark.parametrize("rows, cols", [(2, 2), (2, 5), (3, 3), (4, 7), (9, 6)])
def test_grid_spring_counts_match_formula(rows, cols):
    cloth = grid_cloth(rows, cols)
    counts = cloth.spring_count_by_kind()
    expected = {"stretch": rows * (cols - 1) + cols * (rows - 1),
                "shear": 2 * (rows - 1) * (cols - 1),
                "bend": rows * max(cols - 2, 0) + cols * max(rows - 2, 0)}
    report(f"{rows}x{cols} springs", counts, expected)
    assert counts == expected
    pairs = cloth.spring_indices
    assert np.all(pairs[:, 0] < pairs[:, 1])
    assert len(np.unique(pairs, axis=0)) == len(pairs), "duplicate springs"


def test_grid_rest_lengths():
    rows, cols, width, height = 4, 5, 2.0, 1.5
    cloth = grid_cloth(rows, cols, width, height)
    dx, dy = width / (cols - 1), height / (rows - 1)
    i, j = cloth.spring_indices.T
    di, dj = np.abs(j % cols - i % cols), np.abs(j // cols - i // cols)
    for kind, allowed in [(K.STRETCH, {(1, 0): dx, (0, 1): dy}),
                          (K.SHEAR, {(1, 1): np.hypot(dx, dy)}),
                          (K.BEND, {(2, 0): 2 * dx, (0, 2): 2 * dy})]:
        sel = cloth.spring_kind == kind
        steps = set(zip(di[sel].tolist(), dj[sel].tolist()))
        assert steps == set(allowed), f"{kind.name}: grid steps {steps}"
        for step, length in allowed.items():
            s = sel & (di == step[0]) & (dj == step[1])
            np.testing.assert_allclose(cloth.spring_rest_length[s], length, rtol=1e-12)


def test_general_mesh_rule_on_two_triangles():
    # square split along 0-2: edges 01 12 20 23 30; the interior edge 0-2 bends 1-3
    mesh = tc.Mesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]])
    cloth = tc.Cloth(mesh, tc.Material())
    stretch = cloth.spring_indices[cloth.spring_kind == K.STRETCH].tolist()
    bend = cloth.spring_indices[cloth.spring_kind == K.BEND].tolist()
    assert sorted(stretch) == [[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]
    assert bend == [[1, 3]]
    np.testing.assert_allclose(cloth.spring_rest_length[cloth.spring_kind == K.BEND], np.sqrt(2))
    assert cloth.triangle_edge_spring.min() >= 0


def test_closed_mesh_drops_bend_springs_that_repeat_edges():
    # a tetrahedron's surface: every opposite pair across an edge is itself an edge
    tet = tc.Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
                  [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    raw = mesh_springs(tet.triangles)
    assert len(raw[K.STRETCH]) == 6 and len(raw[K.BEND]) == 6
    pairs, kind = unique_springs(raw)
    assert len(pairs) == 6 and np.all(kind == K.STRETCH)


def test_explicit_springs_by_kind_and_duplicates_rejected():
    mesh = tc.grid_mesh(3, 3)
    cloth = tc.Cloth(mesh, tc.Material(), springs={"stretch": [[0, 1], [1, 2]], "bend": [[0, 2]]})
    assert cloth.spring_count_by_kind() == {"stretch": 2, "shear": 0, "bend": 1}
    np.testing.assert_allclose(cloth.spring_rest_length, [0.5, 0.5, 1.0])
    assert cloth.spring_stiffness.tolist() == [5e3, 5e3, 50.0]
    with pytest.raises(ValueError, match="repeated particle pair"):
        tc.Cloth(mesh, tc.Material(), springs=[[0, 1], [1, 0]])
    with pytest.raises(ValueError, match=r"springs\[stretch\]"):
        tc.Cloth(mesh, tc.Material(), springs=[[0, 9]])
    with pytest.raises(ValueError, match="springs key"):
        tc.Cloth(mesh, tc.Material(), springs={"twist": [[0, 1]]})


def test_colouring_is_a_partition_into_matchings():
    cloth = grid_cloth(7, 9)
    order, offsets = color_springs(cloth.spring_indices, cloth.particle_count)
    assert sorted(order.tolist()) == list(range(cloth.spring_count))
    for c in range(len(offsets) - 1):
        ends = cloth.spring_indices[order[offsets[c]:offsets[c + 1]]].ravel()
        assert len(np.unique(ends)) == len(ends), f"colour {c} shares a particle"
    max_degree = np.bincount(cloth.spring_indices.ravel()).max()
    report("colours", len(offsets) - 1, f">= {max_degree} and <= {2 * max_degree - 1}")
    assert max_degree <= len(offsets) - 1 <= 2 * max_degree - 1


def test_zero_area_triangle_rejected():
    mesh = tc.Mesh([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], [[0, 1, 3], [0, 1, 2]])
    with pytest.raises(ValueError, match=r"triangles\[1\].*area > 0"):
        tc.Cloth(mesh, tc.Material())


def test_massless_unpinned_particle_rejected_unless_pinned():
    # vertex 3 belongs to no triangle
    mesh = tc.Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5]], [[0, 1, 2]])
    with pytest.raises(ValueError, match=r"particle_mass\[\[3\]\]"):
        tc.Cloth(mesh, tc.Material())
    assert tc.Cloth(mesh, tc.Material(), pinned=[3]).pinned[3]


@pytest.mark.parametrize("kwargs, field", [
    (dict(pinned=[0, 20]), "pinned"), (dict(pinned=[-1]), "pinned"),
    (dict(pinned=np.zeros(3, bool)), "pinned.shape"),
    (dict(particle_mass_override={99: 1.0}), "particle_mass_override key"),
    (dict(particle_mass_override={1: -1.0}), r"particle_mass_override\[1\]"),
    (dict(particle_mass=np.ones(5)), "particle_mass.shape"),
])
def test_cloth_rejects_bad_input(kwargs, field):
    with pytest.raises(ValueError, match=field):
        tc.Cloth(tc.grid_mesh(4, 5), tc.Material(), **kwargs)


@pytest.mark.parametrize("make, field", [
    (lambda: tc.Material(density=float("nan")), "Material.density"),
    (lambda: tc.Material(density=-1.0), "Material.density"),
    (lambda: tc.Material(density=0.0), "Material.density"),
    (lambda: tc.SpringParams(k=-5.0), "SpringParams.k"),
    (lambda: tc.SpringParams(k=5.0, kd=-1.0), "SpringParams.kd"),
    (lambda: tc.Material(damping="viscous"), "Material.damping"),
    (lambda: tc.Material(hem_mass=-0.1), "Material.hem_mass"),
    (lambda: tc.Material.preset("velvet"), "preset"),
])
def test_material_rejects_bad_input(make, field):
    with pytest.raises(ValueError, match=field) as err:
        make()
    print(err.value)


def test_presets_are_valid_materials():
    for name in tc.PRESETS:
        material = tc.Material.preset(name)
        assert material.stretch.k >= material.shear.k > material.bend.k  # cloth bends easily
    assert tc.Material.preset("denim_springs", hem_mass=0.02).hem_mass == 0.02


def test_spring_and_fabric_presets_cannot_be_taken_for_each_other():
    """Spring presets end in _springs; a former name still gives its springs, with a
    DeprecationWarning naming the new one and the fabric of the same name; a spring name
    asked of Fabric.preset says where it belongs."""
    assert not set(tc.PRESETS) & set(FABRIC_PRESETS)
    with pytest.warns(DeprecationWarning, match="'denim' is now 'denim_springs'.*fabric"):
        former = tc.Material.preset("Denim")
    assert former == tc.Material.preset("denim_springs")
    assert tc.Fabric.preset("denim").density == FABRIC_PRESETS["denim"]["density"]
    with pytest.raises(ValueError, match=r"'silk_springs' names Stuyck's springs"):
        tc.Fabric.preset("silk_springs")
